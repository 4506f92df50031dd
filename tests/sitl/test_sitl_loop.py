"""The one server skeleton (:class:`sitl.net.loop.ServerLoop`) against a fake vehicle and a fake clock."""

from __future__ import annotations

import socket
import threading
import time

import pytest

from sitl.errors import SitlError, UsageError
from sitl.net.loop import THREAD_NAME, ServerLoop, ticks_per_step

TICK_NS = 5_000_000


class FakeClock:
    def __init__(self, now_ns: int = 0) -> None:
        self.now = now_ns

    def now_ns(self) -> int:
        return self.now


class FakeVehicle:
    """Counts what the loop asks of it; in lockstep, one step per ``pending_steps`` item."""

    def __init__(self) -> None:
        self.steps = 0
        self.time_ns = 0
        self.announced = 0
        self.flushed = 0
        self.pending_steps = 0
        self.released = 0

    def announce(self) -> None:
        self.announced += 1

    def take_input(self, now_ns: int) -> None:
        while self.pending_steps:
            self.pending_steps -= 1
            self.tick()
            self.steps += 1

    def tick(self) -> None:
        self.time_ns += TICK_NS

    def flush(self, now_ns: int) -> None:
        self.flushed += 1

    def release(self) -> None:
        self.released += 1


class FakeIo:
    """No transports: a socket pair the test writes to so that the loop's select returns."""

    def __init__(self) -> None:
        self.r, self.w = socket.socketpair()
        self.r.setblocking(False)

    def filenos(self) -> list[int]:
        try:
            while self.r.recv(4096):
                pass
        except BlockingIOError:
            pass
        return [self.r.fileno()]

    def write_filenos(self) -> list[int]:
        return []

    def flush_transports(self) -> None:
        pass

    def next_event_ns(self) -> int | None:
        return None

    def poke(self) -> None:
        self.w.send(b"x")

    def close(self) -> None:
        self.r.close()
        self.w.close()


def until(predicate, timeout: float = 5.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.005)
    return predicate()


@pytest.fixture
def parts():
    v, io, clock = FakeVehicle(), FakeIo(), FakeClock()
    yield v, io, clock
    io.close()


def make(parts, lockstep: bool) -> ServerLoop:
    v, io, clock = parts
    return ServerLoop(v, io, clock, lockstep=lockstep, tick_ns=TICK_NS, release=v.release, name="fake server")


def test_real_time_follows_the_clock_and_skips_ahead_after_a_second(parts):
    v, io, clock = parts
    loop = make(parts, lockstep=False)
    loop.start()
    try:
        assert until(lambda: v.announced == 1 and v.flushed >= 1)
        clock.now = 100_000_000
        io.poke()
        assert until(lambda: v.time_ns == 100_000_000)
        clock.now = 3_100_000_000                      # 3 s late: 1 s of ticks in a burst, then skip
        io.poke()
        assert until(lambda: loop.overruns == 1)
        with loop.lock:
            assert v.time_ns == 100_000_000 + 201 * TICK_NS
        clock.now += 20_000_000                        # and on from there at the clock's pace
        io.poke()
        assert until(lambda: v.time_ns == 100_000_000 + 205 * TICK_NS)
        assert loop.running and [t.name for t in threading.enumerate()].count(THREAD_NAME) >= 1
    finally:
        loop.stop()
    assert not loop.running and v.released == 1
    loop.close()
    assert v.released == 1                             # idempotent


def test_lockstep_never_ticks_and_announces_each_idle_second(parts):
    v, io, clock = parts
    loop = make(parts, lockstep=True)
    loop.start()
    try:
        assert until(lambda: v.announced == 1)
        clock.now = 900_000_000
        io.poke()
        time.sleep(0.05)
        assert v.announced == 1 and v.time_ns == 0
        clock.now = 1_000_000_000
        io.poke()
        assert until(lambda: v.announced == 2)
        v.pending_steps = 3                            # steps reset the idle second
        clock.now = 1_900_000_000
        io.poke()
        assert until(lambda: v.steps == 3)
        clock.now = 2_500_000_000
        io.poke()
        time.sleep(0.05)
        assert v.announced == 2
        clock.now = 2_900_000_000
        io.poke()
        assert until(lambda: v.announced == 3)
        assert v.time_ns == 3 * TICK_NS and loop.overruns == 0
    finally:
        loop.stop()


def test_a_failing_vehicle_is_re_raised_by_stop(parts):
    v, io, clock = parts

    def broken(now_ns: int) -> None:
        raise RuntimeError("boom")

    v.take_input = broken
    loop = make(parts, lockstep=True)
    loop.start()
    with pytest.raises(SitlError, match="already started"):
        loop.start()
    assert until(lambda: not loop.running)
    with pytest.raises(RuntimeError, match="boom"):
        loop.stop()
    assert v.released == 1


def test_ticks_per_step():
    assert ticks_per_step(0.01, 400, "inner-loop") == 4
    assert ticks_per_step(0.01, 200.0, "onboard") == 2
    for bad in (0.003, 0.0, -0.01, float("nan"), float("inf")):
        with pytest.raises(UsageError, match=r"multiple of the 2\.5 ms inner-loop period"):
            ticks_per_step(bad, 400, "inner-loop")
