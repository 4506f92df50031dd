"""Injected clocks: integer nanoseconds on one monotonic time line, and sleeping until a deadline.

Nothing that runs a loop reads the wall clock itself: the ground station's mission loop and
the simulator's servers take a :class:`Clock`.  :class:`MonotonicClock` is real time;
:class:`ManualClock` moves only when told (tests).  The ground station's lockstep clock, driven
by the vehicle's own time stamps, is ``gcs.flight.clock.VehicleClock``.
"""

from __future__ import annotations

import threading
import time
from typing import Protocol

__all__ = ["Clock", "MonotonicClock", "ManualClock", "ScaledClock"]


class Clock(Protocol):
    """What a loop needs from a clock."""

    def now_ns(self) -> int:
        """Current time [ns] on this clock's monotonic time line."""

    def sleep_until_ns(self, deadline_ns: int) -> None:
        """Return at (or as soon as possible after) ``deadline_ns``."""


class MonotonicClock:
    """``time.monotonic_ns`` with a sleep that wakes early and spins the last ``spin_ns`` for precision."""

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


class ScaledClock(MonotonicClock):
    """Real time run ``speedup`` times faster (``sitl --speedup``, as ArduPilot SITL's): from its
    creation, ``speedup`` ns of this clock pass per wall-clock ns.

    Raises
    ------
    ValueError
        ``speedup`` not finite or not in (0, 100].
    """

    def __init__(self, speedup: float, spin_ns: int = 300_000) -> None:
        if not 0.0 < float(speedup) <= 100.0:  # also rejects NaN
            raise ValueError(f"speedup must be in (0, 100], got {speedup!r}")
        super().__init__(spin_ns)
        self.speedup = float(speedup)
        self._wall0 = time.monotonic_ns()

    def now_ns(self) -> int:
        return self._wall0 + int((time.monotonic_ns() - self._wall0) * self.speedup)

    def sleep_until_ns(self, deadline_ns: int) -> None:
        super().sleep_until_ns(self._wall0 + int((deadline_ns - self._wall0) / self.speedup))


class ManualClock:
    """A clock that moves only when told (thread-safe); sleeping jumps to the deadline."""

    def __init__(self, start_ns: int = 0) -> None:
        self._now = int(start_ns)
        self._lock = threading.Lock()

    def now_ns(self) -> int:
        with self._lock:
            return self._now

    def advance_ns(self, dt_ns: int) -> None:
        """Move forward by ``dt_ns`` (>= 0)."""
        if dt_ns < 0:
            raise ValueError("a monotonic clock cannot go back")
        with self._lock:
            self._now += int(dt_ns)

    def advance(self, seconds: float) -> None:
        """Move forward by ``seconds`` (>= 0)."""
        self.advance_ns(int(round(seconds * 1e9)))

    def sleep_until_ns(self, deadline_ns: int) -> None:
        with self._lock:
            if deadline_ns > self._now:
                self._now = int(deadline_ns)
