"""Status telemetry of the emulated ArduCopter: SYS_STATUS health bits, EKF_STATUS_REPORT and housekeeping.

* SYS_STATUS: present / enabled / healthy bits as ArduPilot's ``GCS::update_sensor_status_flags``
  and ``GCS_Copter::update_vehicle_sensor_status_flags`` set them in SITL: gyro, accel, mag, baro,
  GPS, rate/attitude/yaw control, motor outputs, AHRS (enabled and healthy once the estimator is
  ready), logging, battery, propulsion, rangefinder (LASER_POSITION) if fitted, Z/XY position control
  (present; enabled and healthy while LAND flies), GEOFENCE present and healthy but not enabled
  (ArduCopter's FENCE_TYPE default with FENCE_ENABLE = 0: MAVProxy reports no breach), PREARM_CHECK
  enabled with ``ARMING_CHECK != 0`` and healthy when armed or when arming would pass now. No RC
  receiver (never seen RC input).  ``load`` 10 %.
* EKF_STATUS_REPORT: flags 831 (attitude, velocities, relative/absolute horizontal and vertical
  position, predicted positions) once ready, 165 (attitude, vertical velocity and position, constant
  position mode) while an emulated EKF is settling; small variances.
* POWER_STATUS (5 V board, USB-less), MEMINFO (fixed free memory, as SITL), SYSTEM_TIME (wall clock
  at start + simulated time), VIBRATION (from the body rates' scale; no clipping), AHRS (DCM terms).
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sitl.copter.arming import arming_failure
from sitl.copter.modes import ARMABLE_MODES
from sitl.copter.simulation import Simulation

__all__ = ["STATUS_BUILDERS", "sensor_bits", "prearm_ok", "EKF_FLAGS_READY", "EKF_FLAGS_SETTLING"]

M = mavlink
_UINT16_MAX = 65535
_ALWAYS = (M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL | M.MAV_SYS_STATUS_SENSOR_3D_MAG
           | M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE | M.MAV_SYS_STATUS_SENSOR_GPS
           | M.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL | M.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
           | M.MAV_SYS_STATUS_SENSOR_YAW_POSITION | M.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
           | M.MAV_SYS_STATUS_LOGGING | M.MAV_SYS_STATUS_SENSOR_BATTERY | M.MAV_SYS_STATUS_SENSOR_PROPULSION)
_POS_CONTROL = M.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL | M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
_LAND = 9
EKF_FLAGS_READY = (M.EKF_ATTITUDE | M.EKF_VELOCITY_HORIZ | M.EKF_VELOCITY_VERT | M.EKF_POS_HORIZ_REL
                   | M.EKF_POS_HORIZ_ABS | M.EKF_POS_VERT_ABS | M.EKF_PRED_POS_HORIZ_REL | M.EKF_PRED_POS_HORIZ_ABS)
EKF_FLAGS_SETTLING = M.EKF_ATTITUDE | M.EKF_VELOCITY_VERT | M.EKF_POS_VERT_ABS | M.EKF_CONST_POS_MODE


def _ms(sim: Simulation) -> int:
    return (sim.boot_ns // 1_000_000) & 0xFFFFFFFF


def prearm_ok(sim: Simulation) -> bool:
    """Whether the pre-arm checks pass now (ArduPilot's ``AP_Notify::flags.pre_arm_check``; the mode aside)."""
    ap = sim.autopilot
    now = sim.time_ns
    readiness = getattr(ap, "readiness", None)  # the ArduCopter emulation's estimator start-up
    if readiness is not None and readiness.prearm_reason(now * 1e-9):
        return False
    mode = ap.mode if ap.mode in ARMABLE_MODES else ARMABLE_MODES[0]
    return not arming_failure(mode, now, ap.prearm_delay_ns, sim.params, sim.imu, sim.nav, sim.world.battery,
                              sim.vehicle.battery.internal_resistance_ohm)


def sensor_bits(sim: Simulation) -> tuple[int, int, int]:
    """SYS_STATUS ``(present, enabled, health)``."""
    ap = sim.autopilot
    ready = ap.position_ready(sim.time_ns)
    present = _ALWAYS | M.MAV_SYS_STATUS_AHRS | M.MAV_SYS_STATUS_GEOFENCE | _POS_CONTROL | M.MAV_SYS_STATUS_PREARM_CHECK
    enabled = _ALWAYS | M.MAV_SYS_STATUS_AHRS
    health = _ALWAYS | M.MAV_SYS_STATUS_GEOFENCE
    if ready:
        health |= M.MAV_SYS_STATUS_AHRS
    if sim.vehicle.sensors.rangefinder:
        bit = M.MAV_SYS_STATUS_SENSOR_LASER_POSITION
        present, enabled, health = present | bit, enabled | bit, health | bit
    if ap.armed and int(ap.mode) == _LAND:
        enabled |= _POS_CONTROL
        health |= _POS_CONTROL
    if sim.params["ARMING_CHECK"] != 0:
        enabled |= M.MAV_SYS_STATUS_PREARM_CHECK
        if ap.armed or prearm_ok(sim):
            health |= M.MAV_SYS_STATUS_PREARM_CHECK
    return present, enabled, health


def _sys_status(sim: Simulation, c) -> mavlink.MAVLink_message:
    b = sim.world.battery
    total = c.frames_in + c.errors
    drop = min(10000, int(10000 * c.errors / total)) if total else 0
    present, enabled, health = sensor_bits(sim)
    return M.MAVLink_sys_status_message(
        present, enabled, health, 100, int(round(b.voltage_v * 1000)), int(round(b.current_a * 100)),
        int(round(100 * b.charge)), drop, min(c.errors, _UINT16_MAX), min(c.errors, _UINT16_MAX),
        min(c.unknown, _UINT16_MAX), min(c.bad_signature, _UINT16_MAX), min(c.wrong_target, _UINT16_MAX), 0, 0, 0)


def _ekf_status_report(sim: Simulation, c) -> mavlink.MAVLink_message:
    ready = sim.autopilot.position_ready(sim.time_ns)
    flags = EKF_FLAGS_READY if ready else EKF_FLAGS_SETTLING
    if ready and sim.vehicle.sensors.rangefinder:
        flags |= M.EKF_POS_VERT_AGL
    return M.MAVLink_ekf_status_report_message(flags, 0.02, 0.01, 0.01, 0.02, 0.0, 0.0)


def _power_status(sim: Simulation, c) -> mavlink.MAVLink_message:
    return M.MAVLink_power_status_message(5000, 0, M.MAV_POWER_STATUS_BRICK_VALID)


def _meminfo(sim: Simulation, c) -> mavlink.MAVLink_message:
    return M.MAVLink_meminfo_message(0, _UINT16_MAX, 131072)


def _system_time(sim: Simulation, c) -> mavlink.MAVLink_message:
    return M.MAVLink_system_time_message(c.boot_unix_us + sim.boot_ns // 1000, _ms(sim))


def _vibration(sim: Simulation, c) -> mavlink.MAVLink_message:
    i = sim.imu
    level = 0.02 + 0.05 * math.sqrt(i.p * i.p + i.q * i.q + i.r * i.r) if sim.autopilot.armed else 0.0
    return M.MAVLink_vibration_message(sim.boot_ns // 1000, level, level, level, 0, 0, 0)


def _ahrs(sim: Simulation, c) -> mavlink.MAVLink_message:
    return M.MAVLink_ahrs_message(0.0, 0.0, 0.0, 0.0, 0.0, 0.01, 0.01)


def _rc_channels(sim: Simulation, c) -> mavlink.MAVLink_message:
    """No RC: count 0, every channel 0 (UINT16_MAX would mean 'unused'; ArduPilot sends 0 without input)."""
    return M.MAVLink_rc_channels_message(_ms(sim), 0, *([0] * 18), 255)


STATUS_BUILDERS = {
    M.MAVLINK_MSG_ID_SYS_STATUS: _sys_status,
    M.MAVLINK_MSG_ID_EKF_STATUS_REPORT: _ekf_status_report,
    M.MAVLINK_MSG_ID_POWER_STATUS: _power_status,
    M.MAVLINK_MSG_ID_MEMINFO: _meminfo,
    M.MAVLINK_MSG_ID_SYSTEM_TIME: _system_time,
    M.MAVLINK_MSG_ID_VIBRATION: _vibration,
    M.MAVLINK_MSG_ID_AHRS: _ahrs,
    M.MAVLINK_MSG_ID_RC_CHANNELS: _rc_channels,
}
