"""Telemetry age by the vehicle's own time stamps: VehicleTimeMap, Telemetry.age_s and Telemetry.fresh.

Real pymavlink messages, packed and parsed as they come off the wire (so ``get_srcComponent`` is the
sender's); loop times are given explicitly, never read from the machine's clock.
"""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.control import model_params
from gcs.estimate import StateEstimator
from gcs.flight.validate import TelemetryValidator
from gcs.vehicles.telemetry import OFFSET_DRIFT, Telemetry, VehicleTimeMap

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
    assert m.age_ns(123 * S, 5 * S) == 0


def test_time_map_age_of_on_time_samples():
    m = VehicleTimeMap()
    m.observe(10 * S, 5 * S)  # first sample: offset = arrival - stamp
    assert m.offset_ns == 5 * S
    assert m.age_ns(10 * S, 5 * S) == 0
    assert m.age_ns(10 * S, 5 * S - 200 * MS) == 200 * MS  # older stamp, same instant


def test_time_map_late_sample_does_not_move_the_floor_and_is_old():
    m = VehicleTimeMap()
    m.observe(10 * S, 5 * S)
    m.observe(12 * S, 6 * S)  # delivered 1 s later than the fastest one
    drift = int(OFFSET_DRIFT * 2 * S)
    assert m.offset_ns == 5 * S + drift  # only the drift allowance, not the late difference
    assert m.age_ns(12 * S, 6 * S) == 1 * S - drift


def test_time_map_floor_is_the_smallest_difference():
    m = VehicleTimeMap()
    m.observe(10 * S, 5 * S)
    m.observe(11 * S, 7 * S)  # faster than any before: the floor goes down to it
    assert m.offset_ns == 4 * S
    m.observe(12 * S, 7 * S + 500 * MS)  # slower again: the floor stays (plus drift)
    assert m.offset_ns == 4 * S + int(OFFSET_DRIFT * 1 * S)


def test_time_map_drift_is_bounded_by_offset_drift():
    """The floor rises by at most OFFSET_DRIFT per second of loop time (two crystals drifting apart)."""
    m = VehicleTimeMap()
    m.observe(0, 0)
    m.observe(1000 * S, 999 * S)  # 1 s more delay after 1000 s: only 0.1 s of it is drift
    assert m.offset_ns == int(OFFSET_DRIFT * 1000 * S)
    assert m.age_ns(1000 * S, 999 * S) == 1 * S - int(OFFSET_DRIFT * 1000 * S)
    # age_ns applies the allowance since the last observation too
    assert m.age_ns(1010 * S, 999 * S) == 11 * S - int(OFFSET_DRIFT * 1000 * S) - int(OFFSET_DRIFT * 10 * S)


@pytest.mark.parametrize(("ppm", "young"), [(50, True), (-300, True), (300, False)])
def test_time_map_follows_a_clock_drift_within_the_allowance(ppm, young):
    """100 s at 100 Hz, the vehicle's crystal off by ``ppm``: within OFFSET_DRIFT (100 ppm) nothing ages."""
    m = VehicleTimeMap()
    step = 10 * MS
    for k in range(10_000):
        arrival = k * step + int(k * step * ppm * 1e-6) + 3 * MS
        m.observe(arrival, k * step)
    age = m.age_ns(arrival, (10_000 - 1) * step)
    if young:
        assert 0 <= age <= 1 * MS
    else:
        assert age > 10 * MS  # 300 ppm of 100 s = 30 ms, 10 ms of it allowed


# --------------------------------------------------------------------------- Telemetry: real time
L0 = 5_000 * S  # the loop's monotonic clock
V0_MS = 60_000  # the vehicle booted 60 s ago


def live_100hz(tel: Telemetry, wire: Wire, wall: Wall, seconds: float = 2.0) -> int:
    """On-time telemetry at 100 Hz (2..4 ms delivery); the loop time of the last sample."""
    n = int(round(seconds * 100))
    arrivals = [L0 + k * 10 * MS + (2 + k % 3) * MS for k in range(n)]
    feed(tel, wire, wall, arrivals, [V0_MS + 10 * k for k in range(n)])
    return arrivals[-1]


def test_nothing_received_is_not_fresh(make_telemetry):
    tel = make_telemetry()
    assert tel.age_s("ATTITUDE", L0) == math.inf
    assert not tel.fresh(L0, 0.3)


def test_100hz_on_time_is_fresh(make_telemetry, wire):
    wall = Wall()
    tel = make_telemetry(wall)
    last = live_100hz(tel, wire, wall)
    assert tel.counts == {"ATTITUDE": 200, "LOCAL_POSITION_NED": 200}
    assert tel.validator.total == 0
    assert tel.fresh(last, 0.3)
    assert tel.fresh(last + 5 * MS, 0.3)
    for name in ("ATTITUDE", "LOCAL_POSITION_NED"):
        assert 0.0 <= tel.age_s(name, last) <= 0.005
    assert tel.vehicle_time_ns() == (V0_MS + 1990) * MS
    assert tel.stamp_ns["ATTITUDE"] == (V0_MS + 1990) * MS
    # it ages with the loop's clock (the last sample came 1 ms slower than the fastest: 1 ms older by its stamp)
    assert tel.age_s("ATTITUDE", last + 400 * MS) == pytest.approx(0.401, abs=0.0002)
    assert not tel.fresh(last + 400 * MS, 0.3)


def test_burst_of_samples_stamped_1s_ago_arriving_now_is_not_fresh(make_telemetry, wire):
    """The link stalled for 1 s, then delivered what it buffered: just arrived, but 1 s old."""
    wall = Wall()
    tel = make_telemetry(wall)
    live_100hz(tel, wire, wall)  # vehicle 60.00..61.99 s arriving at loop 5000.002..5001.994 s
    now = L0 + 3 * S  # the vehicle is at ~63.0 s now
    feed(tel, wire, wall, [now] * 5, [V0_MS + 2000 + 10 * j for j in range(5)])  # stamped 62.00..62.04 s
    assert tel.last_ns["ATTITUDE"] == now  # by arrival: brand new
    assert tel.age_s("ATTITUDE", now) == pytest.approx(0.958, abs=0.002)
    assert tel.age_s("LOCAL_POSITION_NED", now) == pytest.approx(0.958, abs=0.002)
    assert not tel.fresh(now, 0.3)
    assert tel.fresh(now, 1.0)

    # The link recovers: on-time samples are fresh again (the late burst did not move the floor).
    k0 = 300
    arrivals = [L0 + k * 10 * MS + 2 * MS for k in range(k0, k0 + 10)]
    feed(tel, wire, wall, arrivals, [V0_MS + 10 * k for k in range(k0, k0 + 10)])
    assert tel.fresh(arrivals[-1], 0.3)
    assert tel.age_s("ATTITUDE", arrivals[-1]) <= 0.005


def test_one_stream_late_is_enough_to_be_stale(make_telemetry, wire):
    wall = Wall()
    tel = make_telemetry(wall)
    live_100hz(tel, wire, wall)
    now = L0 + 3 * S
    wall.ns = now
    tel.handle(wire.attitude(V0_MS + 2990), now)  # on time
    tel.handle(wire.position(V0_MS + 2000), now)  # 1 s late
    assert tel.age_s("ATTITUDE", now) < 0.01
    assert tel.age_s("LOCAL_POSITION_NED", now) > 0.9
    assert not tel.fresh(now, 0.3)


def test_late_burst_is_old_when_the_vehicle_has_been_up_longer_than_the_ground_station(make_telemetry, wire):
    wall = Wall()
    tel = make_telemetry(wall)
    l0 = 100 * S  # ground station's monotonic clock: booted 100 s ago
    v0 = 3_600_000  # the vehicle has been up an hour
    n = 200
    feed(tel, wire, wall, [l0 + k * 10 * MS + 2 * MS for k in range(n)], [v0 + 10 * k for k in range(n)])
    now = l0 + 3 * S
    feed(tel, wire, wall, [now] * 5, [v0 + 2000 + 10 * j for j in range(5)])
    assert not tel.fresh(now, 0.3)


# --------------------------------------------------------------------------- Telemetry: the vehicle's own clock
def test_vehicle_clock_first_sample_ahead_of_now_does_not_age_later_ones(make_telemetry, wire):
    """Lockstep / paced: the loop's now is the newest stamp so far (0 before any telemetry).

    Regression: the first sample (stamped 2.1 s, the vehicle's boot) arriving at now = 0 set the floor to
    -2.1 s, and every later sample looked 2.1 s old.
    """
    wall = Wall()
    tel = make_telemetry(wall)
    tel.on_vehicle_clock = True  # the session sets it when the loop runs on the vehicle's clock
    t_ms = 2100
    for _ in range(100):
        now = tel.vehicle_time_ns()  # the clock: the newest vehicle time stamp received
        wall.ns += 10 * MS
        tel.handle(wire.attitude(t_ms), now)
        tel.handle(wire.position(t_ms), now)
        t_ms += 10
    now = tel.vehicle_time_ns()
    assert now == 3090 * MS
    assert tel.age_s("ATTITUDE", now) <= 0.011
    assert tel.age_s("LOCAL_POSITION_NED", now) <= 0.011
    assert tel.fresh(now, 0.3)
    assert tel.time_map.offset_ns is not None and tel.time_map.offset_ns >= 0


def test_vehicle_clock_silence_ages_by_the_clock(make_telemetry, wire):
    """On the vehicle's clock a silent vehicle ages as the (virtual) clock moves past its last stamp."""
    wall = Wall()
    tel = make_telemetry(wall)
    tel.on_vehicle_clock = True  # the session sets it when the loop runs on the vehicle's clock
    for k in range(10):
        now = tel.vehicle_time_ns()
        tel.handle(wire.attitude(1000 + 10 * k), now)
        tel.handle(wire.position(1000 + 10 * k), now)
    last = tel.vehicle_time_ns()
    assert tel.fresh(last, 0.3)
    assert not tel.fresh(last + 400 * MS, 0.3)


# --------------------------------------------------------------------------- Telemetry: other messages
def test_other_component_is_ignored(make_telemetry, wire):
    tel = make_telemetry()
    msg = wire.attitude(1000, comp=2)  # a gimbal or companion computer of the same system
    assert msg.get_srcComponent() == 2
    tel.handle(msg, L0)
    assert "ATTITUDE" not in tel.counts
    assert tel.age_s("ATTITUDE", L0) == math.inf
    assert tel.vehicle_time_ns() == 0
    msg = wire.attitude(1000, comp=1)
    assert msg.get_srcComponent() == 1
    tel.handle(msg, L0)
    assert tel.counts["ATTITUDE"] == 1
    assert tel.vehicle_time_ns() == 1000 * MS


def test_rejected_sample_is_not_stamped(make_telemetry, wire):
    tel = make_telemetry()
    tel.handle(wire.attitude(1000, roll=math.nan), L0)
    assert tel.validator.total == 1
    assert "ATTITUDE" not in tel.last_ns
    assert tel.time_map.offset_ns is None
    assert tel.vehicle_time_ns() == 0


def test_ekf_status_report_sets_the_flags(make_telemetry, wire):
    tel = make_telemetry()
    assert tel.status.ekf_flags is None
    flags = (mavlink.EKF_ATTITUDE | mavlink.EKF_VELOCITY_HORIZ | mavlink.EKF_VELOCITY_VERT
             | mavlink.EKF_POS_HORIZ_REL | mavlink.EKF_POS_VERT_ABS | mavlink.EKF_PRED_POS_HORIZ_REL)
    msg = wire(lambda m: m.ekf_status_report_encode(flags, 0.1, 0.2, 0.3, 0.4, 0.0))
    tel.handle(msg, L0)
    assert tel.status.ekf_flags == flags
    assert isinstance(tel.status.ekf_flags, int)
    tel.handle(wire(lambda m: m.ekf_status_report_encode(0, 0.1, 0.2, 0.3, 0.4, 0.0)), L0 + 1)
    assert tel.status.ekf_flags == 0
    assert tel.counts["EKF_STATUS_REPORT"] == 2


def test_autopilot_version_is_kept(make_telemetry, wire):
    tel = make_telemetry()
    assert tel.autopilot_version is None
    sw = (4 << 24) | (6 << 16) | (2 << 8) | 255
    msg = wire(lambda m: m.autopilot_version_encode(64 | 1024, sw, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0,
                                                     [0] * 18))
    tel.handle(msg, L0)
    assert tel.autopilot_version is msg
    assert tel.autopilot_version.flight_sw_version == sw
    assert tel.autopilot_version.capabilities == 64 | 1024
