"""Injectable clocks: the server never reads the wall clock directly.

:class:`MonotonicClock` wraps :func:`time.monotonic_ns` (real-time mode, link
latency, idle heartbeats); :class:`ManualClock` is advanced by hand (tests).
Simulated time is separate: it is kept by :class:`sitl.simulation.Simulation`
and, in lockstep, advanced only by commands.
"""

from __future__ import annotations

import threading
import time
from typing import Protocol

__all__ = ["Clock", "MonotonicClock", "ManualClock"]


class Clock(Protocol):
    """Source of monotonic time in integer nanoseconds."""

    def monotonic_ns(self) -> int:
        """Current time [ns]; never decreases."""
        ...


class MonotonicClock:
    """The process's monotonic clock."""

    def monotonic_ns(self) -> int:
        return time.monotonic_ns()


class ManualClock:
    """A clock that moves only when told to (thread-safe).

    Parameters
    ----------
    start_ns : int
    """

    def __init__(self, start_ns: int = 0) -> None:
        self._now = int(start_ns)
        self._lock = threading.Lock()

    def monotonic_ns(self) -> int:
        with self._lock:
            return self._now

    def advance(self, seconds: float) -> None:
        """Move forward by ``seconds`` (>= 0)."""
        if seconds < 0:
            raise ValueError("a monotonic clock cannot go back")
        with self._lock:
            self._now += int(round(seconds * 1e9))
