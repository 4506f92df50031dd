"""The 4-DOF rig emulator without a link: stops, ultrasonic, arming, cut-off, watchdog, PWM, determinism."""

from __future__ import annotations

import math
import random

import pytest

from quadrotor import rig_protocol as rp
from quadrotor.rig_protocol import AckResult, RigFlags, RigState
from quadrotor.state import State
from sitl.rig.dynamics import RigParams, mix, step, unmix
from sitl.rig.firmware import RigFirmware, RigSafetyParams
from sitl.rig.sensors import RigSensorParams, RigSensors

P = RigParams()
HOVER = P.hover_thrust_n


class Pilot:
    """Drives a :class:`RigFirmware` the way the PC does in lockstep: one CONTROL, two ticks."""

    def __init__(self, fw: RigFirmware) -> None:
        self.fw = fw
        self.seq = 0
        self.telemetry: list[rp.Telemetry] = []
        self.status: list[rp.Status] = []

    def send(self, msg: rp.Message) -> list[rp.Message]:
        replies, _ = self.fw.handle(msg)
        return replies

    def arm(self) -> AckResult:
        (ack,) = self.send(rp.Arm(1))
        assert ack.acked_type == rp.Arm.TYPE and ack.seq == 1
        return ack.result

    def ticks(self, n: int) -> None:
        for _ in range(n):
            for m in self.fw.tick():
                (self.telemetry if isinstance(m, rp.Telemetry) else self.status).append(m)

    def control(self, thrust: float, roll: float = 0.0, pitch: float = 0.0, yaw: float = 0.0) -> None:
        self.seq = (self.seq + 1) & 0xFFFF
        self.send(rp.Control(self.seq, thrust, roll, pitch, yaw))
        self.ticks(2)

    def hold(self, z_ref: float, seconds: float) -> None:
        """A truth-based PD autopilot at 100 Hz."""
        for _ in range(int(round(seconds / 0.01))):
            s = self.fw.plant
            thrust = HOVER + 8.0 * (z_ref - s.z) - 5.0 * s.vz
            thrust = min(max(thrust / (math.cos(s.roll) * math.cos(s.pitch)), 0.0), 24.0)
            self.control(thrust, -100.0 * s.roll - 20.0 * s.roll_rate, -100.0 * s.pitch - 20.0 * s.pitch_rate)


def ideal_fw(**kwargs) -> RigFirmware:
    return RigFirmware(sensors=RigSensorParams.ideal(), **kwargs)


# ---------------------------------------------------------------------------------------------- dynamics
@pytest.mark.parametrize("axis, limit_deg", [("roll", 15.0), ("pitch", 60.0)])
def test_mechanical_stops_clamp_the_angle_and_zero_the_rate(axis, limit_deg):
    limit = math.radians(limit_deg)
    s = State(z=50.0)
    for sign in (1.0, -1.0):
        a = sign * 40.0
        motors, sat = mix(HOVER, a if axis == "roll" else 0.0, a if axis == "pitch" else 0.0, P)
        assert not sat
        at_stop_seen = False
        for _ in range(200):                      # 1 s
            res = step(s, motors, 0.005, P)
            s = res.state
            angle, rate = (s.roll, s.roll_rate) if axis == "roll" else (s.pitch, s.pitch_rate)
            assert abs(angle) <= limit + 1e-12
            if res.roll_at_stop if axis == "roll" else res.pitch_at_stop:
                at_stop_seen = True
                assert angle == sign * limit and rate == 0.0
        assert at_stop_seen
        assert s.y == s.vy == s.yaw == s.yaw_rate == 0.0
        # Pushing the other way leaves the stop.
        motors, _ = mix(HOVER, -a if axis == "roll" else 0.0, -a if axis == "pitch" else 0.0, P)
        res = step(s, motors, 0.05, P)
        angle = res.state.roll if axis == "roll" else res.state.pitch
        assert abs(angle) < limit and not (res.roll_at_stop or res.pitch_at_stop)
        s = State(z=50.0)


def test_y_and_yaw_stay_locked_under_roll():
    s = State(z=50.0, roll=0.2)
    motors, _ = mix(HOVER * 1.2, 0.0, 0.0, P)
    for _ in range(100):
        s = step(s, motors, 0.005, P).state
    assert s.y == s.vy == s.yaw == s.yaw_rate == 0.0 and s.vz > 0


def test_mixer_round_trip_and_saturation():
    motors, sat = mix(12.0, 30.0, -20.0, P)
    assert not sat and unmix(motors, P) == pytest.approx((12.0, 30.0, -20.0))
    motors, sat = mix(24.5, 50.0, 0.0, P)
    assert sat and all(0.0 <= f <= P.max_motor_thrust_n for f in motors)
    u, a_roll, _ = unmix(motors, P)
    assert u < 24.5 and 0 < a_roll < 50.0
    assert mix(-5.0, 0.0, 0.0, P) == ((0.0, 0.0, 0.0, 0.0), True)


# ---------------------------------------------------------------------------------------------- ultrasonic
def test_ultrasonic_quantisation_and_minimum_range():
    sen = RigSensors(RigSensorParams.ideal(), random.Random(0))
    res = 0.04
    for i in range(300):
        z = i * 0.005
        alt, out = sen.altitude(z)
        assert abs(alt / res - round(alt / res)) < 1e-9, "a multiple of 4 cm"
        if z + 0.05 < 0.07:                       # below the minimum range: reads the minimum
            assert out and alt == pytest.approx(0.04)
        else:
            assert not out and abs(alt - z) <= res / 2 + 1e-9
    alt, out = sen.altitude(10.0)
    assert out and alt == pytest.approx(2.96)


def test_landed_reads_zero_or_four_centimetres_with_noise():
    sen = RigSensors(RigSensorParams(), random.Random(3))
    readings = [sen.measure(State()).altitude_m for _ in range(400)]
    assert {round(r, 3) for r in readings} == {0.0, 0.04}


def test_telemetry_altitude_is_in_millimetres_and_flags_out_of_range():
    p = Pilot(RigFirmware(seed=4))
    p.ticks(10)
    for t in p.telemetry:
        assert t.altitude_mm % 40 == 0 and t.altitude_mm in (0, 40)
        assert RigFlags.LANDED in t.flags and RigFlags.ALT_OUT_OF_RANGE in t.flags


def test_imu_noise_and_determinism_per_seed():
    def run(seed):
        p = Pilot(RigFirmware(seed=seed))
        assert p.arm() == AckResult.ACCEPTED
        for _ in range(60):
            p.control(HOVER + 2.0, 0.5, -0.5)
        return p.telemetry, p.fw.plant

    a, b, c = run(5), run(5), run(6)
    assert a == b and a[0] != c[0]
    assert a[1] == c[1], "the plant does not depend on the noise"
    assert any(t.yaw_rad != 0.0 for t in a[0][:5]), "IMU noise"


# ---------------------------------------------------------------------------------------------- arming
def test_arm_only_when_landed():
    fw = ideal_fw(initial=State(z=0.5))
    p = Pilot(fw)
    assert p.arm() == AckResult.DENIED_NOT_LANDED and fw.state == RigState.DISARMED
    p.ticks(200)                                   # falls and lands
    assert fw.landed
    assert p.arm() == AckResult.ACCEPTED and fw.state == RigState.ARMED
    assert p.arm() == AckResult.ACCEPTED           # idempotent
    p.hold(0.3, 3.0)
    assert fw.plant.z == pytest.approx(0.3, abs=0.03)
    (ack,) = p.send(rp.Disarm(2))
    assert ack == rp.Ack(rp.Disarm.TYPE, 2, AckResult.ACCEPTED) and fw.motors_n == (0.0,) * 4
    p.ticks(2)
    assert p.arm() == AckResult.DENIED_NOT_LANDED  # disarmed in the air: falling


def test_controls_while_disarmed_are_ignored_but_echoed():
    p = Pilot(ideal_fw())
    p.control(20.0)
    assert p.fw.plant.z == 0.0 and p.fw.controls_ignored == 1 and p.telemetry[-1].control_seq == 1
    assert RigFlags.ARMED not in p.telemetry[-1].flags


# ---------------------------------------------------------------------------------------------- cut-off
@pytest.mark.parametrize("demand", [
    (30.0, 0.0, 0.0, 0.0), (-1.0, 0.0, 0.0, 0.0), (HOVER, 250.0, 0.0, 0.0), (HOVER, 0.0, -201.0, 0.0),
    (HOVER, 0.0, 0.0, 300.0), (float("nan"), 0.0, 0.0, 0.0), (HOVER, float("inf"), 0.0, 0.0),
])
def test_excessive_command_cuts_the_motors_and_latches(demand):
    fw = ideal_fw()
    p = Pilot(fw)
    assert p.arm() == AckResult.ACCEPTED
    p.hold(0.3, 2.0)
    p.control(*demand)
    assert fw.state == RigState.CUTOFF and fw.motors_n == (0.0,) * 4 and fw.cutoffs == 1
    f = p.telemetry[-1].flags
    assert RigFlags.CUTOFF in f and RigFlags.CUT_COMMAND in f and RigFlags.ARMED not in f
    p.hold(0.3, 1.0)                                # valid commands no longer fly it
    assert fw.landed and fw.state == RigState.CUTOFF and fw.motors_n == (0.0,) * 4
    assert p.arm() == AckResult.DENIED_CUTOFF
    st = p.send(rp.Heartbeat(77))[0]
    assert st.state == RigState.CUTOFF and RigFlags.CUT_COMMAND in st.flags and st.cutoffs == 1
    (ack,) = p.send(rp.Disarm(4))
    assert ack.result == AckResult.ACCEPTED and fw.state == RigState.DISARMED
    p.ticks(1)
    assert not p.telemetry[-1].flags & (rp.CUTOFF_CAUSES | RigFlags.CUTOFF)
    assert p.arm() == AckResult.ACCEPTED
    p.hold(0.2, 2.0)
    assert fw.plant.z == pytest.approx(0.2, abs=0.03)


def test_limits_include_the_saturated_values():
    fw = ideal_fw()
    p = Pilot(fw)
    p.arm()
    p.control(24.5, 200.0, -200.0, 200.0)
    p.control(0.0)
    assert fw.state == RigState.ARMED


def test_vertical_speed_cut_off():
    fw = ideal_fw()
    p = Pilot(fw)
    p.arm()
    for _ in range(50):
        p.control(24.0)
    assert fw.state == RigState.CUTOFF and fw.cut_causes == RigFlags.CUT_VELOCITY_Z
    assert fw.plant.z < 0.3


def test_altitude_cut_off():
    fw = ideal_fw(safety=RigSafetyParams(max_vz_m_s=50.0, max_altitude_m=0.5))
    p = Pilot(fw)
    p.arm()
    for _ in range(100):
        p.control(24.0)
    assert fw.state == RigState.CUTOFF and fw.cut_causes == RigFlags.CUT_ALTITUDE
    first_cut = next(t for t in p.telemetry if RigFlags.CUTOFF in t.flags)
    assert 0.5 <= first_cut.altitude_m <= 0.6 and RigFlags.CUT_ALTITUDE in first_cut.flags


def test_horizontal_speed_cut_off_and_pitch_stop_flag():
    fw = ideal_fw(safety=RigSafetyParams(max_vz_m_s=50.0, max_altitude_m=50.0, max_angular_rate_rad_s=50.0))
    p = Pilot(fw)
    p.arm()
    p.hold(0.5, 2.0)
    for _ in range(100):
        p.control(HOVER * 1.5, 0.0, 20.0)
        if fw.state == RigState.CUTOFF:
            break
    assert fw.cut_causes == RigFlags.CUT_VELOCITY_X
    assert any(RigFlags.PITCH_AT_STOP in t.flags for t in p.telemetry)


def test_angular_rate_cut_off():
    fw = ideal_fw()
    p = Pilot(fw)
    p.arm()
    p.hold(0.4, 2.0)
    for _ in range(20):
        p.control(HOVER, 0.0, 150.0)
        if fw.state == RigState.CUTOFF:
            break
    assert RigFlags.CUT_ANGULAR_RATE in fw.cut_causes


def test_roll_stop_flag_in_flight():
    fw = ideal_fw()
    p = Pilot(fw)
    p.arm()
    p.hold(0.3, 2.0)
    for _ in range(50):
        p.control(HOVER / math.cos(math.radians(15)), 10.0)
    t = p.telemetry[-1]
    assert RigFlags.ROLL_AT_STOP in t.flags and t.roll_rad == pytest.approx(math.radians(15))
    assert fw.state == RigState.ARMED


# ---------------------------------------------------------------------------------------------- watchdog
def test_watchdog_descends_and_disarms():
    fw = ideal_fw()
    p = Pilot(fw)
    p.arm()
    p.hold(0.5, 3.0)
    n0 = len(p.telemetry)
    p.ticks(99)                                    # 0.5 s since the last CONTROL: still armed
    assert fw.state == RigState.ARMED and fw.watchdog_trips == 0
    p.ticks(1)
    assert fw.state == RigState.DESCENT and fw.watchdog_trips == 1
    p.ticks(200)
    assert RigFlags.WATCHDOG in p.telemetry[-1].flags and RigFlags.ARMED in p.telemetry[-1].flags
    assert fw.plant.vz == pytest.approx(-0.3, abs=0.05)
    assert abs(fw.plant.roll) < 1e-6 and abs(fw.plant.pitch) < 1e-6
    p.ticks(600)
    assert fw.state == RigState.DISARMED and fw.landed and fw.cutoffs == 0
    assert min(t.altitude_m for t in p.telemetry[n0:]) <= 0.04


def test_control_during_descent_resumes_and_on_ground_the_watchdog_disarms():
    fw = ideal_fw()
    p = Pilot(fw)
    p.arm()
    p.hold(0.5, 2.0)
    p.ticks(150)
    assert fw.state == RigState.DESCENT
    p.hold(0.5, 0.5)
    assert fw.state == RigState.ARMED
    p.send(rp.Disarm(0))
    p.ticks(200)
    assert p.arm() == AckResult.ACCEPTED
    p.ticks(102)                                  # armed on the ground, never commanded
    assert fw.state == RigState.DISARMED and fw.watchdog_trips == 2


# ---------------------------------------------------------------------------------------------- PWM, status
def test_pwm_control_maps_to_motor_thrust():
    fw = ideal_fw()
    p = Pilot(fw)
    p.arm()
    p.send(rp.ControlPwm(1, (600, 600, 600, 600)))
    p.ticks(2)
    assert sum(fw.motors_n) == pytest.approx(4 * P.max_motor_thrust_n * 600 / 1023)
    assert fw.plant.vz > 0 and RigFlags.PWM_MODE in p.telemetry[-1].flags
    p.send(rp.ControlPwm(2, (700, 700, 500, 500)))  # (f1 + f2) > (f3 + f4): positive roll acceleration
    p.ticks(2)
    assert fw.plant.roll_rate > 0 and fw.plant.pitch_rate == 0.0
    p.control(HOVER)
    assert RigFlags.PWM_MODE not in p.telemetry[-1].flags


def test_status_every_second_and_heartbeat_echo():
    p = Pilot(RigFirmware(seed=1))
    p.ticks(400)
    assert [s.time_us for s in p.status] == [1_000_000, 2_000_000]
    assert len(p.telemetry) == 400 and p.telemetry[-1].time_us == 2_000_000
    (st,) = p.send(rp.Heartbeat(123456))
    assert st.heartbeat_echo_us == 123456 and st.protocol_version == rp.PROTOCOL_VERSION
    assert (st.fw_major, st.fw_minor, st.fw_patch) == (1, 0, 0) and st.state == RigState.DISARMED
    assert rp.RigDecoder().feed(rp.encode(st)) == [st]


def test_parameters_are_validated():
    with pytest.raises(ValueError, match="roll_stop_rad"):
        RigParams(roll_stop_rad=0.0)
    with pytest.raises(ValueError, match="watchdog_timeout_s"):
        RigSafetyParams(watchdog_timeout_s=-1.0)
    with pytest.raises(ValueError, match="max_range_m"):
        RigSensorParams(max_range_m=0.01)
