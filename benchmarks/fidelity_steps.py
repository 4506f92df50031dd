"""Attitude step responses over MAVLink, for ``bench_fidelity.py``: any ArduPilot-like vehicle at a URL.

The vehicle is flown as ``gcs fly`` sets it up for the attitude output (GUID_OPTIONS 8, ATC_ANGLE_BOOST 0,
ATC_RATE_FF_ENAB 0, GUIDED_NOGPS): armed, lifted at 110 % of ``MOT_THST_HOVER`` for 4 s of its time,
held level at hover thrust for 2 s, then given a 10 deg roll step (quaternion, zero body rates, the
thrust divided by cos 10 deg) for 1.5 s and levelled.  ATTITUDE is streamed at 200 Hz; the response is
roll [deg] and roll rate [deg/s] against the vehicle's time since the step.  Thrust, rates and time are
in SI units; nothing here asserts.
"""

from __future__ import annotations

import math
import time

from pymavlink import mavutil

__all__ = ["roll_step"]

_STEP_DEG = 10.0


def _q(roll: float, pitch: float, yaw: float) -> list[float]:
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return [cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy]


def _set(m, name: str, value: float) -> None:
    for _ in range(5):
        m.mav.param_set_send(m.target_system, m.target_component, name.encode(), value,
                             mavutil.mavlink.MAV_PARAM_TYPE_REAL32)
        msg = m.recv_match(type="PARAM_VALUE", blocking=True, timeout=2)
        if msg is not None and msg.param_id == name and abs(msg.param_value - value) < 1e-3:
            return
    raise RuntimeError(f"{name} not set")


def _hover(m) -> float:
    for _ in range(10):
        m.mav.param_request_read_send(m.target_system, m.target_component, b"MOT_THST_HOVER", -1)
        msg = m.recv_match(type="PARAM_VALUE", blocking=True, timeout=2)
        while msg is not None and msg.param_id != "MOT_THST_HOVER":  # late echoes of the parameters set
            msg = m.recv_match(type="PARAM_VALUE", blocking=True, timeout=2)
        if msg is not None:
            return float(msg.param_value)
    raise RuntimeError("MOT_THST_HOVER not read")


def _mode(m, mode: int, deadline: float) -> None:
    while time.monotonic() < deadline:
        m.mav.command_long_send(m.target_system, m.target_component, 176, 0, 1, mode, 0, 0, 0, 0, 0)
        hb = m.recv_match(type="HEARTBEAT", blocking=True, timeout=2)
        if hb is not None and hb.custom_mode == mode:
            return
    raise RuntimeError(f"mode {mode} not taken")


def roll_step(url: str, ready_timeout_wall_s: float = 120.0, udpout: bool = False) -> dict:
    """Fly the step on the vehicle at ``url``; returns ``{"t_s", "roll_deg", "rate_deg_s", "yaw0_deg"}``."""
    m = mavutil.mavlink_connection(url, source_system=255, source_component=190)
    if udpout:
        m.mav.heartbeat_send(6, 8, 0, 0, 0)
    m.wait_heartbeat(timeout=30)
    for mid in (30, 32):  # ATTITUDE, LOCAL_POSITION_NED
        m.mav.command_long_send(m.target_system, m.target_component, 511, 0, mid, 5000, 0, 0, 0, 0, 0)
    for name, value in (("GUID_OPTIONS", 8), ("ATC_ANGLE_BOOST", 0), ("ATC_RATE_FF_ENAB", 0)):
        _set(m, name, value)
    hover = _hover(m)
    deadline = time.monotonic() + ready_timeout_wall_s
    _mode(m, 20, deadline)  # GUIDED_NOGPS
    armed = False
    while not armed and time.monotonic() < deadline:
        _mode(m, 20, deadline)  # again: the firmware may fall back to its default mode while booting
        m.mav.command_long_send(m.target_system, m.target_component, 400, 0, 1, 0, 0, 0, 0, 0, 0)
        ack = m.recv_match(type="COMMAND_ACK", blocking=True, timeout=2)
        armed = ack is not None and ack.command == 400 and ack.result == 0
        m.mav.heartbeat_send(6, 8, 0, 0, 0)
        time.sleep(0.5)
    if not armed:
        raise RuntimeError("not armed")
    att = m.recv_match(type="ATTITUDE", blocking=True, timeout=5)
    yaw = att.yaw if att is not None else 0.0
    t_arm = att.time_boot_ms * 1e-3 if att is not None else 0.0
    out: dict = {"t_s": [], "roll_deg": [], "rate_deg_s": [], "yaw0_deg": math.degrees(yaw)}
    step_at = None
    last_send = 0.0
    vt = t_arm
    while True:
        msg = m.recv_match(type="ATTITUDE", blocking=True, timeout=2)
        if msg is None:
            raise RuntimeError("telemetry lost")
        vt = msg.time_boot_ms * 1e-3
        phase = vt - t_arm
        if phase < 2.5 + 4.0:
            roll, thrust = 0.0, 1.1 * hover
        elif phase < 2.5 + 6.0:
            roll, thrust = 0.0, hover
        else:
            roll, thrust = math.radians(_STEP_DEG), hover / math.cos(math.radians(_STEP_DEG))
            if step_at is None:
                step_at = vt
        if step_at is not None:
            out["t_s"].append(vt - step_at)
            out["roll_deg"].append(math.degrees(msg.roll))
            out["rate_deg_s"].append(math.degrees(msg.rollspeed))
            if vt - step_at > 1.5:
                break
        if vt - last_send >= 0.01 or vt < last_send:
            last_send = vt
            m.mav.set_attitude_target_send(0, m.target_system, m.target_component, 7, _q(roll, 0.0, yaw), 0, 0, 0,
                                           thrust)
    for _ in range(50):  # level, then land
        m.mav.set_attitude_target_send(0, m.target_system, m.target_component, 7, _q(0, 0, yaw), 0, 0, 0, hover)
        time.sleep(0.01)
    m.mav.command_long_send(m.target_system, m.target_component, 176, 0, 1, 9, 0, 0, 0, 0, 0)  # LAND
    m.close()
    return out
