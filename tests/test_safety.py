import math

import pytest

from gcs.flight.safety import EnvelopeLimits, SafetyEnvelope
from quadrotor.state import Command, State

LIM = EnvelopeLimits(max_thrust_n=20.0, max_angular_accel_rad_s2=50.0, max_tilt_rad=math.radians(30),
                     fence_half_width_m=10.0, ceiling_m=5.0)


def test_inside_the_envelope_nothing_changes():
    cmd = Command(9.81, 1.0, -1.0, 0.5)
    assert SafetyEnvelope(LIM).apply(State(z=1.0), cmd) == (cmd, frozenset())


def test_thrust_and_torque_are_clipped():
    out, flags = SafetyEnvelope(LIM).apply(State(z=1.0), Command(30.0, 80.0, -90.0, 10.0))
    assert out == Command(20.0, 50.0, -50.0, 10.0) and flags == {"thrust", "torque"}
    out, flags = SafetyEnvelope(LIM).apply(State(z=1.0), Command(-1.0, 0, 0, 0))
    assert out.thrust_n == 0.0 and flags == {"thrust"}


def test_tilt_beyond_the_limit_is_levelled_not_increased():
    s = State(z=1.0, roll=math.radians(35), roll_rate=0.5)
    out, flags = SafetyEnvelope(LIM).apply(s, Command(9.81, 10.0, 0.0, 0.0))
    assert out.roll_accel_rad_s2 < 0 and "tilt" in flags
    out, flags = SafetyEnvelope(LIM).apply(s, Command(9.81, -10.0, 0.0, 0.0))  # already levelling: kept
    assert out.roll_accel_rad_s2 == -10.0 and "tilt" not in flags


def test_fence_and_ceiling_are_reported():
    env = SafetyEnvelope(LIM)
    assert env.apply(State(x=10.5, z=1.0), Command(9.81, 0, 0, 0))[1] == {"geofence"}
    assert env.breaches(State(z=5.5)) == {"ceiling"}
    with pytest.raises(ValueError):
        EnvelopeLimits(0.0, 1.0, 1.0, 1.0, 1.0)
