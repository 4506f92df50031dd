"""Output adapters: the controller's command as MAVLink setpoints.

The controllers command thrust ``u`` [N] and Euler-angle accelerations
``tau`` [rad/s^2] (the paper's model has unit inertia).  First the Euler-angle
accelerations become FRD body angular accelerations ``alpha_d`` with the exact
kinematics (:func:`quadrotor.frames.euler_accel_to_body_accel`; the identity near
hover).  Then, per ``--output``:

``actuator`` — SET_ACTUATOR_CONTROL_TARGET, group 0::

    controls[0..2] = clip(I alpha_d / max_torque_nm, -1, 1)   (roll, pitch, yaw)
    controls[3]    = thrust_norm

``rates`` — SET_ATTITUDE_TARGET, type_mask = 128 (attitude ignored)::

    body rates = omega + alpha_d / K_r

  where ``K_r`` [1/s] is the autopilot's rate-loop gain (angular acceleration
  per rate error): a rate loop ``alpha = K_r (omega_t - omega)`` then delivers
  ``alpha_d`` in one step.  The quaternion is the current attitude (ArduPilot
  rejects non-unit quaternions even when they are ignored).

``attitude`` — SET_ATTITUDE_TARGET, type_mask = 0 (attitude and body-rate
feed-forward both used, as ArduPilot does when the three rate bits are clear)::

    q_target = attitude one control period ahead under alpha_d
    body rates (feed-forward) = omega + alpha_d / K_r - K_a e(q_target)

  where ``K_a`` are the angle gains (ATC_ANG_RLL_P, ... read from the vehicle)
  and ``e`` the rotation vector from the current attitude to the target, so
  that the autopilot's ``omega_d = K_a e + ff`` equals ``omega + alpha_d / K_r``.

Thrust in all three (GUID_OPTIONS bit 3 set: thrust is thrust, not a climb
rate): ``thrust_norm = clip(u / (m g) * hover_throttle, 0, 1)`` with
``hover_throttle`` = MOT_THST_HOVER read from the vehicle — the throttle that
holds the vehicle, assumed linear in thrust around it.
"""

from __future__ import annotations

from dataclasses import dataclass

from quadrotor.frames import euler_accel_to_body_accel, euler_rates_to_body_rates, euler_to_quaternion, rotation_vector
from quadrotor.state import Command, State

__all__ = ["OutputModel", "OutputAdapter", "OUTPUTS"]

OUTPUTS = ("attitude", "rates", "actuator")
IGNORE_RATES = 1 | 2 | 4
IGNORE_ATTITUDE = 128


@dataclass(frozen=True)
class OutputModel:
    """What the adapters need to know of the vehicle and its autopilot (SI units)."""

    kind: str
    mass_kg: float
    gravity_m_s2: float
    hover_throttle: float
    inertia_kg_m2: tuple[float, float, float]
    max_torque_nm: tuple[float, float, float]
    rate_gain_1_s: tuple[float, float, float]
    angle_gain_1_s: tuple[float, float, float] = (4.5, 4.5, 4.5)
    ts_s: float = 0.01

    def __post_init__(self) -> None:
        if self.kind not in OUTPUTS:
            raise ValueError(f"output must be one of {OUTPUTS}, got {self.kind!r}")
        if not 0.0 < self.hover_throttle < 1.0:
            raise ValueError(f"hover_throttle must be in (0, 1), got {self.hover_throttle!r}")
        for name in ("inertia_kg_m2", "max_torque_nm", "rate_gain_1_s", "angle_gain_1_s"):
            if len(getattr(self, name)) != 3 or min(getattr(self, name)) <= 0:
                raise ValueError(f"{name} must be three positive numbers, got {getattr(self, name)!r}")

    def thrust_norm(self, thrust_n: float) -> float:
        """Normalised thrust 0..1 for a thrust in newtons."""
        v = thrust_n / (self.mass_kg * self.gravity_m_s2) * self.hover_throttle
        return 0.0 if v < 0.0 else 1.0 if v > 1.0 else v


class OutputAdapter:
    """Encodes commands for one vehicle as MAVLink messages."""

    def __init__(self, model: OutputModel, mav, target_system: int = 1, target_component: int = 1) -> None:
        self.model = model
        self.mav = mav
        self.target_system = target_system
        self.target_component = target_component

    def body_accel(self, state: State, cmd: Command) -> tuple[float, float, float]:
        """FRD body angular acceleration [rad/s^2] for the command's Euler-angle accelerations."""
        return euler_accel_to_body_accel((state.roll, state.pitch, state.yaw),
                                         (state.roll_rate, state.pitch_rate, state.yaw_rate),
                                         (cmd.roll_accel_rad_s2, cmd.pitch_accel_rad_s2, cmd.yaw_accel_rad_s2))

    def fields(self, state: State, cmd: Command) -> dict:
        """The setpoint's fields (also what the log records)."""
        m = self.model
        alpha = self.body_accel(state, cmd)
        thrust = m.thrust_norm(cmd.thrust_n)
        if m.kind == "actuator":
            controls = [max(-1.0, min(1.0, i * a / t)) for i, a, t in zip(m.inertia_kg_m2, alpha, m.max_torque_nm)]
            return {"message": "SET_ACTUATOR_CONTROL_TARGET", "controls": controls + [thrust, 0.0, 0.0, 0.0, 0.0]}
        omega = euler_rates_to_body_rates(state.roll, state.pitch, state.roll_rate, state.pitch_rate, state.yaw_rate)
        rates = [w + a / k for w, a, k in zip(omega, alpha, m.rate_gain_1_s)]
        q_now = euler_to_quaternion(state.roll, state.pitch, state.yaw)
        if m.kind == "rates":
            return {"message": "SET_ATTITUDE_TARGET", "type_mask": IGNORE_ATTITUDE, "q": list(q_now),
                    "body_rates": rates, "thrust": thrust}
        # attitude: the attitude one period ahead, and the feed-forward that makes the loop deliver alpha_d.
        h = m.ts_s
        ahead = (state.roll + state.roll_rate * h + 0.5 * cmd.roll_accel_rad_s2 * h * h,
                 state.pitch + state.pitch_rate * h + 0.5 * cmd.pitch_accel_rad_s2 * h * h,
                 state.yaw + state.yaw_rate * h + 0.5 * cmd.yaw_accel_rad_s2 * h * h)
        q_t = euler_to_quaternion(*ahead)
        e = rotation_vector(q_now, q_t)
        ff = [r - k * ei for r, k, ei in zip(rates, m.angle_gain_1_s, e)]
        return {"message": "SET_ATTITUDE_TARGET", "type_mask": 0, "q": list(q_t), "body_rates": ff, "thrust": thrust}

    def encode(self, fields: dict, time_boot_ms: int):
        """A pymavlink message from :meth:`fields`."""
        if fields["message"] == "SET_ACTUATOR_CONTROL_TARGET":
            return self.mav.set_actuator_control_target_encode(
                time_boot_ms * 1000, 0, self.target_system, self.target_component, fields["controls"])
        r = fields["body_rates"]
        return self.mav.set_attitude_target_encode(
            time_boot_ms & 0xFFFFFFFF, self.target_system, self.target_component, fields["type_mask"],
            fields["q"], r[0], r[1], r[2], fields["thrust"])

    def level(self, state: State, thrust_n: float, time_boot_ms: int):
        """A level-attitude setpoint (yaw held) at ``thrust_n``: what failsafes send while the link lives."""
        q = euler_to_quaternion(0.0, 0.0, state.yaw)
        return self.mav.set_attitude_target_encode(time_boot_ms & 0xFFFFFFFF, self.target_system,
                                                   self.target_component, IGNORE_RATES, q, 0.0, 0.0, 0.0,
                                                   self.model.thrust_norm(thrust_n))

