"""Telemetry decoding: MAVLink messages into the estimator (paper frame) and the vehicle status.

Conversions go through :mod:`quadrotor.frames` only: LOCAL_POSITION_NED becomes
(x, y, z up) and (vx, vy, vz up); ATTITUDE's body rates become Euler-angle
rates.  Freshness is kept per stream on the loop's clock, and the vehicle's
own time (``time_boot_ms``) is tracked for lockstep.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from typing import Callable

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.estimate import StateEstimator
from gcs.flight.validate import TelemetryValidator
from quadrotor.mavlink.modes import copter_mode_name
from quadrotor.frames import body_rates_to_euler_rates, ned_to_paper_position, ned_to_paper_velocity

__all__ = ["VehicleStatus", "Telemetry"]



@dataclass
class VehicleStatus:
    """What the vehicle last said about itself."""

    armed: bool = False
    custom_mode: int = -1
    system_status: int = 0
    battery_voltage_v: float | None = None
    battery_remaining_pct: int | None = None
    time_boot_ms: int = 0
    statustext: deque = field(default_factory=lambda: deque(maxlen=64))
    #: custom_mode -> the mode's name (the autopilot profile's).
    mode_name: Callable[[int], str] = field(default=copter_mode_name, repr=False)

    @property
    def mode(self) -> str:
        return self.mode_name(self.custom_mode)


class Telemetry:
    """Feeds the estimator and the status from received messages.

    Parameters
    ----------
    estimator : StateEstimator
    position_var_m2, velocity_var_m2_s2 : (float, float, float)
        Variances given to LOCAL_POSITION_NED positions and velocities.
    on_event : callable (kind, text) or None
        Told of mode changes, arming, disarming and STATUSTEXT.
    """

    def __init__(self, estimator: StateEstimator, position_var_m2=(0.0025,) * 3, velocity_var_m2_s2=(0.0025,) * 3,
                 on_event: Callable[[str, str], None] | None = None, target_component: int = 1,
                 validator: TelemetryValidator | None = None, mode_name: Callable[[int], str] = copter_mode_name) -> None:
        self.target_component = target_component
        self.estimator = estimator
        self.position_var = tuple(position_var_m2)
        self.velocity_var = tuple(velocity_var_m2_s2)
        self.status = VehicleStatus(mode_name=mode_name)
        self.on_event = on_event
        self.last_ns: dict[str, int] = {}
        self.timesync_rtt_ms: float | None = None
        self.timesync_samples_ms: list[float] = []
        self.timesync_sent: set[int] = set()
        #: Valid messages received, per type (the loop's stream-rate monitor reads it).
        self.counts: dict[str, int] = {}
        self.validator = validator or TelemetryValidator(on_first=lambda why: self._event(
            "warning", f"telemetry rejected: {why} (further ones are counted)"))

    def _event(self, kind: str, text: str) -> None:
        if self.on_event is not None:
            self.on_event(kind, text)

    def handle(self, msg, now_ns: int) -> None:
        """Take one message received at loop time ``now_ns`` (validated first: see :mod:`gcs.flight.validate`)."""
        if msg.get_srcComponent() != self.target_component:
            return  # a companion computer or gimbal of the same system: not the autopilot
        t = msg.get_type()
        st = self.status
        v = self.validator
        if t == "ATTITUDE":
            if not v.attitude(msg.roll, msg.pitch, msg.yaw, msg.rollspeed, msg.pitchspeed, msg.yawspeed,
                              int(msg.time_boot_ms)):
                return
            er = body_rates_to_euler_rates(msg.roll, msg.pitch, msg.rollspeed, msg.pitchspeed, msg.yawspeed)
            self.estimator.set_attitude(msg.roll, msg.pitch, msg.yaw, *er)
            st.time_boot_ms = max(st.time_boot_ms, int(msg.time_boot_ms))
        elif t == "LOCAL_POSITION_NED":
            if not v.position(msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz, int(msg.time_boot_ms)):
                return
            self.estimator.correct_position(ned_to_paper_position(msg.x, msg.y, msg.z), self.position_var)
            self.estimator.correct_velocity(ned_to_paper_velocity(msg.vx, msg.vy, msg.vz), self.velocity_var)
            st.time_boot_ms = max(st.time_boot_ms, int(msg.time_boot_ms))
        self.last_ns[t] = now_ns
        self.counts[t] = self.counts.get(t, 0) + 1
        if t in ("ATTITUDE", "LOCAL_POSITION_NED"):
            return
        if t == "HEARTBEAT":
            armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            if armed != st.armed:
                st.armed = armed
                self._event("arming", "armed" if armed else "disarmed")
            if msg.custom_mode != st.custom_mode:
                st.custom_mode = int(msg.custom_mode)
                self._event("mode", st.mode)
            st.system_status = int(msg.system_status)
        elif t == "SYS_STATUS":
            if msg.voltage_battery != 65535 and v.voltage(msg.voltage_battery / 1000.0):
                st.battery_voltage_v = msg.voltage_battery / 1000.0
            if msg.battery_remaining >= 0:
                st.battery_remaining_pct = int(msg.battery_remaining)
        elif t == "STATUSTEXT":
            text = msg.text.decode(errors="replace") if isinstance(msg.text, bytes) else str(msg.text)
            text = text.rstrip("\x00")
            st.statustext.append(text)
            self._event("statustext", text)
        elif t == "TIMESYNC" and msg.ts1 in self.timesync_sent:
            # Our request carried ts1 = our wall-clock monotonic ns (not the loop clock, which
            # is the vehicle's own in lockstep); the reply echoes it.
            rtt_ms = (time.monotonic_ns() - msg.ts1) / 1e6
            self.timesync_sent.discard(msg.ts1)
            if 0.0 <= rtt_ms < 60_000.0:
                self.timesync_rtt_ms = rtt_ms
                self.timesync_samples_ms.append(rtt_ms)

    def age_s(self, message: str, now_ns: int) -> float:
        """Seconds since ``message`` last arrived (inf if never)."""
        t = self.last_ns.get(message)
        return float("inf") if t is None else (now_ns - t) / 1e9

    def fresh(self, now_ns: int, stale_s: float) -> bool:
        """Attitude and position both newer than ``stale_s``."""
        return max(self.age_s("ATTITUDE", now_ns), self.age_s("LOCAL_POSITION_NED", now_ns)) <= stale_s
