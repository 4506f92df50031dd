"""AuthorityWatch: sustained saturation of the setpoints says the fault is past the vehicle's authority."""

from __future__ import annotations

import pytest

from gcs.flight.result import EXIT_CODES
from gcs.flight.authority import INTEGRAL_PINNED_S, THRUST_SATURATED_S, AuthorityWatch

TS = 0.01


def att(thrust: float) -> dict:
    return {"message": "SET_ATTITUDE_TARGET", "thrust": thrust}


def run(w: AuthorityWatch, seconds: float, fields: dict, airborne: bool = True, delta=None, max_rad=None) -> None:
    for _ in range(int(round(seconds / TS))):
        w.update(fields, airborne, delta, max_rad)


def test_thrust_at_its_top_for_a_second_in_the_air_is_past_authority():
    w = AuthorityWatch(TS)
    run(w, THRUST_SATURATED_S - 0.05, att(1.0))
    assert w.failure() is None
    run(w, 0.06, att(1.0))
    assert "thrust at its top" in w.failure()
    assert EXIT_CODES["out_of_authority"] == 13


def test_short_saturations_and_the_ground_do_not_count():
    w = AuthorityWatch(TS)
    for _ in range(20):  # 0.5 s saturated, one period below: never 1 s in a row
        run(w, 0.5, att(1.0))
        run(w, TS, att(0.99))
    run(w, 5.0, att(1.0), airborne=False)  # spooling up on the ground
    assert w.failure() is None


def test_actuator_output_thrust_is_read_from_its_controls():
    w = AuthorityWatch(TS)
    run(w, 1.1, {"message": "SET_ACTUATOR_CONTROL_TARGET", "controls": [0.0, 0.0, 0.0, 0.0, 1.0, 0, 0, 0]})
    assert "thrust" in w.failure()


@pytest.mark.parametrize(("axis", "name"), [(0, "roll"), (1, "pitch"), (2, "yaw")])
def test_the_rate_correction_pinned_at_its_bound_for_2s_names_the_axis(axis, name):
    w = AuthorityWatch(TS)
    lim = (0.1, 0.1, 0.2)
    delta = [0.0, 0.0, 0.0]
    delta[axis] = -lim[axis]
    run(w, INTEGRAL_PINNED_S - 0.05, att(0.5), delta=delta, max_rad=lim)
    assert w.failure() is None
    run(w, 0.06, att(0.5), delta=delta, max_rad=lim)
    assert f"{name} rate fell short" in w.failure()
    delta[axis] = 0.0
    run(w, 1.0, att(0.5), delta=delta, max_rad=lim)
    assert w.failure() is not None  # once said, it stays: the flight is landing


def test_a_correction_below_its_bound_or_off_is_fine():
    w = AuthorityWatch(TS)
    run(w, 10.0, att(0.6), delta=[0.09, -0.09, 0.19], max_rad=(0.1, 0.1, 0.2))  # 90-95 % of the bound
    run(w, 10.0, att(0.6), delta=[0.0, 0.0, 0.0], max_rad=(0.0, 0.0, 0.0))  # an axis off (bound 0)
    assert w.failure() is None


def test_bad_periods_are_refused():
    with pytest.raises(ValueError):
        AuthorityWatch(0.0)


def test_not_following_the_reference_for_2s_is_past_authority():
    from gcs.flight.authority import TRACKING_LOST_S, TrackingWatch
    from quadrotor.state import State

    w = TrackingWatch(TS)
    ref = State(0.0, 0.0, 1.5)
    for _ in range(1000):  # 0.9 m away for 10 s: not lost
        assert w.update(State(0.9, 0.0, 1.5), ref) is None
    for _ in range(int(TRACKING_LOST_S / TS) - 1):  # on the ground under a 1.5 m reference
        assert w.update(State(0.0, 0.0, 0.0), ref) is None
    assert "does not follow" in w.update(State(0.0, 0.0, 0.0), ref)


def test_the_tracking_watch_follows_its_config_keys_and_zero_turns_it_off(tmp_path):
    from gcs.config import load_config
    from gcs.errors import ConfigError
    from gcs.config.parse import resolve_config_path
    from gcs.flight.authority import TrackingWatch
    from quadrotor.state import State

    off = TrackingWatch(TS, 0.0, 2.0)
    assert all(off.update(State(0.0, 0.0, 0.0), State(0.0, 0.0, 9.0)) is None for _ in range(1000))
    base = load_config("outdoor-circle")
    assert (base.flight.tracking_lost_m, base.flight.tracking_lost_s) == (1.0, 2.0)
    text = resolve_config_path("outdoor-circle").read_text()
    for body, ok in (("tracking_lost_m = 0.0\ntracking_lost_s = 5.0\n", True), ("tracking_lost_s = 0.0\n", False)):
        f = tmp_path / "c.toml"
        f.write_text(text + "\n[flight]\n" + body)
        if ok:
            fc = load_config(f).flight
            assert (fc.tracking_lost_m, fc.tracking_lost_s) == (0.0, 5.0)
        else:
            with pytest.raises(ConfigError, match="tracking_lost_s"):
                load_config(f)
