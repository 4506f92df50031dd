"""Physics of the 4-DOF rig: the paper's reduced model with y and yaw locked, stops, motors.

The rig (paper section 4.1) holds the quadrotor on two bars: it moves along
x and z and turns in roll and pitch; y and yaw are locked.  Joints limit roll
to +-15 deg and pitch to +-60 deg.

Model (paper frame, z up, SI units):

* translation and attitude: :func:`quadrotor.plant.step` (eq. 1 with linear air
  drag, RK4, ground contact at z = 0) in sub-steps of ``max_substep_s``; after
  each sub-step y, vy, yaw and yaw rate are reset to 0 (the bars take those
  forces and torques);
* mechanical stops: after each sub-step an angle beyond its stop is set to
  the stop and a rate pointing further out is zeroed (an inelastic stop);
* motors (paper numbering): collective thrust ``u = f1 + f2 + f3 + f4``, roll
  torque ``L ((f1 + f2) - (f3 + f4))``, pitch torque ``L ((f1 + f4) - (f2 + f3))``;
  angular acceleration = torque / inertia.  Each motor gives 0 to
  ``max_motor_thrust_n``; a 10-bit PWM value p gives ``max_motor_thrust_n * p / 1023``
  (linear).  A thrust/angular-acceleration demand is turned into motor thrusts
  by the inverse mixer and each motor is clipped to its range, so a demand the
  motors cannot produce loses torque first where a motor saturates.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

from quadrotor import plant
from quadrotor.state import State

__all__ = ["RigParams", "RigStep", "mix", "unmix", "pwm_to_thrust", "step"]


@dataclass(frozen=True)
class RigParams:
    """Parameters of the rig's plant.

    Attributes
    ----------
    mass_kg : float
        Moving mass (the paper's 1 kg).
    gravity_m_s2 : float
    max_motor_thrust_n : float
        Full thrust of one motor (4 x 6.125 = 24.5 N, the indoor config's limit).
    arm_length_m : float
        Lever arm L of a motor pair about the roll and pitch axes.
    inertia_roll_kg_m2, inertia_pitch_kg_m2 : float
        Moments of inertia about the roll and pitch joints.
    roll_stop_rad, pitch_stop_rad : float
        Mechanical stops, symmetric (+-15 deg and +-60 deg).
    drag_n_per_m_s : float
        Linear air drag coefficient [N/(m/s)].
    max_substep_s : float
        Integration sub-step; the stops are applied after each.
    """

    mass_kg: float = 1.0
    gravity_m_s2: float = 9.81
    max_motor_thrust_n: float = 6.125
    arm_length_m: float = 0.175
    inertia_roll_kg_m2: float = 0.0115
    inertia_pitch_kg_m2: float = 0.0115
    roll_stop_rad: float = math.radians(15.0)
    pitch_stop_rad: float = math.radians(60.0)
    drag_n_per_m_s: float = 0.25
    max_substep_s: float = 0.001

    def __post_init__(self) -> None:
        for name in ("mass_kg", "gravity_m_s2", "max_motor_thrust_n", "arm_length_m", "inertia_roll_kg_m2",
                     "inertia_pitch_kg_m2", "roll_stop_rad", "pitch_stop_rad", "max_substep_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if not self.drag_n_per_m_s >= 0:
            raise ValueError(f"drag_n_per_m_s must be >= 0, got {self.drag_n_per_m_s!r}")
        if self.roll_stop_rad >= math.pi / 2 or self.pitch_stop_rad >= math.pi / 2:
            raise ValueError("stops must be below 90 deg")

    @property
    def max_thrust_n(self) -> float:
        """Collective thrust with every motor at full thrust [N]."""
        return 4.0 * self.max_motor_thrust_n

    @property
    def hover_thrust_n(self) -> float:
        """Thrust that holds the level rig in the air [N]."""
        return self.mass_kg * self.gravity_m_s2

    @property
    def reduced(self) -> plant.ReducedParams:
        """The matching :class:`~quadrotor.plant.ReducedParams` (saturation left to the motors)."""
        amax = 2.0 * self.max_motor_thrust_n * self.arm_length_m / min(self.inertia_roll_kg_m2,
                                                                      self.inertia_pitch_kg_m2)
        return plant.ReducedParams(mass_kg=self.mass_kg, gravity_m_s2=self.gravity_m_s2,
                                     max_thrust_n=self.max_thrust_n, max_angular_accel_rad_s2=amax,
                                     drag_n_per_m_s=self.drag_n_per_m_s, max_substep_s=self.max_substep_s)


def mix(thrust_n: float, roll_accel_rad_s2: float, pitch_accel_rad_s2: float,
        params: RigParams) -> tuple[tuple[float, float, float, float], bool]:
    """Motor thrusts [N] for a demand, each clipped to ``[0, max_motor_thrust_n]``.

    Returns
    -------
    motors : tuple of 4 float
        f1..f4 [N].
    saturated : bool
        True if a motor was clipped.
    """
    base = 0.25 * thrust_n
    r = 0.25 * roll_accel_rad_s2 * params.inertia_roll_kg_m2 / params.arm_length_m
    p = 0.25 * pitch_accel_rad_s2 * params.inertia_pitch_kg_m2 / params.arm_length_m
    raw = (base + r + p, base + r - p, base - r - p, base - r + p)
    fmax = params.max_motor_thrust_n
    out = tuple(0.0 if f < 0.0 else fmax if f > fmax else f for f in raw)
    return out, out != raw  # type: ignore[return-value]


def unmix(motors: Sequence[float], params: RigParams) -> tuple[float, float, float]:
    """``(thrust_n, roll_accel_rad_s2, pitch_accel_rad_s2)`` produced by motor thrusts f1..f4 [N]."""
    f1, f2, f3, f4 = motors
    lever = params.arm_length_m
    return (f1 + f2 + f3 + f4,
            lever * ((f1 + f2) - (f3 + f4)) / params.inertia_roll_kg_m2,
            lever * ((f1 + f4) - (f2 + f3)) / params.inertia_pitch_kg_m2)


def pwm_to_thrust(pwm: int, params: RigParams) -> float:
    """Thrust of one motor [N] for a 10-bit PWM value (clipped to 0..1023)."""
    p = 0 if pwm < 0 else 1023 if pwm > 1023 else pwm
    return params.max_motor_thrust_n * p / 1023.0


class RigStep(NamedTuple):
    """Result of :func:`step`."""

    state: State
    roll_at_stop: bool
    pitch_at_stop: bool


def _stop(angle: float, rate: float, limit: float) -> tuple[float, float, bool]:
    if angle >= limit:
        return limit, (0.0 if rate > 0.0 else rate), True
    if angle <= -limit:
        return -limit, (0.0 if rate < 0.0 else rate), True
    return angle, rate, False


def step(state: Sequence[float], motors: Sequence[float], dt: float, params: RigParams,
         reduced_params: plant.ReducedParams | None = None) -> RigStep:
    """Advance the rig by ``dt`` seconds with the motor thrusts held.

    Parameters
    ----------
    state : sequence of 12 floats
        :class:`~quadrotor.plant.State` order (y, vy, yaw, yaw rate are ignored: locked at 0).
    motors : sequence of 4 floats
        f1..f4 [N], already within ``[0, max_motor_thrust_n]``.
    dt : float
        Duration [s], > 0.
    params : RigParams
    reduced_params : ReducedParams or None
        ``params.reduced``, passed in to save rebuilding it every call.

    Returns
    -------
    RigStep
    """
    if not dt > 0:
        raise ValueError(f"dt must be > 0, got {dt!r}")
    rp = reduced_params or params.reduced
    u, a_roll, a_pitch = unmix(motors, params)
    cmd = (u, a_roll, a_pitch, 0.0)
    n = max(1, math.ceil(dt / params.max_substep_s - 1e-9))
    h = dt / n
    x, _, z, vx, _, vz, phi, th, _, p, q, _ = (float(v) for v in state)
    phi, p, at_r = _stop(phi, p, params.roll_stop_rad)
    th, q, at_p = _stop(th, q, params.pitch_stop_rad)
    s = State(x, 0.0, z, vx, 0.0, vz, phi, th, 0.0, p, q, 0.0)
    for _ in range(n):
        s = plant.step(s, cmd, h, rp)
        phi, p, at_r = _stop(s.roll, s.roll_rate, params.roll_stop_rad)
        th, q, at_p = _stop(s.pitch, s.pitch_rate, params.pitch_stop_rad)
        s = State(s.x, 0.0, s.z, s.vx, 0.0, s.vz, phi, th, 0.0, p, q, 0.0)
    return RigStep(s, at_r, at_p)
