"""The rig's telemetry as the ground station keeps it: validated TELEMETRY into the estimate, STATUS, flags.

TELEMETRY (200 Hz) gives the attitude and Euler-angle rates, the ultrasonic altitude (4 cm steps)
and x along the rail; y and yaw are locked (measured as 0).  Each one is checked first: finite,
physically plausible, its 32-bit microsecond time stamp advancing (unwrapped into
:attr:`RigTelemetry.time_ns`, the lockstep clock).  STATUS carries the rig's state, flags, its
decoder counters and the echo of our HEARTBEAT (the round trip).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from gcs.estimate import StateEstimator
from gcs.flight.validate import TelemetryValidator
from quadrotor import rig_protocol as rp
from quadrotor.rig_protocol import AckResult, RigFlags, RigState

__all__ = ["RigTelemetry", "RIG_MAX_X_M", "cutoff_causes"]

#: |x| along the rail beyond which a TELEMETRY reading is implausible [m].
RIG_MAX_X_M = 50.0
_US_WRAP = 1 << 32


def cutoff_causes(flags: RigFlags) -> str:
    """The cut-off causes set in ``flags``, comma separated."""
    return ", ".join(f.name for f in RigFlags if f & rp.CUTOFF_CAUSES and f & flags)


class RigTelemetry:
    """What the rig last said, fed to ``estimator``; ``event(kind, text)`` tells of changes."""

    def __init__(self, estimator: StateEstimator, event: Callable[[str, str], None]) -> None:
        self.estimator = estimator
        self._event = event
        self.flags = RigFlags(0)
        self.state_rig: RigState | None = None
        self.status: rp.Status | None = None
        self.rtt_ms: float | None = None
        self.validator = TelemetryValidator(on_first=lambda why: event(
            "warning", f"telemetry rejected: {why} (further ones are counted)"))
        self.time_ns = 0
        self.last_rx_ns: int | None = None
        self._time_us_last: int | None = None
        self._hb_sent: dict[int, int] = {}

    def heartbeat_stamp(self) -> int:
        """A HEARTBEAT time stamp [us, 32-bit] remembered for the round trip (a wall-clock measurement)."""
        t_us = (time.monotonic_ns() // 1000) & 0xFFFFFFFF
        self._hb_sent[t_us] = time.monotonic_ns()
        if len(self._hb_sent) > 16:
            self._hb_sent.pop(next(iter(self._hb_sent)))
        return t_us

    def fresh(self, now_ns: int, stale_s: float) -> bool:
        return self.last_rx_ns is not None and (now_ns - self.last_rx_ns) / 1e9 <= stale_s

    def _rig_time(self, time_us: int) -> None:
        """Unwrap the rig's 32-bit microsecond clock into :attr:`time_ns`."""
        last = self._time_us_last
        if last is not None:
            step = (time_us - last) % _US_WRAP
            if step < _US_WRAP // 2:
                self.time_ns += step * 1000
        else:
            self.time_ns = time_us * 1000
        self._time_us_last = time_us

    def _valid(self, msg: rp.Telemetry) -> bool:
        """Finite, physically plausible, and not older than the last TELEMETRY (see :mod:`gcs.flight.validate`)."""
        v = self.validator
        if not v.attitude(msg.roll_rad, msg.pitch_rad, msg.yaw_rad, msg.roll_rate_rad_s, msg.pitch_rate_rad_s,
                          msg.yaw_rate_rad_s, None, message="TELEMETRY"):
            return False
        if not math.isfinite(msg.x_m) or abs(msg.x_m) > RIG_MAX_X_M:
            return v.reject("TELEMETRY", "x out of range")
        step = (msg.time_us - self._time_us_last) % _US_WRAP if self._time_us_last is not None else 0
        if self._time_us_last is not None and (step == 0 or step >= _US_WRAP // 2):
            return v.reject("TELEMETRY", "time stamp did not advance")
        return True

    def handle(self, msg: rp.Message, now_ns: int) -> None:
        """Take one message received at loop time ``now_ns``."""
        if isinstance(msg, rp.Telemetry):
            if not self._valid(msg):
                return
            self._rig_time(msg.time_us)
            self.last_rx_ns = now_ns  # arrival on the loop's clock (in lockstep: >= the rig's time)
            self.estimator.correct_position((msg.x_m, 0.0, msg.altitude_m))
            self.estimator.set_attitude(msg.roll_rad, msg.pitch_rad, 0.0,
                                        msg.roll_rate_rad_s, msg.pitch_rate_rad_s, 0.0)
            self.set_flags(RigFlags(msg.flags))
        elif isinstance(msg, rp.Status):
            self.status = msg
            if self.state_rig is not None and msg.state != self.state_rig:
                self._event("mode", f"rig {RigState(msg.state).name}")
            self.state_rig = RigState(msg.state)
            sent = self._hb_sent.pop(msg.heartbeat_echo_us, None)
            if sent is not None:
                self.rtt_ms = (time.monotonic_ns() - sent) / 1e6
            self.set_flags(RigFlags(msg.flags))
        elif isinstance(msg, rp.Ack):
            kind = rp.MESSAGE_TYPES.get(msg.acked_type)
            name = kind.NAME if kind is not None else f"unknown type 0x{msg.acked_type:02x}"
            result = AckResult(msg.result).name if msg.result in AckResult._value2member_map_ else str(msg.result)
            self._event("ack", f"{name} seq {msg.seq}: {result}")

    def set_flags(self, flags: RigFlags) -> None:
        changed = flags ^ self.flags
        self.flags = flags
        if changed & RigFlags.ARMED:
            self._event("arming", "armed" if flags & RigFlags.ARMED else "disarmed")
        if changed & RigFlags.CUTOFF and flags & RigFlags.CUTOFF:
            self._event("failsafe", f"rig safety cut-off ({cutoff_causes(flags) or 'unknown cause'}): motors off")
        if changed & RigFlags.WATCHDOG and flags & RigFlags.WATCHDOG:
            self._event("failsafe", "rig link watchdog: no control frames, the rig descends by itself")
        if changed & RigFlags.LANDED:
            self._event("landing", "on the ground" if flags & RigFlags.LANDED else "lifted off")
