"""The flight's clocks and its one way of waiting: on the injected clock, never on the wall directly.

:class:`VehicleClock` is lockstep time — the vehicle's own telemetry time stamps.
:func:`wait_until` is how the preflight, the landing and the sessions wait for something
(a mode, a touchdown, fresh telemetry): one control period at a time on the flight's clock,
calling ``step`` each period (a setpoint: it keeps a guided vehicle fed and moves a lockstep
simulator one step).  The link's own request/response timeouts (an ACK, a PARAM_VALUE) are the
link's business and stay in wall time.
"""

from __future__ import annotations

import time
from typing import Callable

from quadrotor.clock import Clock, ManualClock, MonotonicClock

__all__ = ["VehicleClock", "SimClock", "wait_until", "Clock", "MonotonicClock", "ManualClock"]


class VehicleClock:
    """Lockstep clock: the vehicle's own time (the time stamps of its telemetry).

    Parameters
    ----------
    vehicle_time_ns : callable () -> int
        The newest vehicle time stamp received [ns].
    pump : callable (wait_s)
        Receive from the link, waiting at most ``wait_s`` when nothing is there.
    max_wait_s : float
        Wall time to wait for a step's telemetry before giving up on it.

    After :meth:`mark_sent`, ``sleep_until_ns`` pumps the link until telemetry newer
    than the command has arrived (the vehicle steps once per command; an absolute time
    would never be reached after a lost frame).  Wall time enters only when that telemetry
    does not come: after ``max_wait_s`` (long enough that a simulator starved of CPU is
    waited for, so the same seed gives the same flight) the clock moves to the deadline
    anyway, and while nothing comes back it runs at real time — a silent vehicle still ages
    the telemetry and trips the failsafe, and a timeout of S seconds takes S seconds.
    :attr:`timeouts` counts the steps given up on (a flight with none did not depend on wall time).
    """

    lockstep = True

    def __init__(self, vehicle_time_ns: Callable[[], int], pump: Callable[[float], None],
                 max_wait_s: float = 0.5) -> None:
        self.vehicle_time_ns = vehicle_time_ns
        self.pump = pump
        self.max_wait_s = max_wait_s
        self._virtual_ns = 0
        self._sent_ns: int | None = None
        self._lost = False
        self.timeouts = 0

    def now_ns(self) -> int:
        return max(self.vehicle_time_ns(), self._virtual_ns)

    def mark_sent(self) -> None:
        """A command went out: the next sleep waits for telemetry newer than now."""
        self._sent_ns = self.vehicle_time_ns()

    def sleep_until_ns(self, deadline_ns: int) -> None:
        sent, self._sent_ns = self._sent_ns, None
        if self._lost:
            budget = min(1.0, max(0.0, (deadline_ns - self.now_ns()) / 1e9))
        else:
            budget = self.max_wait_s
        end = time.monotonic() + budget
        while (self.vehicle_time_ns() <= sent) if sent is not None else (self.now_ns() < deadline_ns):
            remaining = end - time.monotonic()
            if remaining <= 0:
                self.timeouts += 1
                self._lost = True
                break
            self.pump(min(remaining, 0.005))
        else:
            self._lost = False
        self._virtual_ns = max(self._virtual_ns, deadline_ns)


class SimClock:
    """The in-process simulation's clock: simulated time, moved only by the loop's sleeps (one thread)."""

    lockstep = True

    def __init__(self, start_ns: int = 0) -> None:
        self._now = int(start_ns)

    def now_ns(self) -> int:
        return self._now

    def sleep_until_ns(self, deadline_ns: int) -> None:
        if deadline_ns > self._now:
            self._now = deadline_ns


def wait_until(clock: Clock, predicate: Callable[[], bool], timeout_s: float, *, period_s: float,
               pump: Callable[[], object], step: Callable[[], bool] | None = None,
               stop: Callable[[], bool] | None = None) -> bool:
    """Pump until ``predicate()`` holds (True) or ``timeout_s`` of ``clock`` time passes (False).

    Every control period ``period_s``: ``pump()``, check, then ``step()`` (True when it sent a
    setpoint: in lockstep that is what moves the vehicle's time, and the sleep then waits for
    the step's telemetry) and sleep to the next period.  ``stop()`` true ends the wait early
    (False), e.g. on Ctrl-C.
    """
    t0 = clock.now_ns()
    timeout_ns = int(timeout_s * 1e9)
    period_ns = int(round(period_s * 1e9))
    k = 0
    while True:
        pump()
        if predicate():
            return True
        if stop is not None and stop():
            return False
        if clock.now_ns() - t0 >= timeout_ns:
            return predicate()
        if step is not None and step():
            mark = getattr(clock, "mark_sent", None)
            if mark is not None:
                mark()
        k += 1
        clock.sleep_until_ns(t0 + k * period_ns)
