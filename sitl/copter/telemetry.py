"""Telemetry messages of the emulated autopilot, built from a :class:`~sitl.copter.simulation.Simulation`.

What each message carries (all from the sensor readings, not the truth):

* ATTITUDE / ATTITUDE_QUATERNION: IMU attitude and body rates (noisy).
* LOCAL_POSITION_NED: the position/velocity estimate (noisy), origin = the EKF origin (the boot
  position, ``[home]`` of the vehicle file).
* GLOBAL_POSITION_INT: the same around the origin (flat earth, :mod:`quadrotor.geodesy`), altitudes
  in mm; ``relative_alt`` above home (``sim.home``: set when the estimator is ready, re-set at
  arming, moved by DO_SET_HOME), as ArduPilot.
* ALTITUDE: ``altitude_relative``/``altitude_terrain`` = barometric altitude
  above home (10 cm resolution + noise), ``altitude_monotonic``/
  ``altitude_amsl`` = that + home altitude, ``altitude_local`` = -z of the
  estimate, ``bottom_clearance`` = rangefinder if fitted, else the baro altitude.
* DISTANCE_SENSOR (only with ``sensors.rangefinder``): downward range, cm.
* BATTERY_STATUS: pack voltage, current, consumed charge and energy, remaining %.
* SYS_STATUS (:mod:`sitl.copter.telemetry_status`, with EKF_STATUS_REPORT, POWER_STATUS, MEMINFO,
  SYSTEM_TIME, VIBRATION, AHRS, RC_CHANNELS): health bits as ArduPilot, battery, link error counters
  (``drop_rate_comm``, ``errors_comm`` and ``errors_count1..4`` = bad frames, unknown messages,
  rejected signatures, messages for other systems).
* GPS_RAW_INT, GPS_GLOBAL_ORIGIN, HOME_POSITION, RAW_IMU, SCALED_IMU2, SCALED_PRESSURE,
  NAV_CONTROLLER_OUTPUT, AHRS2: :mod:`sitl.copter.telemetry_nav`; MISSION_CURRENT: :mod:`sitl.copter.mission`.
* HEARTBEAT: QUADROTOR / ARDUPILOTMEGA, custom mode, armed flag, MAV_STATE.
* EXTENDED_SYS_STATE (landed state), VFR_HUD, SERVO_OUTPUT_RAW (rotor thrust as 1000..2000 us, linear), ATTITUDE_TARGET.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from quadrotor.geodesy import geodetic_from_local
from sitl.copter.mission import mission_current
from sitl.copter.simulation import Simulation
from sitl.copter.telemetry_nav import NAV_BUILDERS
from sitl.copter.telemetry_status import STATUS_BUILDERS

__all__ = ["BUILDERS", "heartbeat", "build", "autopilot_version", "TelemetryCounters"]

_UINT16_MAX = 65535

# ArduPilot 4.8.0-dev: major << 24 | minor << 16 | patch << 8 | FIRMWARE_VERSION_TYPE_DEV (0)
FLIGHT_SW_VERSION = (4 << 24) | (8 << 16)
#: What this SITL implements: the mission protocol (float and int items, fences, rally points),
#: float parameters, COMMAND_INT, MAVFTP (``@PARAM/param.pck``), SET_ATTITUDE_TARGET, MAVLink 2, and
#: SET_ACTUATOR_CONTROL_TARGET (bit 1024, MAV_PROTOCOL_CAPABILITY_SET_ACTUATOR_TARGET).  The
#: SET_POSITION_TARGET_* bits are added by the dispatcher when the navigation module takes them.
CAPABILITIES = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_FTP | mavlink.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY | 1024
)
#: ``flight_custom_version``: the mark by which gcs knows its own simulator (gcs.vehicles.firmware).
BUILTIN_SITL_MARK = list(b"gcssitl\0")


class TelemetryCounters:
    """Link statistics shown in SYS_STATUS (filled by the endpoint), and the wall clock at boot.

    ``boot_unix_us``: SYSTEM_TIME.time_unix_usec at simulated time 0 (default: the wall clock when
    made; give a fixed value for byte-identical lockstep runs).
    """

    __slots__ = ("frames_in", "errors", "unknown", "bad_signature", "wrong_target", "boot_unix_us")

    def __init__(self, boot_unix_us: int | None = None) -> None:
        self.boot_unix_us = time.time_ns() // 1000 if boot_unix_us is None else int(boot_unix_us)
        self.frames_in = 0
        self.errors = 0
        self.unknown = 0
        self.bad_signature = 0
        self.wrong_target = 0


def _ms(sim: Simulation) -> int:
    return (sim.boot_ns // 1_000_000) & 0xFFFFFFFF


def heartbeat(sim: Simulation) -> mavlink.MAVLink_message:
    """HEARTBEAT of the current mode / arming state."""
    ap = sim.autopilot
    base = ap.base_mode  # CUSTOM_MODE | STABILIZE (+ GUIDED) (+ SAFETY_ARMED); an emulation's own
    return mavlink.MAVLink_heartbeat_message(
        mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, base, int(ap.mode), ap.system_status, 3)


def _attitude(sim: Simulation, c: TelemetryCounters) -> mavlink.MAVLink_message:
    i = sim.imu
    return mavlink.MAVLink_attitude_message(_ms(sim), i.roll, i.pitch, i.yaw, i.p, i.q, i.r)


def _attitude_quaternion(sim: Simulation, c: TelemetryCounters) -> mavlink.MAVLink_message:
    i = sim.imu
    return mavlink.MAVLink_attitude_quaternion_message(_ms(sim), i.qw, i.qx, i.qy, i.qz, i.p, i.q, i.r,
                                                       [0.0, 0.0, 0.0, 0.0])


def _local_position(sim: Simulation, c: TelemetryCounters) -> mavlink.MAVLink_message | None:
    if not sim.autopilot.position_ready(sim.time_ns):
        return None  # an emulated EKF not ready yet
    n = sim.nav
    return mavlink.MAVLink_local_position_ned_message(_ms(sim), n.n, n.e, n.d, n.vn, n.ve, n.vd)


def _heading_cdeg(sim: Simulation) -> int:
    return int(round(math.degrees(sim.imu.yaw) * 100)) % 36000


def _global_position(sim: Simulation, c: TelemetryCounters) -> mavlink.MAVLink_message:
    n = sim.nav
    h = sim.vehicle.home
    lat, lon = geodetic_from_local(h.lat_deg, h.lon_deg, n.n, n.e)
    alt = h.alt_m - n.d
    return mavlink.MAVLink_global_position_int_message(
        _ms(sim), int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000)),
        int(round((alt - sim.home.alt_m) * 1000)), int(round(n.vn * 100)), int(round(n.ve * 100)),
        int(round(n.vd * 100)),
        _heading_cdeg(sim))


def _altitude(sim: Simulation, c: TelemetryCounters) -> mavlink.MAVLink_message:
    n = sim.nav
    home = sim.vehicle.home.alt_m
    baro = n.baro_alt_m
    clearance = n.range_m if n.range_m >= 0 else baro
    return mavlink.MAVLink_altitude_message(sim.boot_ns // 1000, home + baro, home + baro, -n.d, baro, baro,
                                            clearance)


def _distance_sensor(sim: Simulation, c: TelemetryCounters) -> mavlink.MAVLink_message | None:
    sp = sim.vehicle.sensors
    if not sp.rangefinder:
        return None
    r = sim.nav.range_m
    cur = int(round(r * 100)) if r >= 0 else int(round(sp.rangefinder_max_m * 100)) + 1
    return mavlink.MAVLink_distance_sensor_message(
        _ms(sim), 2, int(round(sp.rangefinder_max_m * 100)), cur, mavlink.MAV_DISTANCE_SENSOR_ULTRASOUND, 0,
        mavlink.MAV_SENSOR_ROTATION_PITCH_270, 255, 0.0, 0.0, [0.0, 0.0, 0.0, 0.0], 0)


def _battery_status(sim: Simulation, c: TelemetryCounters) -> mavlink.MAVLink_message:
    b = sim.world.battery
    cells = sim.vehicle.battery.cells
    cell_mv = int(round(b.voltage_v / cells * 1000))
    volts = [cell_mv if i < cells else _UINT16_MAX for i in range(10)]
    charge_state = mavlink.MAV_BATTERY_CHARGE_STATE_OK
    low = sim.params["BATT_LOW_VOLT"]
    if low > 0 and b.voltage_v < low:
        charge_state = mavlink.MAV_BATTERY_CHARGE_STATE_LOW
    return mavlink.MAVLink_battery_status_message(
        0, mavlink.MAV_BATTERY_FUNCTION_ALL, mavlink.MAV_BATTERY_TYPE_LIPO, 32767, volts,
        int(round(b.current_a * 100)), int(round(b.consumed_mah)), int(round(b.consumed_wh * 36)),
        int(round(100 * b.charge)), 0, charge_state, [0, 0, 0, 0], 0, 0)


def _vfr_hud(sim: Simulation, c: TelemetryCounters) -> mavlink.MAVLink_message:
    n = sim.nav
    gs = math.hypot(n.vn, n.ve)
    hdg = int(round(math.degrees(sim.imu.yaw))) % 360
    return mavlink.MAVLink_vfr_hud_message(gs, gs, hdg, int(round(100 * sim.autopilot.throttle)),
                                           sim.vehicle.home.alt_m - n.d, -n.vd)


def _extended_sys_state(sim: Simulation, c: TelemetryCounters) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_extended_sys_state_message(mavlink.MAV_VTOL_STATE_UNDEFINED, sim.autopilot.landed_state)


def _servo_output_raw(sim: Simulation, c: TelemetryCounters) -> mavlink.MAVLink_message:
    tmax = sim.vehicle.rotors.max_thrust_n
    armed = sim.autopilot.armed
    pwm = [int(round(1000 + 1000 * t / tmax)) if armed else 1000 for t in sim.autopilot.rotor_cmd_n]
    return mavlink.MAVLink_servo_output_raw_message((sim.boot_ns // 1000) & 0xFFFFFFFF, 0, *pwm,
                                                    0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0)


def _attitude_target(sim: Simulation, c: TelemetryCounters) -> mavlink.MAVLink_message:
    ap = sim.autopilot
    r = ap.rate_target
    return mavlink.MAVLink_attitude_target_message(_ms(sim), 0, list(ap.att_target_q), r[0], r[1], r[2],
                                                   ap.throttle)


def autopilot_version(sim: Simulation, extra_capabilities: int = 0) -> mavlink.MAVLink_message:
    """AUTOPILOT_VERSION (answer to MAV_CMD_REQUEST_MESSAGE 148 / REQUEST_AUTOPILOT_CAPABILITIES).

    ``extra_capabilities``: bits of what the navigation module takes (SET_POSITION_TARGET_*).
    """
    caps, version, custom = sim.autopilot.identity or (CAPABILITIES | extra_capabilities, FLIGHT_SW_VERSION,
                                                       BUILTIN_SITL_MARK)
    return mavlink.MAVLink_autopilot_version_message(
        caps, version, 0, 0, 0, custom, [0] * 8, [0] * 8, 0, 0, 0, [0] * 18)


BUILDERS: dict[int, Callable[[Simulation, TelemetryCounters], mavlink.MAVLink_message | None]] = {
    mavlink.MAVLINK_MSG_ID_HEARTBEAT: lambda sim, c: heartbeat(sim),
    mavlink.MAVLINK_MSG_ID_ATTITUDE: _attitude,
    mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: _attitude_quaternion,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: _local_position,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: _global_position,
    mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: _servo_output_raw,
    mavlink.MAVLINK_MSG_ID_VFR_HUD: _vfr_hud,
    mavlink.MAVLINK_MSG_ID_ATTITUDE_TARGET: _attitude_target,
    mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR: _distance_sensor,
    mavlink.MAVLINK_MSG_ID_ALTITUDE: _altitude,
    mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: _battery_status,
    mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: _extended_sys_state,
    mavlink.MAVLINK_MSG_ID_MISSION_CURRENT: lambda sim, c: mission_current(sim),
    **STATUS_BUILDERS,
    **NAV_BUILDERS,
}


def build(msg_id: int, sim: Simulation, counters: TelemetryCounters) -> mavlink.MAVLink_message | None:
    """The message ``msg_id`` for the current state, or None (unsupported / not fitted)."""
    f = BUILDERS.get(msg_id)
    return f(sim, counters) if f is not None else None
