"""Telemetry age by the vehicle's own time stamps: VehicleTimeMap, Telemetry.age_s and Telemetry.fresh.

Real pymavlink messages, packed and parsed as they come off the wire (so ``get_srcComponent`` is the
sender's); loop times are given explicitly, never read from the machine's clock.
"""

from __future__ import annotations


import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.control import model_params
from gcs.estimate import StateEstimator
from gcs.flight.validate import TelemetryValidator
from gcs.vehicles.telemetry import Telemetry, VehicleTimeMap

MS = 1_000_000
S = 1_000_000_000


# --------------------------------------------------------------------------- helpers
class Wire:
    """Packs messages as a vehicle (system 1, component ``comp``) and parses them as the ground station does."""

    def __init__(self) -> None:
        self.rx = mavlink.MAVLink(None)
        self.tx = {c: mavlink.MAVLink(None, srcSystem=1, srcComponent=c) for c in (1, 2)}

    def __call__(self, build, comp: int = 1):
        tx = self.tx[comp]
        out = self.rx.parse_buffer(build(tx).pack(tx))
        assert out is not None and len(out) == 1
        return out[0]

    def attitude(self, t_ms: int, comp: int = 1, roll: float = 0.01):
        return self(lambda m: m.attitude_encode(t_ms, roll, -0.02, 0.3, 0.0, 0.0, 0.0), comp)

    def position(self, t_ms: int, comp: int = 1):
        return self(lambda m: m.local_position_ned_encode(t_ms, 1.0, 2.0, -3.0, 0.1, 0.0, 0.0), comp)


class Wall:
    """The validator's wall clock (its time-leap check), moved by the test alongside the loop time."""

    def __init__(self) -> None:
        self.ns = 0

    def __call__(self) -> int:
        return self.ns


@pytest.fixture
def wire() -> Wire:
    return Wire()


@pytest.fixture
def make_telemetry(circle):
    """Telemetry as gcs.vehicles.mavlink builds it (its estimator from the config), with an injected wall."""
    fc = circle.flight

    def make(wall: Wall | None = None, **kw) -> Telemetry:
        est = StateEstimator(circle.experiment.ts_s, model_params(circle), (fc.position_std_m,) * 3,
                             circle.estimator.accel_noise_std_m_s2, ground_z_m=None)
        validator = TelemetryValidator(wall_ns=wall or Wall())
        return Telemetry(est, (fc.position_std_m ** 2,) * 3, (fc.velocity_std_m_s ** 2,) * 3, validator=validator,
                         **kw)
    return make


def feed(tel: Telemetry, wire: Wire, wall: Wall, arrivals_ns, stamps_ms) -> None:
    """ATTITUDE and LOCAL_POSITION_NED stamped ``stamps_ms`` arriving at loop times ``arrivals_ns``."""
    for now, t_ms in zip(arrivals_ns, stamps_ms):
        wall.ns = now
        tel.handle(wire.attitude(t_ms), now)
        tel.handle(wire.position(t_ms), now)


# --------------------------------------------------------------------------- VehicleTimeMap
def test_time_map_before_any_sample_gives_age_zero():
    m = VehicleTimeMap()
    assert m.offset_ns is None
    assert m.vehicle_time_ns(123 * S) is None
    assert m.age_ns(123 * S, 5 * S) == 0
    assert m.rate == 1.0


def test_time_map_age_of_on_time_samples():
    m = VehicleTimeMap()
    m.observe(10 * S, 5 * S)  # first sample: offset = arrival - stamp
    assert m.offset_ns == 5 * S
    assert m.age_ns(10 * S, 5 * S) == 0
    assert m.age_ns(10 * S, 5 * S - 200 * MS) == 200 * MS  # older stamp, same instant
    assert m.vehicle_time_ns(10 * S + 30 * MS) == 5 * S + 30 * MS


def test_time_map_late_sample_does_not_move_the_floor_and_is_old():
    m = VehicleTimeMap()
    m.observe(10 * S, 5 * S)
    m.observe(12 * S, 6 * S)  # delivered 1 s later than the fastest one
    assert m.offset_ns == 5 * S  # the floor did not rise to the late difference
    assert m.age_ns(12 * S, 6 * S) == 1 * S


def test_time_map_floor_is_the_smallest_difference():
    m = VehicleTimeMap()
    m.observe(10 * S, 5 * S)
    m.observe(11 * S, 7 * S)  # faster than any before: the floor goes down to it
    assert m.offset_ns == 4 * S
    m.observe(12 * S, 7 * S + 500 * MS)  # slower again: the floor does not rise to it
    assert m.offset_ns <= 4 * S


class VehicleClock:
    """A vehicle whose clock runs at ``rate`` of the loop's, streaming at 100 Hz with 2..6 ms deliveries."""

    def __init__(self, rate: float, boot_ms: int = 60_000, l0_ns: int = 5_000 * S, seed: int = 1) -> None:
        import random
        self.rate, self.boot_ns, self.l0 = rate, boot_ms * MS, l0_ns
        self.rng = random.Random(seed)
        self.t_ns = 0  # loop time since the start

    def stamp(self, t_ns: int) -> int:
        """The vehicle's stamp (whole ms, as time_boot_ms) of a sample taken at loop time l0 + t_ns."""
        return (self.boot_ns + int(self.rate * t_ns)) // MS * MS

    def run(self, m: VehicleTimeMap, seconds: float) -> tuple[int, int]:
        """Stream for ``seconds``; the (arrival, stamp) of the last sample."""
        for _ in range(int(round(seconds * 100))):
            self.t_ns += 10 * MS
            arrival = self.l0 + self.t_ns + self.rng.randint(2, 6) * MS
            stamp = self.stamp(self.t_ns)
            m.observe(arrival, stamp)
        return arrival, stamp


@pytest.mark.parametrize("rate", [0.9, 0.95, 0.988, 1.0, 1.05, 1.1])
def test_time_map_tracks_a_vehicle_clock_at_its_own_rate(rate):
    """120 s at 100 Hz: on-time samples stay young and the rate is estimated, 0.9..1.1.

    The first 1.5 s at most, before the history spans two bins, is taken at rate 1 (0.15 s at 0.9);
    the old map (a floor rising 1e-4 s/s) made them (1 - rate) * t old: 0.3 s at t = 25 s at 0.988."""
    m = VehicleTimeMap()
    v = VehicleClock(rate)
    warm, worst = 0, 0
    for k in range(1200):
        arrival, stamp = v.run(m, 0.1)
        age = m.age_ns(arrival, stamp)
        assert age >= -5 * MS  # a delivery faster than the fitted floor (jitter 4 ms)
        if k < 20:
            warm = max(warm, age)
        else:
            worst = max(worst, age)
    assert warm <= max(0.0, 1 - rate) * 1.5 * S + 10 * MS
    assert worst <= 10 * MS
    assert m.rate == pytest.approx(rate, abs=2e-3)
    assert m.mean_rate == pytest.approx(rate, abs=1e-3)
    # between samples, the vehicle's time moves at its rate
    assert (m.vehicle_time_ns(arrival + 1 * S) - m.vehicle_time_ns(arrival)) / S == pytest.approx(rate, abs=2e-3)


@pytest.mark.parametrize("rate", [0.95, 0.988, 1.0, 1.05])
@pytest.mark.parametrize("stall_s", [0.5, 2.0])
def test_time_map_a_backlog_after_a_stall_is_old_at_any_rate(rate, stall_s):
    """The link (or the ground station) stalls ``stall_s``, then delivers what was buffered at once:
    just arrived, but as old as the stall; fresh again once on-time samples flow."""
    m = VehicleTimeMap()
    v = VehicleClock(rate)
    v.run(m, 30.0)
    taken = [v.t_ns + k * 10 * MS for k in range(1, int(stall_s * 100) + 1)]
    v.t_ns = taken[-1]
    burst = v.l0 + v.t_ns + 5 * MS  # everything arrives at the stall's end
    for t in taken:
        m.observe(burst, v.stamp(t))
    oldest, newest = v.stamp(taken[0]), v.stamp(taken[-1])
    assert m.age_ns(burst, oldest) == pytest.approx(stall_s * rate * S, abs=30 * MS)
    assert m.age_ns(burst, oldest) > 0.3 * S  # older than the stale timeout
    assert m.age_ns(burst, newest) < 20 * MS  # the last one was taken just now
    arrival, stamp = v.run(m, 2.0)
    assert 0 <= m.age_ns(arrival, stamp) < 20 * MS
    assert m.rate == pytest.approx(rate, abs=3e-3)


@pytest.mark.parametrize("rate", [0.95, 0.988, 1.05])
def test_time_map_a_link_delivering_late_for_2s_is_old_throughout(rate):
    """A radio that buffers: for 2 s every sample arrives 0.4 s late; each is seen 0.4 s old."""
    m = VehicleTimeMap()
    v = VehicleClock(rate)
    v.run(m, 20.0)
    ages = []
    for _ in range(200):
        v.t_ns += 10 * MS
        arrival = v.l0 + v.t_ns + 400 * MS
        m.observe(arrival, v.stamp(v.t_ns))
        ages.append(m.age_ns(arrival, v.stamp(v.t_ns)))
    assert min(ages) > 0.35 * S




def test_time_map_a_vehicle_clock_that_pauses_reports_its_long_run_rate():
    """A SITL on a loaded machine: its clock (and its physics) stop for 0.4 s now and then while
    ours runs on.  The windowed slope may swing to its bound after a pause; the rate since the
    first sample (the summary's vehicle_clock_rate) is the long-run one, and on-time samples after
    each pause are young again within a few seconds."""
    m = VehicleTimeMap()
    v = VehicleClock(0.988)
    v.run(m, 20.0)
    paused_ns = 0
    for _ in range(3):
        v.l0 += 400 * MS  # the vehicle's clock stands still 0.4 s of ours
        paused_ns += 400 * MS
        v.run(m, 10.0)
    arrival, stamp = v.run(m, 0.1)
    elapsed_s = (arrival - v.l0 + paused_ns) / S
    expected = 0.988 * (elapsed_s - paused_ns / S) / elapsed_s
    assert m.mean_rate == pytest.approx(expected, abs=3e-3)
    assert 0 <= m.age_ns(arrival, stamp) < 20 * MS
