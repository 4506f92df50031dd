"""Clocks for the control loop: injected, monotonic, integer nanoseconds.

The loop never reads wall time itself.  In real time it runs on
:class:`MonotonicClock`; in lockstep with the SITL it runs on a clock driven
by the vehicle's own time stamps (see ``gcs.flight.session``), and a
:class:`ManualClock` drives tests.
"""

from __future__ import annotations

import time
from typing import Protocol

__all__ = ["Clock", "MonotonicClock", "ManualClock"]


class Clock(Protocol):
    """What the loop needs from a clock."""

    def now_ns(self) -> int:
        """Current time [ns] on this clock's monotonic time line."""

    def sleep_until_ns(self, deadline_ns: int) -> None:
        """Return at (or as soon as possible after) ``deadline_ns``."""


class MonotonicClock:
    """``time.monotonic_ns`` with a sleep that wakes early and spins the last ~0.3 ms for precision."""

    def __init__(self, spin_ns: int = 300_000) -> None:
        self.spin_ns = spin_ns

    def now_ns(self) -> int:
        return time.monotonic_ns()

    def sleep_until_ns(self, deadline_ns: int) -> None:
        while True:
            remaining = deadline_ns - time.monotonic_ns()
            if remaining <= 0:
                return
            if remaining > self.spin_ns:
                time.sleep((remaining - self.spin_ns) / 1e9)


class ManualClock:
    """A clock that moves only when told (tests); sleeping jumps to the deadline."""

    def __init__(self, start_ns: int = 0) -> None:
        self.t = start_ns

    def now_ns(self) -> int:
        return self.t

    def advance_ns(self, dt_ns: int) -> None:
        self.t += dt_ns

    def sleep_until_ns(self, deadline_ns: int) -> None:
        if deadline_ns > self.t:
            self.t = deadline_ns
