"""6-DOF plant, mixer, frames and the reduced-model option."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadrotor import frames
from quadrotor import plant as reduced
from sitl.copter import rigid_body
from sitl.copter.mixer import Mixer
from sitl.copter.rigid_body import RigidBodyModel, RigidBodyState, initial_state, rotor_wrench
from sitl.copter.vehicle_file import load_vehicle
from sitl.copter.world import ReducedPlant, RigidBodyPlant

V = load_vehicle("quad-1kg")
MODEL = RigidBodyModel(V)
HOVER_N = V.mass_kg * V.gravity_m_s2 / 4.0

finite = st.floats(-1e3, 1e3, allow_nan=False)
angle = st.floats(-3.0, 3.0)


def airborne(alt: float = 100.0, thrust: float = HOVER_N, **kw) -> RigidBodyState:
    return initial_state(alt)._replace(on_ground=False, t1=thrust, t2=thrust, t3=thrust, t4=thrust, **kw)


def run(state, cmd, seconds, dt=0.001, wind=(0.0, 0.0, 0.0), model=MODEL):
    for _ in range(int(round(seconds / dt))):
        state = rigid_body.step(state, cmd, dt, model, wind)
    return state


def test_hover_is_an_equilibrium():
    s = run(airborne(), (HOVER_N,) * 4, 2.0)
    assert abs(s.d + 100.0) < 1e-9 and abs(s.vd) < 1e-9
    assert (s.qw, s.qx, s.qy, s.qz) == pytest.approx((1, 0, 0, 0), abs=1e-12)


def test_free_fall_with_linear_drag():
    c, m, g = V.drag.vertical_n_per_m_s, V.mass_kg, V.gravity_m_s2
    vehicle = V.__class__(**{**V.__dict__, "drag": V.drag.__class__(vertical_n_per_m_s=c, linear_n_per_m_s=c)})
    s = run(airborne(thrust=0.0), (0.0,) * 4, 1.0, model=RigidBodyModel(vehicle))
    exact = m * g / c * (1.0 - math.exp(-c / m * 1.0))
    assert s.vd == pytest.approx(exact, rel=2e-3)


def test_torque_gives_angular_acceleration_through_inertia():
    d = V.rotors.arm_length_m / math.sqrt(2.0)
    dt_n = 0.1
    # steady rotors with a roll differential: motors 2, 3 (left) up, 1, 4 (right) down
    th = (HOVER_N - dt_n, HOVER_N + dt_n, HOVER_N + dt_n, HOVER_N - dt_n)
    s = airborne()._replace(t1=th[0], t2=th[1], t3=th[2], t4=th[3])
    s = run(s, th, 0.01, dt=0.0001)
    tau = 4.0 * d * dt_n
    rot = V.drag.rotational_n_m_s
    assert s.p == pytest.approx(tau / V.inertia_kg_m2[0][0] * 0.01, rel=0.02 + rot * 10)
    assert abs(s.q) < 1e-9 and abs(s.r) < 1e-9
    f, tx, ty, tz = rotor_wrench(th, V)
    assert (f, tx, ty, tz) == pytest.approx((4 * HOVER_N, tau, 0.0, 0.0), abs=1e-12)


def test_full_inertia_matrix_couples_axes():
    j = ((0.01, 0.002, 0.0), (0.002, 0.01, 0.0), (0.0, 0.0, 0.018))
    vehicle = V.__class__(**{**V.__dict__, "inertia_kg_m2": j,
                             "drag": V.drag.__class__(rotational_n_m_s=0.0)})
    model = RigidBodyModel(vehicle)
    th = (HOVER_N - 0.1, HOVER_N + 0.1, HOVER_N + 0.1, HOVER_N - 0.1)
    s = airborne()._replace(t1=th[0], t2=th[1], t3=th[2], t4=th[3])
    s = rigid_body.step(s, th, 1e-4, model)
    tau = rotor_wrench(th, vehicle)[1]
    det = 0.01 * 0.01 - 0.002 ** 2
    assert s.p == pytest.approx(0.01 / det * tau * 1e-4, rel=1e-6)
    assert s.q == pytest.approx(-0.002 / det * tau * 1e-4, rel=1e-6)


def test_constant_yaw_rate_integrates_exactly_and_quaternion_stays_unit():
    s = airborne()._replace(r=1.0)
    model = RigidBodyModel(V.__class__(**{**V.__dict__, "drag": V.drag.__class__(rotational_n_m_s=0.0)}))
    s = run(s, (HOVER_N,) * 4, 1.5, model=model)
    _, _, yaw = frames.quaternion_to_euler((s.qw, s.qx, s.qy, s.qz))
    assert yaw == pytest.approx(1.5, abs=1e-9)
    assert frames.quat_norm((s.qw, s.qx, s.qy, s.qz)) == pytest.approx(1.0, abs=1e-12)


def test_motor_first_order_lag():
    s = airborne(thrust=0.0)
    s = run(s, (4.0,) * 4, V.rotors.time_constant_s, dt=0.0005)
    assert s.t1 == pytest.approx(4.0 * (1 - math.exp(-1)), rel=1e-9)
    s = run(s, (100.0,) * 4, 1.0)
    assert s.t1 == pytest.approx(V.rotors.max_thrust_n, rel=1e-6)  # thrust limit


def test_ground_contact_landed_takeoff_touchdown():
    s = initial_state(0.0, yaw=0.5)
    assert s.on_ground
    s = run(s, (HOVER_N * 0.9,) * 4, 1.0)
    assert s.on_ground and s.d == 0.0 and s.vd == 0.0          # landed: stays
    s = run(s, (HOVER_N * 1.3,) * 4, 1.0)
    assert not s.on_ground and s.d < -0.5 and s.vd < 0           # taking off
    s = s._replace(qw=math.cos(0.2), qx=math.sin(0.2), p=1.0)   # tilted, rolling
    s = run(s, (0.0,) * 4, 3.0)
    assert s.on_ground and s.d == 0.0                            # touched down ...
    assert (s.vn, s.ve, s.vd, s.p, s.q, s.r) == (0.0,) * 6       # ... stopped ...
    roll, pitch, yaw = frames.quaternion_to_euler((s.qw, s.qx, s.qy, s.qz))
    assert roll == pytest.approx(0, abs=1e-12) and pitch == pytest.approx(0, abs=1e-12)  # ... and levelled


def test_tilted_vehicle_rests_on_a_slope():
    s = initial_state(0.0, roll=math.radians(20))
    s2 = run(s, (HOVER_N * 0.9,) * 4, 0.5)
    assert s2.on_ground and (s2.qw, s2.qx) == (s.qw, s.qx)


def test_wind_drags_a_hovering_vehicle_to_wind_speed():
    s = run(airborne(), (HOVER_N,) * 4, 60.0, dt=0.002, wind=(3.0, -1.0, 0.0))
    assert (s.vn, s.ve) == pytest.approx((3.0, -1.0), abs=0.01)


@settings(max_examples=300, deadline=None)
@given(st.floats(0, 24.5), st.floats(-1, 1), st.floats(-1, 1), st.floats(-0.2, 0.2))
def test_mixer_limits_and_inverse(thrust, tx, ty, tz):
    mixer = Mixer(V)
    r = mixer.mix(thrust, tx, ty, tz)
    lo, hi = V.rotors.min_thrust_n, V.rotors.max_thrust_n
    assert all(lo - 1e-9 <= t <= hi + 1e-9 for t in r.thrusts)
    f, ox, oy, oz = rotor_wrench(r.thrusts, V)
    if not (r.rp_limited or r.yaw_limited or r.thrust_limited):
        assert (f, ox, oy, oz) == pytest.approx((thrust, tx, ty, tz), abs=1e-9)
    if not r.rp_limited:
        assert (ox, oy) == pytest.approx((tx, ty), abs=1e-9)  # roll/pitch have priority over thrust and yaw
    else:
        # scaled down, same direction
        assert ox * tx >= -1e-12 and oy * ty >= -1e-12


def test_mixer_keeps_attitude_authority_at_full_and_zero_thrust():
    mixer = Mixer(V)
    for thrust in (0.0, 24.5):
        r = mixer.mix(thrust, 0.3, -0.2, 0.0)
        f, ox, oy, _ = rotor_wrench(r.thrusts, V)
        assert (ox, oy) == pytest.approx((0.3, -0.2), abs=1e-9)
        assert r.thrust_limited


@settings(max_examples=200, deadline=None)
@given(st.lists(finite, min_size=18, max_size=18), st.lists(st.floats(-5, 20), min_size=4, max_size=4),
       st.lists(st.floats(-20, 20), min_size=3, max_size=3))
def test_step_is_finite_and_quaternion_unit(vals, cmd, wind):
    q = frames.euler_to_quaternion(vals[6] % 3, vals[7] % 1.5, vals[8])
    s = RigidBodyState(vals[0], vals[1], -abs(vals[2]) - 1, vals[3] / 10, vals[4] / 10, vals[5] / 10, *q,
                       vals[9] / 100, vals[10] / 100, vals[11] / 100, 1.0, 2.0, 3.0, 4.0, False)
    for _ in range(20):
        s = rigid_body.step(s, cmd, 0.001, MODEL, wind)
    assert all(math.isfinite(v) for v in s[:17])
    assert frames.quat_norm(s[6:10]) == pytest.approx(1.0, abs=1e-9)


@settings(max_examples=300, deadline=None)
@given(angle, st.floats(-1.5, 1.5), angle)
def test_euler_quaternion_round_trip(roll, pitch, yaw):
    q = frames.euler_to_quaternion(roll, pitch, yaw)
    r2, p2, y2 = frames.quaternion_to_euler(q)
    q2 = frames.euler_to_quaternion(r2, p2, y2)
    assert abs(sum(a * b for a, b in zip(q, q2))) == pytest.approx(1.0, abs=1e-9)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(-50, 50), min_size=6, max_size=6), angle, st.floats(-1.4, 1.4), angle,
       st.lists(st.floats(-5, 5), min_size=3, max_size=3))
def test_paper_ned_conversion_round_trip(pos_vel, roll, pitch, yaw, rates):
    paper = (*pos_vel, roll, pitch, yaw, *rates)
    k = frames.ned_from_paper(paper)
    assert k.d == -paper[2] and k.vd == -paper[5]
    back = frames.paper_from_ned(k)
    assert back[:6] == pytest.approx(paper[:6])
    assert back[9:] == pytest.approx(paper[9:], abs=1e-6)
    for a, b in zip(back[6:9], paper[6:9]):
        assert math.cos(a - b) == pytest.approx(1.0, abs=1e-9)


def test_paper_frame_conversion_known_values():
    # z up 2 m, climbing 1 m/s, level, yaw rate 0.5 rad/s -> d = -2, vd = -1, r = 0.5
    k = frames.ned_from_paper((1, 2, 2, 0, 0, 1, 0, 0, 0, 0, 0, 0.5))
    assert (k.n, k.e, k.d, k.vd, k.r) == (1, 2, -2, -1, 0.5)
    assert frames.ned_wind_from_paper((1, 2, 3)) == (1, 2, -3)


def test_reduced_plant_uses_the_paper_model():
    # Motors at steady state with a constant command: the reduced plant must see the same inputs as reduced.step.
    th = (HOVER_N * 1.1 - 0.05, HOVER_N * 1.1 + 0.05, HOVER_N * 1.1 + 0.05, HOVER_N * 1.1 - 0.05)
    start = airborne(10.0)._replace(t1=th[0], t2=th[1], t3=th[2], t4=th[3])
    plant = ReducedPlant(V.with_model("reduced"), start)
    ref = plant.state
    plant.step(th, 0.01)
    f, tx, ty, tz = rotor_wrench(th, V)
    ix, iy, iz = V.inertia_diagonal
    expected = reduced.step(ref, (f, tx / ix, ty / iy, tz / iz), 0.01, plant.params)
    assert tuple(plant.state) == pytest.approx(tuple(expected), rel=1e-12, abs=1e-12)
    assert plant.kinematics == frames.ned_from_paper(expected)
    assert plant.kinematics.d < -10.0  # climbing (z up became d down)


def test_rigid_body_and_reduced_plants_agree_near_hover():
    th = (HOVER_N * 1.05,) * 4
    a = RigidBodyPlant(V, airborne(5.0, thrust=HOVER_N))
    b = ReducedPlant(V.with_model("reduced"), airborne(5.0, thrust=HOVER_N))
    for _ in range(100):
        a.step(th, 0.01)
        b.step(th, 0.01)
    assert a.kinematics.d == pytest.approx(b.kinematics.d, abs=0.01)
    assert a.kinematics.vd == pytest.approx(b.kinematics.vd, abs=0.01)
