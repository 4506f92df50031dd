"""Navigation and sensor telemetry of the emulated ArduCopter, and where home is.

* GPS_RAW_INT: ArduPilot SITL's simulated u-blox: fix type 6 (RTK fixed), 10 satellites, HDOP 1.21,
  VDOP 2.0, accuracies 0.3 m / 0.4 m / 0.2 m/s; position and velocity from the estimate.
* GPS_GLOBAL_ORIGIN: the EKF origin = the boot position (``sim.vehicle.home``; the local NED origin),
  once the estimator is ready.
* HOME_POSITION: ``sim.home`` once set; ``x/y/z`` its NED offset from the origin [m]; the quaternion
  (NaN in ArduPilot: nothing non-finite is sent here) is the identity.
* RAW_IMU / SCALED_IMU2: specific force [mG] (gravity at rest, rotor thrust in flight), body rates
  [mrad/s], the earth field [mGauss] rotated into the body; SCALED_PRESSURE: ISA pressure at the
  barometric altitude [hPa], 25 degC.
* NAV_CONTROLLER_OUTPUT: attitude target [deg], heading; no waypoint distance outside AUTO.
* AHRS2: attitude, altitude AMSL and position (the secondary estimator agrees with the first).

:func:`current_location` and :class:`HomeTracker` give the home logic of ArduCopter: home is set
to the current location once the estimator is ready and again at arming (unless locked by a
DO_SET_HOME), and every change is announced with a HOME_POSITION.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from quadrotor.frames import quat_conjugate, quat_rotate, quaternion_to_euler
from quadrotor.geodesy import geodetic_from_local, local_from_geodetic
from sitl.copter.simulation import Simulation

__all__ = ["NAV_BUILDERS", "current_location", "HomeTracker", "home_position", "set_home", "MAX_HOME_DISTANCE_M"]

M = mavlink
_EARTH_FIELD_MGAUSS = (200.0, 20.0, 450.0)  # NED
#: ArduCopter refuses a home farther than this from the EKF origin (``far_from_EKF_origin``).
MAX_HOME_DISTANCE_M = 50_000.0


def _ms(sim: Simulation) -> int:
    return (sim.boot_ns // 1_000_000) & 0xFFFFFFFF


def current_location(sim: Simulation) -> tuple[float, float, float]:
    """The estimate as latitude, longitude [deg] and altitude AMSL [m]."""
    o = sim.vehicle.home
    n = sim.nav
    lat, lon = geodetic_from_local(o.lat_deg, o.lon_deg, n.n, n.e)
    return lat, lon, o.alt_m - n.d


def set_home(sim: Simulation, lat_deg: float, lon_deg: float, alt_m: float, lock: bool) -> bool:
    """Move home (False if not finite or farther than :data:`MAX_HOME_DISTANCE_M` from the origin)."""
    if not all(math.isfinite(v) for v in (lat_deg, lon_deg, alt_m)) or abs(lat_deg) > 90 or abs(lon_deg) > 180:
        return False
    o = sim.vehicle.home
    n, e = local_from_geodetic(o.lat_deg, o.lon_deg, lat_deg, lon_deg)
    if math.hypot(n, e) > MAX_HOME_DISTANCE_M:
        return False
    h = sim.home
    h.lat_deg, h.lon_deg, h.alt_m = lat_deg, lon_deg, alt_m
    h.is_set = True
    h.locked = h.locked or lock
    return True


class HomeTracker:
    """ArduCopter's home: set when the estimator is ready, re-set at arming unless locked; reports changes."""

    def __init__(self, sim: Simulation) -> None:
        self.sim = sim
        self._was_armed = False
        self._sent: tuple[float, float, float, bool] | None = None

    def poll(self) -> bool:
        """Update home; True when it changed since the last call (a HOME_POSITION is due)."""
        sim = self.sim
        ap = sim.autopilot
        h = sim.home
        if not h.is_set and ap.position_ready(sim.time_ns):
            set_home(sim, *current_location(sim), lock=False)
        armed = ap.armed
        if armed and not self._was_armed and h.is_set and not h.locked:
            set_home(sim, *current_location(sim), lock=False)
        self._was_armed = armed
        now = (h.lat_deg, h.lon_deg, h.alt_m, h.is_set)
        changed = h.is_set and now != self._sent
        self._sent = now
        return changed


def home_position(sim: Simulation, c=None) -> mavlink.MAVLink_message | None:
    """HOME_POSITION, or None while home is not set."""
    h = sim.home
    if not h.is_set:
        return None
    o = sim.vehicle.home
    n, e = local_from_geodetic(o.lat_deg, o.lon_deg, h.lat_deg, h.lon_deg)
    return M.MAVLink_home_position_message(
        int(round(h.lat_deg * 1e7)), int(round(h.lon_deg * 1e7)), int(round(h.alt_m * 1000)), n, e,
        o.alt_m - h.alt_m, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, sim.boot_ns // 1000)


def _gps_global_origin(sim: Simulation, c) -> mavlink.MAVLink_message | None:
    if not sim.autopilot.position_ready(sim.time_ns):
        return None
    o = sim.vehicle.home
    return M.MAVLink_gps_global_origin_message(int(round(o.lat_deg * 1e7)), int(round(o.lon_deg * 1e7)),
                                              int(round(o.alt_m * 1000)), sim.boot_ns // 1000)


def _gps_raw_int(sim: Simulation, c) -> mavlink.MAVLink_message:
    lat, lon, alt = current_location(sim)
    n = sim.nav
    gs = math.hypot(n.vn, n.ve)
    cog = int(round(math.degrees(math.atan2(n.ve, n.vn)) * 100)) % 36000 if gs > 0.2 else 0
    alt_mm = int(round(alt * 1000))
    return M.MAVLink_gps_raw_int_message(
        sim.boot_ns // 1000, M.GPS_FIX_TYPE_RTK_FIXED, int(round(lat * 1e7)), int(round(lon * 1e7)), alt_mm, 121,
        200, int(round(gs * 100)), cog, 10, alt_mm, 300, 400, 200, 0, 0)


def _specific_force_body(sim: Simulation) -> tuple[float, float, float]:
    """Accelerometer reading [m/s^2], FRD."""
    g = sim.vehicle.gravity_m_s2
    if sim.world.on_ground or not sim.autopilot.armed:
        i = sim.imu
        return quat_rotate(quat_conjugate((i.qw, i.qx, i.qy, i.qz)), (0.0, 0.0, -g))
    return 0.0, 0.0, -sum(sim.world.plant.rotor_thrusts) / sim.vehicle.mass_kg


def _imu_fields(sim: Simulation) -> list[int]:
    i = sim.imu
    ax, ay, az = _specific_force_body(sim)
    mx, my, mz = quat_rotate(quat_conjugate((i.qw, i.qx, i.qy, i.qz)), _EARTH_FIELD_MGAUSS)
    k = 1000.0 / sim.vehicle.gravity_m_s2
    return [int(round(v)) for v in (ax * k, ay * k, az * k, i.p * 1000, i.q * 1000, i.r * 1000, mx, my, mz)]


def _raw_imu(sim: Simulation, c) -> mavlink.MAVLink_message:
    return M.MAVLink_raw_imu_message(sim.boot_ns // 1000, *_imu_fields(sim), 0, 4500)


def _scaled_imu2(sim: Simulation, c) -> mavlink.MAVLink_message:
    return M.MAVLink_scaled_imu2_message(_ms(sim), *_imu_fields(sim), 4500)


def _scaled_pressure(sim: Simulation, c) -> mavlink.MAVLink_message:
    alt = sim.vehicle.home.alt_m + sim.nav.baro_alt_m
    press_hpa = 1013.25 * max(0.0, 1.0 - 2.25577e-5 * alt) ** 5.25588
    return M.MAVLink_scaled_pressure_message(_ms(sim), press_hpa, 0.0, 2500, 0)


def _nav_controller_output(sim: Simulation, c) -> mavlink.MAVLink_message:
    roll, pitch, _ = quaternion_to_euler(sim.autopilot.att_target_q)
    hdg = int(round(math.degrees(sim.imu.yaw))) % 360
    return M.MAVLink_nav_controller_output_message(math.degrees(roll), math.degrees(pitch), hdg, hdg, 0, 0.0, 0.0,
                                                   0.0)


def _ahrs2(sim: Simulation, c) -> mavlink.MAVLink_message:
    i = sim.imu
    lat, lon, alt = current_location(sim)
    return M.MAVLink_ahrs2_message(i.roll, i.pitch, i.yaw, alt, int(round(lat * 1e7)), int(round(lon * 1e7)))


NAV_BUILDERS = {
    M.MAVLINK_MSG_ID_GPS_RAW_INT: _gps_raw_int,
    M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: _gps_global_origin,
    M.MAVLINK_MSG_ID_HOME_POSITION: home_position,
    M.MAVLINK_MSG_ID_RAW_IMU: _raw_imu,
    M.MAVLINK_MSG_ID_SCALED_IMU2: _scaled_imu2,
    M.MAVLINK_MSG_ID_SCALED_PRESSURE: _scaled_pressure,
    M.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT: _nav_controller_output,
    M.MAVLINK_MSG_ID_AHRS2: _ahrs2,
}
