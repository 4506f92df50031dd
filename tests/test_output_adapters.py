"""The output adapters (gcs/vehicles/output.py): rate demand, attitude and rates setpoints, the stall property."""

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.config import load_config
from gcs.control import make_controller
from gcs.vehicles.ardupilot import angle_accel_limits
from gcs.vehicles.profile import OutputParams
from gcs.vehicles.output import (IGNORE_ATTITUDE, IGNORE_RATES, OutputAdapter, OutputModel, angle_for_rate,
                                 build_adapter, rotation_quaternion)
from quadrotor.frames import euler_rates_to_body_rates, euler_to_quaternion, quat_multiply, quat_rotate, rotation_vector
from quadrotor.state import Command, State

MAV = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
ARDUCOPTER_LIMITS = angle_accel_limits((1100.0, 1100.0, 270.0))


def model(kind, **kw):
    args = dict(kind=kind, mass_kg=1.0, gravity_m_s2=9.81, hover_throttle=0.4, inertia_kg_m2=(0.01, 0.01, 0.02),
                max_torque_nm=(2.0, 2.0, 0.2), rate_gain_1_s=(65.0, 65.0, 80.0), angle_gain_1_s=(4.5, 4.5, 4.5))
    args.update(kw)
    return OutputModel(**args)


def sqrt_controller(err, p, lim):
    """ArduPilot's AP_Math sqrt_controller (without the dt clamp): the angle loop the attitude output inverts."""
    if lim <= 0:
        return err * p
    ld = lim / p ** 2
    if abs(err) <= ld:
        return err * p
    return math.copysign(math.sqrt(2 * lim * (abs(err) - ld / 2)), err)


def angle_error(q_from, q_to):
    return rotation_vector(q_from, q_to)


# ---------------------------------------------------------------------- the pieces

def test_angle_for_rate_inverts_the_square_root_angle_loop():
    for p, lim in ((4.5, ARDUCOPTER_LIMITS[0]), (4.5, ARDUCOPTER_LIMITS[2]), (6.0, 0.0)):
        for w in (-3.0, -0.8, -0.2, 0.0, 0.05, 0.3, 1.0, 2.5):
            assert sqrt_controller(angle_for_rate(w, p, lim), p, lim) == pytest.approx(w, abs=1e-12)
    assert angle_for_rate(0.9, 4.5, 0.0) == pytest.approx(0.2)   # no limit: linear


def test_arducopter_angle_loop_limits():
    r, p, y = angle_accel_limits((1100.0, 1100.0, 270.0))
    assert r == p == pytest.approx(math.radians(550.0)) and y == pytest.approx(math.radians(120.0))
    assert angle_accel_limits((0.0, 50.0, 5.0)) == pytest.approx((0.0, math.radians(40.0), math.radians(10.0)))


def test_rotation_quaternion_is_exp():
    q = rotation_quaternion((0.3, -0.2, 0.1))
    assert math.fsum(c * c for c in q) == pytest.approx(1.0)
    assert rotation_vector((1.0, 0.0, 0.0, 0.0), q) == pytest.approx((0.3, -0.2, 0.1))
    assert rotation_quaternion((0.0, 0.0, 0.0)) == (1.0, 0.0, 0.0, 0.0)


def test_rate_demand_is_omega_plus_alpha_over_the_gain_and_clipped():
    a = OutputAdapter(model("rates"), MAV)
    assert a.rate_demand((0.1, 0.0, -0.2), (6.5, -13.0, 8.0)) == pytest.approx([0.2, -0.2, -0.1])
    clipped = OutputAdapter(model("rates", rate_limit_rad_s=(0.15, 0.0, 0.05)), MAV)
    assert clipped.rate_demand((0.1, 0.0, -0.2), (6.5, -13.0, 8.0)) == pytest.approx([0.15, -0.2, -0.05])


@pytest.mark.parametrize("name", ["pd", "nlsoc", "loc"])
def test_with_the_laws_rate_damping_the_demand_does_not_depend_on_the_measured_rate(name):
    """K_d = -d tau / d omega (the law's own rate damping) cancels omega: the demand is the rate the law's
    attitude loop settles to, so the autopilot's rate-loop gain and delay do not enter."""
    ctl = make_controller(name, load_config("outdoor-circle"))
    ref, s0 = State(z=1.5, vy=0.3), State(z=1.5, roll=0.02)
    b = -(ctl.step(100, s0._replace(roll_rate=1e-3), ref).roll_accel_rad_s2
          - ctl.step(100, s0, ref).roll_accel_rad_s2) / 1e-3
    a = OutputAdapter(model("rates", rate_gain_1_s=(b, b, 80.0)), MAV)
    demands = [a.fields(s, ctl.step(100, s, ref))["body_rates"][0]
               for s in (s0._replace(roll_rate=w) for w in (-0.3, 0.0, 0.4))]
    assert demands == pytest.approx([demands[1]] * 3, abs=1e-6)
    assert 60.0 < b < 70.0   # the default rate_gain_1_s (65) is each law's damping to within 10 %


# ---------------------------------------------------------------------- the setpoints

def test_attitude_output_is_a_quaternion_with_zero_rates_whose_error_demands_the_rate():
    m = model("attitude", angle_accel_limit_rad_s2=ARDUCOPTER_LIMITS)
    a = OutputAdapter(m, MAV)
    s = State(z=1.0, roll=0.1, pitch=-0.05, yaw=0.3, roll_rate=0.2, yaw_rate=-0.1)
    cmd = Command(9.81, 13.0, -6.5, 8.0)
    f = a.fields(s, cmd)
    assert f["type_mask"] == IGNORE_RATES and f["body_rates"] == [0.0, 0.0, 0.0]
    assert math.fsum(c * c for c in f["q"]) == pytest.approx(1.0)
    # The attitude the vehicle has one period later (at the measured rate) ...
    omega = euler_rates_to_body_rates(s.roll, s.pitch, s.roll_rate, s.pitch_rate, s.yaw_rate)
    q_ahead = quat_multiply(euler_to_quaternion(s.roll, s.pitch, s.yaw), rotation_quaternion([w * 0.01 for w in omega]))
    # ... and the angle loop on the target from there demands omega_d.
    e = angle_error(q_ahead, f["q"])
    demand = a.rate_demand(omega, a.body_accel(s, cmd))
    got = [sqrt_controller(ei, 4.5, lim) for ei, lim in zip(e, ARDUCOPTER_LIMITS)]
    assert got == pytest.approx(demand, abs=1e-9)
    msg = a.encode(f, 1234)
    assert msg.type_mask == 7 and (msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate) == (0.0, 0.0, 0.0)


def test_rates_output_sends_the_demand_with_the_attitude_ignored():
    a = OutputAdapter(model("rates"), MAV)
    f = a.fields(State(roll_rate=0.1), Command(9.81, 6.5, -3.25, 8.0))
    assert f["type_mask"] == IGNORE_ATTITUDE
    assert f["body_rates"] == pytest.approx([0.1 + 0.1, -0.05, 0.1])
    assert math.fsum(c * c for c in f["q"]) == pytest.approx(1.0)


def test_level_setpoints_carry_zero_rates():
    a = OutputAdapter(model("attitude"), MAV)
    msg = a.level(State(yaw=0.4, roll=0.3, roll_rate=2.0), 9.81, 10)
    assert msg.type_mask == IGNORE_RATES and (msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate) == (0, 0, 0)
    assert msg.thrust == pytest.approx(0.4)


def test_thrust_normalisation_uses_the_hover_throttle():
    m = model("attitude")
    assert m.thrust_norm(9.81) == pytest.approx(0.4)
    assert m.thrust_norm(2 * 9.81) == pytest.approx(0.8)
    assert m.thrust_norm(100.0) == 1.0 and m.thrust_norm(-1.0) == 0.0


def test_actuator_controls_are_torques_over_their_maximum():
    a = OutputAdapter(model("actuator"), MAV)
    f = a.fields(State(z=1.0), Command(9.81, 50.0, -100.0, 5.0))
    assert f["message"] == "SET_ACTUATOR_CONTROL_TARGET"
    assert f["controls"][:4] == pytest.approx([0.01 * 50 / 2.0, 0.01 * -100 / 2.0, 0.02 * 5 / 0.2, 0.4])


def test_output_model_is_checked():
    with pytest.raises(ValueError, match="hover_throttle"):
        model("attitude", hover_throttle=1.2)
    with pytest.raises(ValueError, match="output"):
        model("torque")
    with pytest.raises(ValueError, match="angle_accel_limit_rad_s2"):
        model("attitude", angle_accel_limit_rad_s2=(1.0, -1.0, 0.0))


def test_build_adapter_takes_what_the_profile_read():
    cfg = load_config("outdoor-circle")
    out = OutputParams(0.39, (4.0, 4.5, 5.0), ARDUCOPTER_LIMITS, (0.0, 0.0, 1.0), output="attitude")
    a = build_adapter("attitude", cfg.vehicle, cfg.flight, out, 0.01, MAV, 1, 1)
    assert a.model.hover_throttle == 0.39 and a.model.angle_gain_1_s == (4.0, 4.5, 5.0)
    assert a.model.rate_limit_rad_s == (0.0, 0.0, 1.0) and a.model.rate_gain_1_s == cfg.flight.rate_gain_1_s


# ---------------------------------------------------------------------- the stall property

class StoredTarget:
    """ArduCopter's guided angle target between messages (AC_AttitudeControl::input_quaternion, step 4):
    every 2.5 ms loop the stored quaternion is rolled forward by the message's body rates, rotated into
    NED by the target itself (its frame bug), until GUID_TIMEOUT."""

    def __init__(self, msg_fields):
        self.q = tuple(msg_fields["q"])
        self.rates = (0.0, 0.0, 0.0) if msg_fields["type_mask"] & IGNORE_RATES == IGNORE_RATES \
            else tuple(msg_fields["body_rates"])

    def run(self, seconds, dt=0.0025):
        for _ in range(int(round(seconds / dt))):
            w = quat_rotate(self.q, self.rates)
            self.q = quat_multiply(self.q, rotation_quaternion([v * dt for v in w]))
        return self.q


def tilt_deg(q):
    """Angle between the body z axis and the vertical [deg]."""
    z = quat_rotate(q, (0.0, 0.0, 1.0))
    return math.degrees(math.acos(max(-1.0, min(1.0, z[2]))))


def test_a_stalled_attitude_setpoint_is_a_fixed_attitude_near_the_current_one():
    """The next message never comes: the target stays where the last one put it (zero rates), within
    |omega_d| / K_a of the current attitude; the old setpoint (rates as feed-forward) kept rolling."""
    a = OutputAdapter(model("attitude", angle_accel_limit_rad_s2=ARDUCOPTER_LIMITS), MAV)
    s = State(z=1.5, roll=0.02, pitch=-0.01, roll_rate=0.1, pitch_rate=-0.05)
    cmd = Command(9.81, 5.0, -3.0, 0.0)
    f = a.fields(s, cmd)
    stored = StoredTarget(f)
    assert stored.run(2.0) == pytest.approx(tuple(f["q"]), abs=1e-12)
    q_now = euler_to_quaternion(s.roll, s.pitch, s.yaw)
    demand = a.rate_demand(euler_rates_to_body_rates(s.roll, s.pitch, s.roll_rate, s.pitch_rate, s.yaw_rate),
                           a.body_accel(s, cmd))
    bound = math.hypot(*demand) / 4.5 + 0.01 * math.hypot(s.roll_rate, s.pitch_rate)
    assert math.hypot(*angle_error(q_now, stored.q)) <= bound + 1e-9
    assert tilt_deg(stored.q) < 5.0
    # The same demand as feed-forward rates (type_mask 0) would have rolled the target on.
    old = dict(f, type_mask=0, body_rates=demand)
    assert tilt_deg(StoredTarget(old).run(2.0)) > 3 * tilt_deg(stored.q) + 10.0


def test_a_stalled_rates_setpoint_turns_for_the_guided_timeout_only():
    """ArduCopter keeps the last rate until GUID_TIMEOUT (0.5 s for the flight), then levels: the tilt
    added is |omega_d| x 0.5 s."""
    a = OutputAdapter(model("rates"), MAV)
    f = a.fields(State(z=1.5, roll_rate=0.05), Command(9.81, 1.3, 0.0, 0.0))
    assert math.degrees(math.hypot(*f["body_rates"]) * 0.5) < 3.0



# ---------------------------------------------------------------------- the rate-error integral (issue 26)

class YawAutopilot:
    """One axis of an autopilot flying the attitude output: the angle P (K_a) on the target's yaw error,
    a rate loop ``w' = k (w_cmd - w) + d`` (``d``: a steady torque the model lacks, as a weak motor gives)
    with a slow integrator of its own (``ki``, ArduCopter's ATC_RAT_YAW_I is tens of seconds), at 400 Hz."""

    def __init__(self, disturbance=0.0, k=12.0, ki=0.0):
        self.yaw, self.w, self.i = 0.0, 0.0, 0.0
        self.d, self.k, self.ki = disturbance, k, ki

    def run(self, q_target, seconds=0.01, dt=0.0025):
        target = math.atan2(2 * (q_target[0] * q_target[3] + q_target[1] * q_target[2]),
                            1 - 2 * (q_target[2] ** 2 + q_target[3] ** 2))
        for _ in range(int(round(seconds / dt))):
            err = 4.5 * (target - self.yaw) - self.w
            self.i += self.ki * err * dt
            self.w += dt * (self.k * err + self.i + self.d)
            self.yaw += dt * self.w


def fly_yaw_rate(adapter, plant, rate_rad_s, seconds, airborne=True):
    """The law demands ``rate_rad_s`` of yaw rate (tau = K_d (rate - w): omega_d = rate); the yaw rates flown."""
    rates = []
    for _ in range(int(round(seconds / 0.01))):
        s = State(z=1.5, yaw=plant.yaw, yaw_rate=plant.w)
        f = adapter.fields(s, Command(9.81, 0.0, 0.0, 80.0 * (rate_rad_s - plant.w)), airborne)
        plant.run(f["q"])
        rates.append(plant.w)
    return rates


def integral_model(**kw):
    return model("attitude", angle_accel_limit_rad_s2=ARDUCOPTER_LIMITS, rate_integral_max_rad=(0.1, 0.1, 0.2), **kw)


def test_a_steady_torque_leaves_the_rate_short_without_the_integral_and_not_with_it():
    """The weak-motor defect: re-anchored on the measured attitude every period, the angle loop is a pure
    proportional rate loop; a steady torque the autopilot's own integrator has not learnt leaves the rate
    short of the demand.  The rate-error integral brings it to the demand within a second."""
    without = fly_yaw_rate(OutputAdapter(model("attitude", angle_accel_limit_rad_s2=ARDUCOPTER_LIMITS), MAV),
                           YawAutopilot(disturbance=-1.0), 0.1, 5.0)
    assert without[-1] < 0.1 - 0.05                       # steady shortfall (0.1 - w = d / (k (1 + ...)))
    a = OutputAdapter(integral_model(), MAV)
    with_it = fly_yaw_rate(a, YawAutopilot(disturbance=-1.0), 0.1, 5.0)
    assert with_it[-1] == pytest.approx(0.1, abs=0.005)
    assert max(abs(w - 0.1) for w in with_it[200:]) < 0.01   # settled after 2 s
    assert 0.0 < a.integral.delta_rad[2] < 0.2


def test_the_integral_stays_near_zero_on_a_nominal_vehicle():
    """No disturbance, a rate loop that lags as ArduCopter's (k = 25 1/s): transients of the demand leave
    ``delta`` small, so the nominal flight is the one the law designed."""
    a = OutputAdapter(integral_model(), MAV)
    plant = YawAutopilot(k=25.0)
    for rate in (0.3, -0.2, 0.0):
        fly_yaw_rate(a, plant, rate, 1.0)
        assert abs(a.integral.delta_rad[2]) < 0.01


def test_the_integral_is_bounded_learns_only_airborne_and_restarts_after_level_setpoints():
    a = OutputAdapter(integral_model(), MAV)
    fly_yaw_rate(a, YawAutopilot(disturbance=-50.0), 0.1, 3.0)        # past the vehicle's authority
    assert a.integral.delta_rad[2] == pytest.approx(-0.2) or a.integral.delta_rad[2] == pytest.approx(0.2)
    fly_yaw_rate(a, YawAutopilot(), 0.0, 3.0, airborne=False)          # on the ground: relaxes, learns nothing
    assert abs(a.integral.delta_rad[2]) < 0.2 * math.exp(-5.0)
    fly_yaw_rate(a, YawAutopilot(disturbance=-1.0), 0.1, 1.0)
    assert a.integral.delta_rad[2] != 0.0
    a.level(State(yaw=0.1), 9.81, 0)
    assert a.integral.delta_rad == [0.0, 0.0, 0.0]


def test_the_integral_is_configured_from_the_flight_section_and_off_with_zero_bounds():
    cfg = load_config("outdoor-circle")
    out = OutputParams(0.39, (4.5, 4.5, 4.5), ARDUCOPTER_LIMITS, (0.0, 0.0, 0.0), output="attitude")
    a = build_adapter("attitude", cfg.vehicle, cfg.flight, out, 0.01, MAV, 1, 1)
    assert a.integral is not None and a.integral.max_rad == cfg.flight.rate_integral_max_rad == (0.1, 0.1, 0.2)
    assert build_adapter("rates", cfg.vehicle, cfg.flight, out, 0.01, MAV, 1, 1).integral is None
    off = cfg.with_changes("flight", rate_integral_max_rad=[0.0, 0.0, 0.0])
    assert build_adapter("attitude", off.vehicle, off.flight, out, 0.01, MAV, 1, 1).integral is None
    from quadrotor.errors import ConfigError
    with pytest.raises(ConfigError, match=r"flight\.rate_integral_max_rad"):
        cfg.with_changes("flight", rate_integral_max_rad=[0.1, 0.1, 0.9])
    with pytest.raises(ConfigError, match=r"flight\.rate_response_s"):
        cfg.with_changes("flight", rate_response_s=0.0)
