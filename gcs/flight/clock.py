"""The flight's clocks and its one way of waiting: on the injected clock, never on the wall directly.

:class:`VehicleClock` is lockstep time — the vehicle's own telemetry time stamps;
:class:`PacedVehicleClock` is the same time line for a vehicle that runs by itself (a firmware
SITL at ``--speedup S``: the loop follows its time, S times faster than the wall).
:func:`wait_until` is how the preflight, the landing and the sessions wait for something
(a mode, a touchdown, fresh telemetry): one control period at a time on the flight's clock,
calling ``step`` each period (a setpoint: it keeps a guided vehicle fed and moves a lockstep
simulator one step).  The link's own request/response timeouts (an ACK, a PARAM_VALUE) are the
link's business and stay in wall time.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from quadrotor.clock import Clock, ManualClock, MonotonicClock

__all__ = ["VehicleClock", "PacedVehicleClock", "SimClock", "wait_until", "Clock", "MonotonicClock", "ManualClock"]


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


class PacedVehicleClock:
    """The vehicle's own time (its telemetry time stamps) for a vehicle that runs by itself.

    Parameters
    ----------
    vehicle_time_ns : callable () -> int
        The newest vehicle time stamp received [ns].
    pump : callable (wait_s)
        Receive from the link, waiting at most ``wait_s`` when nothing is there.
    speedup : float
        Vehicle seconds per wall second (a firmware SITL's ``--speedup``; 1 for a real vehicle).
    max_ahead_s : float
        How far past the newest time stamp the clock runs on the wall (times ``speedup``) before
        it waits for the vehicle [vehicle s].
    max_wait_s : float
        Wall time beyond the nominal ``(deadline - now) / speedup`` to wait for the vehicle's time
        to reach a deadline before giving up on it.

    Between two time stamps the clock runs at ``speedup`` times the wall from the newest one, at
    most ``max_ahead_s`` past it: the loop's ticks fall on their deadlines whatever the spacing of
    the telemetry, and a vehicle that runs slower than ``speedup`` (a SITL starved of CPU) holds
    the clock back instead of being overtaken by it.  It never goes back.  When the vehicle falls
    silent the clock moves on by itself at ``speedup`` times the wall (a silent vehicle ages the
    telemetry and trips the failsafe in the same vehicle time as a live one); :attr:`timeouts`
    counts those steps.  Not lockstep: the vehicle does not wait for the ground station, and a
    late tick is skipped.
    """

    lockstep = False

    def __init__(self, vehicle_time_ns: Callable[[], int], pump: Callable[[float], None], speedup: float = 1.0,
                 max_ahead_s: float = 0.02, max_wait_s: float = 0.05) -> None:
        if not speedup > 0:
            raise ValueError(f"speedup must be positive, got {speedup!r}")
        self.vehicle_time_ns = vehicle_time_ns
        self.pump = pump
        self.speedup = float(speedup)
        self.max_ahead_ns = int(max_ahead_s * 1e9)
        self.max_wait_s = max_wait_s
        self._now = 0
        self._anchor_ns = -1
        self._anchor_wall = 0.0
        self._silent = False
        self.timeouts = 0

    def now_ns(self) -> int:
        v = self.vehicle_time_ns()
        wall = time.monotonic()
        if v != self._anchor_ns:
            self._anchor_ns, self._anchor_wall = v, wall
        ahead = min(int((wall - self._anchor_wall) * self.speedup * 1e9), self.max_ahead_ns)
        if v + ahead > self._now:
            self._now = v + ahead
        return self._now

    def sleep_until_ns(self, deadline_ns: int) -> None:
        heard = self._anchor_ns
        while True:
            now = self.now_ns()
            if now >= deadline_ns:
                break
            # Silent = no new time stamp for as long as the vehicle needs to reach the deadline from its
            # newest one (plus a grace, none once silent): a vehicle that speaks but lags is waited for.
            grace = 0.0 if self._silent and self._anchor_ns == heard else self.max_wait_s
            budget = (deadline_ns - self._anchor_ns) / 1e9 / self.speedup + grace
            quiet = time.monotonic() - self._anchor_wall
            if quiet >= budget - 1e-6:  # (a microsecond short is as good as there)
                self.timeouts += 1
                self._silent = True
                self._now = deadline_ns  # the vehicle is silent: its time goes on without it
                return
            self.pump(min(budget - quiet, max(0.0, (deadline_ns - now) / 1e9 / self.speedup), 0.005))
        if self._anchor_ns != heard:
            self._silent = False


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
