"""PacedVehicleClock: the vehicle's own time for a vehicle that runs by itself (a firmware SITL at a speed-up).

The vehicle is faked: its time is a number, the pump records the waits it is asked for and moves that
number on.  The clock reads the wall (its budget, and how far it runs past the newest time stamp), so the
clock module's ``time`` is replaced by a fake wall that only the pump moves: nothing here depends on the
machine's speed.  One test runs on the real wall with a tiny budget.
"""

from __future__ import annotations

import math

import pytest

import gcs.flight.clock as clock_mod
from gcs.flight.clock import PacedVehicleClock

MS = 1_000_000


class FakeWall:
    """Stands in for the ``time`` module inside gcs.flight.clock: ``monotonic()`` moves only when told."""

    def __init__(self) -> None:
        self.t = 1000.0

    def monotonic(self) -> float:
        return self.t


class FakeVehicle:
    """Vehicle time [ns] and a pump that records every ``wait_s``.

    Each pump call runs the vehicle ``step_ns`` on; the fake wall (if any) moves by ``wall_step_s``, or,
    when that is None, by ``wait_s`` while the vehicle is silent (a real pump would have waited for nothing)
    and not at all while it answers at once.
    """

    def __init__(self, t_ns: int = 0, step_ns: int = 0, wall: FakeWall | None = None,
                 wall_step_s: float | None = None) -> None:
        self.t_ns = t_ns
        self.step_ns = step_ns
        self.wall = wall
        self.wall_step_s = wall_step_s
        self.waits: list[float] = []

    def time_ns(self) -> int:
        return self.t_ns

    def pump(self, wait_s: float) -> None:
        self.waits.append(wait_s)
        self.t_ns += self.step_ns
        if self.wall is not None:
            if self.wall_step_s is not None:
                self.wall.t += self.wall_step_s
            elif not self.step_ns:
                self.wall.t += wait_s


@pytest.fixture
def wall(monkeypatch) -> FakeWall:
    w = FakeWall()
    monkeypatch.setattr(clock_mod, "time", w)
    return w


def paced(v: FakeVehicle, **kw) -> PacedVehicleClock:
    return PacedVehicleClock(v.time_ns, v.pump, **kw)


@pytest.mark.parametrize("speedup", [0, 0.0, -1.0, math.nan])
def test_speedup_must_be_positive(speedup):
    with pytest.raises(ValueError, match="speedup"):
        PacedVehicleClock(lambda: 0, lambda w: None, speedup=speedup)


def test_not_lockstep_and_now_is_vehicle_time(wall):
    v = FakeVehicle(t_ns=1234 * MS)
    c = paced(v, speedup=5)
    assert c.lockstep is False
    assert c.speedup == 5.0
    assert c.now_ns() == 1234 * MS
    v.t_ns = 2000 * MS
    assert c.now_ns() == 2000 * MS


def test_now_never_goes_back(wall):
    v = FakeVehicle(t_ns=2000 * MS)
    c = paced(v, speedup=1)
    assert c.now_ns() == 2000 * MS
    v.t_ns = 1500 * MS  # e.g. a stale sample taken as the newest
    assert c.now_ns() == 2000 * MS


def test_between_time_stamps_now_runs_on_the_wall_up_to_max_ahead(wall):
    v = FakeVehicle(t_ns=100 * MS)
    c = paced(v, speedup=5, max_ahead_s=0.02)
    assert c.now_ns() == 100 * MS  # anchored: the newest time stamp, just heard
    wall.t += 0.002  # 2 ms of wall at 5x: 10 ms of vehicle time
    assert abs(c.now_ns() - 110 * MS) <= 1
    wall.t += 1.0  # no more than max_ahead past the newest stamp
    assert c.now_ns() == 120 * MS
    v.t_ns = 130 * MS  # a new stamp: the clock follows it (anchored again)
    assert c.now_ns() == 130 * MS


def test_sleep_returns_once_vehicle_time_reaches_the_deadline(wall):
    v = FakeVehicle(t_ns=100 * MS, step_ns=3 * MS, wall=wall)  # answers at once: the wall does not move
    c = paced(v, speedup=10, max_wait_s=0.05)
    c.sleep_until_ns(110 * MS)
    assert v.t_ns == 112 * MS  # 100 -> 103 -> 106 -> 109 -> 112: the first time >= deadline
    assert len(v.waits) == 4
    assert v.waits[0] == pytest.approx(0.001)  # no longer than (deadline - now) / speedup
    assert all(0 < w <= 0.005 for w in v.waits)  # the link is pumped in small slices
    assert c.timeouts == 0
    assert c.now_ns() == 112 * MS
    assert c._silent is False


def test_pump_slices_are_at_most_5_ms(wall):
    v = FakeVehicle(t_ns=0, step_ns=1 * MS, wall=wall)
    c = paced(v, speedup=1, max_wait_s=0.05)
    c.sleep_until_ns(2 * MS)
    assert v.waits[0] == pytest.approx(0.002)
    c.sleep_until_ns(100 * MS)
    assert v.waits[2] == pytest.approx(0.005)
    assert max(v.waits) <= 0.005
    assert c.timeouts == 0


def test_deadline_reached_exactly_stops_pumping(wall):
    v = FakeVehicle(t_ns=0, step_ns=10 * MS, wall=wall)
    c = paced(v, speedup=1, max_wait_s=0.05)
    c.sleep_until_ns(10 * MS)
    assert v.t_ns == 10 * MS
    assert len(v.waits) == 1


def test_deadline_in_the_past_returns_without_pumping(wall):
    v = FakeVehicle(t_ns=500 * MS, step_ns=10 * MS, wall=wall)
    c = paced(v, speedup=2)
    c.sleep_until_ns(500 * MS)
    c.sleep_until_ns(400 * MS)
    assert v.waits == []
    assert c.timeouts == 0
    assert c.now_ns() == 500 * MS


def test_ticks_follow_vehicle_time(wall):
    """A loop of 10 ms periods: each sleep ends on the vehicle's telemetry of that period."""
    v = FakeVehicle(t_ns=0, step_ns=10 * MS, wall=wall)
    c = paced(v, speedup=50)
    for k in range(1, 21):
        c.sleep_until_ns(k * 10 * MS)
        assert c.now_ns() == k * 10 * MS
    assert c.timeouts == 0
    assert len(v.waits) == 20


def test_sparse_telemetry_ticks_fall_on_their_deadlines(wall):
    """Telemetry every 20 ms of vehicle time, a loop of 10 ms: the tick between two stamps is on the wall."""
    w0 = wall.t
    speedup = 4.0

    class Sparse(FakeVehicle):
        def pump(self, wait_s):
            self.waits.append(wait_s)
            wall.t += wait_s
            true_ns = (wall.t - w0) * speedup * 1e9
            self.t_ns = int(true_ns // (20 * MS)) * 20 * MS

    v = Sparse(t_ns=0)
    c = paced(v, speedup=speedup, max_ahead_s=0.02)
    for k in range(1, 11):
        c.sleep_until_ns(k * 10 * MS)
        assert k * 10 * MS <= c.now_ns() <= v.t_ns + 20 * MS
    assert c.timeouts == 0


def test_a_vehicle_slower_than_the_speedup_holds_the_clock_back(wall):
    """Asked for 10x, running at 2x (a SITL starved of CPU): the clock stays within max_ahead of it."""
    v = FakeVehicle(t_ns=0, step_ns=1 * MS, wall=wall, wall_step_s=0.0005)
    c = paced(v, speedup=10, max_ahead_s=0.02, max_wait_s=0.05)
    for k in range(1, 51):
        c.sleep_until_ns(k * 10 * MS)
        assert c.now_ns() >= k * 10 * MS
        assert c.now_ns() - v.t_ns <= 20 * MS
    assert c.timeouts == 0
    assert v.t_ns >= 480 * MS  # the loop waited for the vehicle's time, not only the wall's


def test_silent_vehicle_times_out_on_the_real_wall():
    """The real wall: a silent vehicle is waited for about (deadline - now) / speedup + max_wait_s (tiny here)."""
    v = FakeVehicle(t_ns=1000 * MS)
    c = paced(v, speedup=50, max_ahead_s=0.0, max_wait_s=0.001)
    c.sleep_until_ns(1010 * MS)
    assert c.timeouts == 1
    assert c._silent is True
    assert c.now_ns() == 1010 * MS  # virtual time: the deadline, the vehicle's own time stands still
    assert v.t_ns == 1000 * MS
    assert v.waits and all(0 < w <= 0.005 for w in v.waits)
    c.sleep_until_ns(1020 * MS)  # still silent: times out again, virtual time goes on
    assert c.timeouts == 2
    assert c.now_ns() == 1020 * MS


def test_silent_vehicle_budget_and_no_grace_once_silent(wall):
    v = FakeVehicle(t_ns=1000 * MS, wall=wall)
    c = paced(v, speedup=4, max_ahead_s=0.02, max_wait_s=0.2)

    t0 = wall.t
    c.sleep_until_ns(1040 * MS)  # 40 ms of vehicle time at 4x = 10 ms of wall, plus 200 ms of grace
    assert wall.t - t0 == pytest.approx(0.010 + 0.2, abs=1e-9)
    assert c.timeouts == 1
    assert c._silent is True
    assert c.now_ns() == 1040 * MS
    assert all(0 < w <= 0.005 for w in v.waits)

    # Silent: the clock runs at 4x the wall from the newest stamp (1000 ms at t0): 210 ms of wall later it
    # owes 840 ms, so deadlines up to 1840 ms are reached at once, later ones at 4x the wall, no grace.
    t1 = wall.t
    c.sleep_until_ns(1080 * MS)
    assert wall.t == t1
    assert c.timeouts == 2
    assert c.now_ns() == 1080 * MS
    c.sleep_until_ns(1880 * MS)  # 40 ms past the silent line: 10 ms of wall
    assert wall.t - t1 == pytest.approx(0.010, abs=1e-9)
    assert c.timeouts == 3
    c.sleep_until_ns(1880 * MS)

    t2 = wall.t
    c.sleep_until_ns(1080 * MS)  # virtual time already there: no wait at all
    assert wall.t == t2
    assert c.timeouts == 3


def test_silent_within_max_ahead_is_no_timeout(wall):
    """A deadline within max_ahead of the newest stamp is reached on the wall alone."""
    v = FakeVehicle(t_ns=1000 * MS, wall=wall)
    c = paced(v, speedup=1, max_ahead_s=0.02, max_wait_s=0.05)
    c.sleep_until_ns(1010 * MS)
    assert c.timeouts == 0
    assert c.now_ns() >= 1010 * MS


def test_virtual_deadline_is_the_base_of_the_next_budget(wall):
    """After a timeout the next nominal wait is counted from the virtual time, not the stale vehicle time."""
    v = FakeVehicle(t_ns=0, wall=wall)
    c = paced(v, speedup=1, max_ahead_s=0.0, max_wait_s=0.0)
    c.sleep_until_ns(100 * MS)
    assert c.now_ns() == 100 * MS
    t1 = wall.t
    c.sleep_until_ns(110 * MS)  # 10 ms from the virtual 100 ms, not 110 ms from the vehicle's 0
    assert wall.t - t1 == pytest.approx(0.010, abs=1e-9)
    assert c.timeouts == 2


def test_vehicle_speaks_again_and_the_clock_follows_it(wall):
    v = FakeVehicle(t_ns=1000 * MS, wall=wall)
    c = paced(v, speedup=10, max_ahead_s=0.0, max_wait_s=0.05)
    c.sleep_until_ns(1010 * MS)
    c.sleep_until_ns(1020 * MS)
    assert c.timeouts == 2 and c._silent is True

    # The vehicle ran on by itself meanwhile: its telemetry comes back ahead of the virtual time.
    v.t_ns = 1025 * MS
    v.step_ns = 10 * MS
    waits_before = len(v.waits)
    c.sleep_until_ns(1030 * MS)
    assert c.timeouts == 2
    assert c._silent is False
    assert c.now_ns() == 1035 * MS == v.t_ns  # vehicle time, not the virtual deadline
    assert len(v.waits) == waits_before + 1

    # Live again: the grace is back (a slow answer is waited for beyond the nominal budget).
    v.step_ns = 0
    t0 = wall.t
    c.sleep_until_ns(1045 * MS)
    assert wall.t - t0 == pytest.approx(0.001 + 0.05, abs=1e-9)
    assert c.timeouts == 3
    assert c.now_ns() == 1045 * MS


def test_vehicle_ahead_of_the_deadline_returns_at_once_after_silence(wall):
    v = FakeVehicle(t_ns=0, wall=wall)
    c = paced(v, speedup=1, max_ahead_s=0.0, max_wait_s=0.0)
    c.sleep_until_ns(10 * MS)
    assert c.timeouts == 1
    v.t_ns = 500 * MS  # a burst of telemetry arrived between the ticks
    n = len(v.waits)
    c.sleep_until_ns(20 * MS)
    assert len(v.waits) == n  # nothing to wait for
    assert c.now_ns() == 500 * MS
    assert c.timeouts == 1


def test_a_vehicle_whose_time_paused_is_followed_again_once_it_speaks(wall):
    """A SITL stopped for a while (starved of CPU, SIGSTOP), then running at its speed-up again."""
    speedup = 1.0
    vehicle = {"true_ns": 0.0, "frozen": False}

    class Sitl(FakeVehicle):
        def pump(self, wait_s):  # 100 Hz telemetry of a vehicle running at the speed-up (unless frozen)
            wall.t += wait_s
            if not vehicle["frozen"]:
                vehicle["true_ns"] += wait_s * speedup * 1e9
                self.t_ns = int(vehicle["true_ns"] // (10 * MS)) * 10 * MS

    v = Sitl(t_ns=0)
    c = paced(v, speedup=speedup, max_ahead_s=0.02, max_wait_s=0.05)
    ticks = iter(range(1, 10_000))
    for _ in range(20):
        c.sleep_until_ns(next(ticks) * 10 * MS)
    assert c.timeouts == 0
    vehicle["frozen"] = True
    for _ in range(20):  # 200 ms of the vehicle's time lost
        c.sleep_until_ns(next(ticks) * 10 * MS)
    assert c.timeouts > 0
    vehicle["frozen"] = False
    for _ in range(10):  # it speaks again
        c.sleep_until_ns(next(ticks) * 10 * MS)
    after = c.timeouts
    for _ in range(100):
        c.sleep_until_ns(next(ticks) * 10 * MS)
    assert c.timeouts == after  # followed again: no more timeouts
    assert c.now_ns() - v.t_ns <= 20 * MS
