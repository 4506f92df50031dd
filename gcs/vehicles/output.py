"""Output adapters: the controller's command as MAVLink setpoints.

The controllers command thrust ``u`` [N] and Euler-angle accelerations ``tau`` [rad/s^2] (the
paper's model has unit inertia), and close their attitude loops fast: their rate damping
``b = -d tau / d omega`` is 63-66 1/s in roll and pitch, 78-86 1/s in yaw (PD, NLSOC, LOC).
No autopilot delivers an angular acceleration that quickly: ArduCopter's rate loop answers
in about 40 ms (message latency, its 400 Hz pipeline, filters), and commanding ``tau`` through
it with its own gain makes those loops oscillate or diverge.  So the adapters hand the fast
loop to the autopilot.  First ``tau`` becomes FRD body angular accelerations ``alpha_d`` with
the exact kinematics (:func:`quadrotor.frames.euler_accel_to_body_accel`; the identity near
hover), then a body-rate demand::

    omega_d = omega + alpha_d / K_d          (K_d = ``[flight] rate_gain_1_s``, default 65, 65, 80 1/s)

With ``K_d`` equal to the law's rate damping ``b`` the measured rate cancels: ``omega_d`` is
the rate the law's fast attitude loop settles to (its slow manifold, ``tau = 0``), and the
autopilot's rate loop realises it whatever its own gain and delay; the slow (position)
dynamics of the paper's closed loop are kept.  A ``K_d`` equal to the autopilot's true rate-loop
gain would deliver ``alpha_d`` itself, but only without delay.  ``omega_d`` is clipped to the
autopilot's rate limits (ATC_RATE_R/P/Y_MAX, where set).  Then, per ``--output``:

``attitude`` (default) — SET_ATTITUDE_TARGET, type_mask = 7 (body rates ignored, i.e. zero)::

    q_target = q(t + Ts) * exp(e),   e_i = S_i^-1(omega_d,i)

  ``q(t + Ts)`` is the attitude one control period ahead at the measured rate and ``S_i`` the
  autopilot's angle loop, ``omega = S(e)``: ``K_a e`` (K_a = ATC_ANG_RLL/PIT/YAW_P) up to
  ``|e| = A_i / K_a^2``, then ``sqrt(2 A_i (|e| - A_i / (2 K_a^2)))`` with ``A_i`` = ATC_ACC_*_MAX / 2
  clamped to 40-720 deg/s^2 (roll, pitch) and 10-120 deg/s^2 (yaw) (AC_AttitudeControl's
  sqrt_controller).  With ATC_RATE_FF_ENAB = 0 (set for the flight by the ArduPilot profile)
  ArduCopter flies ``omega_cmd = S(e)`` on this quaternion, unshaped: ``omega_cmd = omega_d``.
  The setpoint is a fixed attitude: if the next message never comes the vehicle settles
  there (within ``|omega_d| / K_a`` of where it was, a fraction of a degree in cruise) until
  GUID_TIMEOUT levels it.  Non-zero rates would instead be integrated into the stored target
  until GUID_TIMEOUT (ArduCopter) and, with ATC_RATE_FF_ENAB = 1, be ignored as feed-forward.

  **The rate-error integral** (:class:`RateErrorIntegral`).  Each setpoint is anchored on the measured
  attitude, so the angle loop alone is a proportional rate loop around it: a steady torque the model
  does not have (a weak motor, an off-centre payload, a trim) leaves the rate short of ``omega_d`` until
  the autopilot's own rate integrator has learnt it — ArduCopter's yaw one (ATC_RAT_YAW_I 0.02) takes
  tens of seconds, and a 15 % weak motor then held the yaw 11 deg off for 30 s and the circle 0.5 m
  off.  So, as ArduCopter does with a rate input (its target integrates the rate), the shortfall is
  integrated into the target::

      delta += Ts (omega_m - omega),   omega_m = the demand through the modelled rate response
      e_i    = S_i^-1(omega_d,i) + delta_i

  ``omega_m`` is ``omega_d`` one period later through a first-order lag of ``[flight] rate_response_s``
  (0.04 s: ArduCopter SITL's measured rate follows the demand so), so a nominal vehicle's transients
  leave ``delta`` near 0.  The angle loop turns ``delta`` into ``K_a delta`` of extra rate: an integral
  on the rate error with gain ``K_a``.  ``|delta_i|`` is bounded by ``[flight] rate_integral_max_rad``
  (0.1, 0.1, 0.2 rad; 0 turns an axis off); it integrates only in the air (the estimate above the
  mission's start), relaxes on the ground over 0.5 s and restarts after level setpoints.

``rates`` — SET_ATTITUDE_TARGET, type_mask = 128 (attitude ignored), body rates = ``omega_d``;
  the quaternion is the current attitude (ArduPilot rejects non-unit quaternions even when
  ignored).  ArduCopter (ATC_RATE_FF_ENAB = 1) shapes the rate with ACRO_RP_RATE_TC and tracks
  it around an attitude target it integrates from it.  On a stall it keeps turning at the
  last ``omega_d`` until GUID_TIMEOUT (0.5 s for the flight): a tilt of ``|omega_d| x 0.5 s``.

``actuator`` — SET_ACTUATOR_CONTROL_TARGET, group 0 (autopilots that take it: the built-in SITL;
  ArduCopter has no handler and is refused before arming)::

    controls[0..2] = clip(I alpha_d / max_torque_nm, -1, 1)   (roll, pitch, yaw)
    controls[3]    = thrust_norm

Thrust in all three (GUID_OPTIONS bit 3 set: thrust is thrust, not a climb rate)::

    thrust_norm = clip(u / (m g) * MOT_THST_HOVER, 0, 1)

ArduCopter linearises its thrust curve itself (MOT_THST_EXPO, MOT_SPIN_MIN/MAX, battery
voltage), so the field is proportional to thrust; what MOT_THST_HOVER gets wrong (it is not
learned in this mode: 0.39 set, 0.366 true in ArduPilot's SITL) is a steady vertical
acceleration the disturbance observer estimates (:mod:`gcs.estimate`) and the controllers
compensate.  Its spool-up after arming is waited out by the preflight.  "Level" setpoints
(failsafes, preflight, landing) always carry zero body rates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from quadrotor.frames import euler_accel_to_body_accel, euler_rates_to_body_rates, euler_to_quaternion, quat_multiply
from quadrotor.state import Command, State

__all__ = ["OutputModel", "OutputAdapter", "RateErrorIntegral", "OUTPUTS", "build_adapter", "angle_for_rate",
           "rotation_quaternion", "IGNORE_RATES", "IGNORE_ATTITUDE"]

OUTPUTS = ("attitude", "rates", "actuator")
IGNORE_RATES = 1 | 2 | 4
IGNORE_ATTITUDE = 128
_ZERO = (0.0, 0.0, 0.0)
#: Time constant of the integral's relaxation on the ground [s] (ArduCopter relaxes its I terms over 0.5 s).
GROUND_RELAX_S = 0.5


def rotation_quaternion(v) -> tuple[float, float, float, float]:
    """The unit quaternion ``exp(v)`` of a rotation vector ``v`` [rad] (w, x, y, z)."""
    a = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if a < 1e-12:
        return (1.0, 0.5 * v[0], 0.5 * v[1], 0.5 * v[2])
    s = math.sin(0.5 * a) / a
    return (math.cos(0.5 * a), v[0] * s, v[1] * s, v[2] * s)


def angle_for_rate(rate_rad_s: float, gain_1_s: float, accel_limit_rad_s2: float) -> float:
    """The angle error [rad] for which ArduCopter's angle loop ``sqrt_controller`` demands ``rate_rad_s``.

    Linear (``rate / gain``) up to ``accel_limit / gain``, then ``rate^2 / (2 A) + A / (2 gain^2)``;
    ``accel_limit_rad_s2 <= 0``: linear everywhere.
    """
    if accel_limit_rad_s2 <= 0.0 or abs(rate_rad_s) * gain_1_s <= accel_limit_rad_s2:
        return rate_rad_s / gain_1_s
    a = accel_limit_rad_s2
    return math.copysign(rate_rad_s * rate_rad_s / (2.0 * a) + a / (2.0 * gain_1_s * gain_1_s), rate_rad_s)


class RateErrorIntegral:
    """The attitude output's integral of the rate shortfall (module docstring), per FRD body axis.

    Parameters
    ----------
    ts_s : float
        The control period (one :meth:`update` per period).
    response_s : float
        Time constant of the modelled rate response ``omega_m`` to the demand.
    max_rad : (3,) float
        Bound of ``|delta|`` per axis [rad] (0: that axis off).
    """

    __slots__ = ("ts_s", "max_rad", "_a", "_relax", "model_rad_s", "delta_rad")

    def __init__(self, ts_s: float, response_s: float, max_rad) -> None:
        if not (ts_s > 0.0 and response_s > 0.0) or len(max_rad) != 3 or min(max_rad) < 0.0:
            raise ValueError(f"need ts_s > 0, response_s > 0 and three bounds >= 0, got {ts_s!r}, {response_s!r}, "
                             f"{max_rad!r}")
        self.ts_s = ts_s
        self.max_rad = tuple(float(m) for m in max_rad)
        self._a = ts_s / (response_s + ts_s)
        self._relax = min(1.0, ts_s / GROUND_RELAX_S)
        self.model_rad_s = [0.0, 0.0, 0.0]
        self.delta_rad = [0.0, 0.0, 0.0]

    def reset(self, omega=_ZERO) -> None:
        """Start again from no offset, the modelled rate at ``omega`` [rad/s]."""
        self.model_rad_s = [float(w) for w in omega]
        self.delta_rad = [0.0, 0.0, 0.0]

    def update(self, omega, airborne: bool) -> list[float]:
        """One period: ``delta`` after the measured body rate ``omega`` [rad/s] (before this period's demand)."""
        d, m, h = self.delta_rad, self.model_rad_s, self.ts_s
        for i in range(3):
            lim = self.max_rad[i]
            if airborne and lim > 0.0:
                v = d[i] + h * (m[i] - omega[i])
                d[i] = lim if v > lim else -lim if v < -lim else v
            else:
                d[i] -= self._relax * d[i]
        return d

    def demanded(self, demand) -> None:
        """The rate demand sent this period: the model's input for the next one."""
        m, a = self.model_rad_s, self._a
        for i in range(3):
            m[i] += a * (demand[i] - m[i])


@dataclass(frozen=True)
class OutputModel:
    """What the adapters need to know of the vehicle and its autopilot (SI units; see the module docstring).

    Attributes
    ----------
    kind : {"attitude", "rates", "actuator"}
    mass_kg, gravity_m_s2 : float
        The controllers' model.
    hover_throttle : float
        The thrust field that holds the vehicle (MOT_THST_HOVER).
    inertia_kg_m2, max_torque_nm : (3,) float
        For ``actuator``: torque = I alpha, normalised by the maximum torque.
    rate_gain_1_s : (3,) float
        ``K_d``: angular acceleration per rate error of the rate demand.
    angle_gain_1_s : (3,) float
        ``K_a``: the autopilot's angle P (ATC_ANG_*_P).
    angle_accel_limit_rad_s2 : (3,) float
        ``A``: the acceleration limit of the autopilot's angle loop (0: linear).
    rate_limit_rad_s : (3,) float
        The autopilot's rate limits (0: none).
    ts_s : float
        The control period (the attitude setpoint leads by it).
    rate_integral_max_rad : (3,) float
        The attitude output's rate-error integral bounds (all 0: no integral).
    rate_response_s : float
        Its modelled rate-response time constant.
    """

    kind: str
    mass_kg: float
    gravity_m_s2: float
    hover_throttle: float
    inertia_kg_m2: tuple[float, float, float]
    max_torque_nm: tuple[float, float, float]
    rate_gain_1_s: tuple[float, float, float]
    angle_gain_1_s: tuple[float, float, float] = (4.5, 4.5, 4.5)
    angle_accel_limit_rad_s2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rate_limit_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ts_s: float = 0.01
    rate_integral_max_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rate_response_s: float = 0.04

    def __post_init__(self) -> None:
        if self.kind not in OUTPUTS:
            raise ValueError(f"output must be one of {OUTPUTS}, got {self.kind!r}")
        if not 0.0 < self.hover_throttle < 1.0:
            raise ValueError(f"hover_throttle must be in (0, 1), got {self.hover_throttle!r}")
        for name in ("inertia_kg_m2", "max_torque_nm", "rate_gain_1_s", "angle_gain_1_s"):
            if len(getattr(self, name)) != 3 or min(getattr(self, name)) <= 0:
                raise ValueError(f"{name} must be three positive numbers, got {getattr(self, name)!r}")
        for name in ("angle_accel_limit_rad_s2", "rate_limit_rad_s", "rate_integral_max_rad"):
            if len(getattr(self, name)) != 3 or min(getattr(self, name)) < 0:
                raise ValueError(f"{name} must be three numbers >= 0, got {getattr(self, name)!r}")

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
        #: The rate-error integral of the attitude output (None: none).
        self.integral = (RateErrorIntegral(model.ts_s, model.rate_response_s, model.rate_integral_max_rad)
                         if model.kind == "attitude" and max(model.rate_integral_max_rad) > 0.0 else None)

    def body_accel(self, state: State, cmd: Command) -> tuple[float, float, float]:
        """FRD body angular acceleration [rad/s^2] for the command's Euler-angle accelerations."""
        return euler_accel_to_body_accel((state.roll, state.pitch, state.yaw),
                                         (state.roll_rate, state.pitch_rate, state.yaw_rate),
                                         (cmd.roll_accel_rad_s2, cmd.pitch_accel_rad_s2, cmd.yaw_accel_rad_s2))

    def rate_demand(self, omega, alpha) -> list[float]:
        """``omega_d = omega + alpha_d / K_d`` [rad/s], clipped to the autopilot's rate limits."""
        out = []
        for w, a, k, lim in zip(omega, alpha, self.model.rate_gain_1_s, self.model.rate_limit_rad_s):
            v = w + a / k
            out.append(v if lim <= 0.0 else lim if v > lim else -lim if v < -lim else v)
        return out

    def fields(self, state: State, cmd: Command, airborne: bool = True) -> dict:
        """The setpoint's fields (also what the log records); ``airborne``: the rate-error integral may learn."""
        m = self.model
        alpha = self.body_accel(state, cmd)
        thrust = m.thrust_norm(cmd.thrust_n)
        if m.kind == "actuator":
            controls = [max(-1.0, min(1.0, i * a / t)) for i, a, t in zip(m.inertia_kg_m2, alpha, m.max_torque_nm)]
            return {"message": "SET_ACTUATOR_CONTROL_TARGET", "controls": controls + [thrust, 0.0, 0.0, 0.0, 0.0]}
        omega = euler_rates_to_body_rates(state.roll, state.pitch, state.roll_rate, state.pitch_rate, state.yaw_rate)
        demand = self.rate_demand(omega, alpha)
        q_now = euler_to_quaternion(state.roll, state.pitch, state.yaw)
        if m.kind == "rates":
            return {"message": "SET_ATTITUDE_TARGET", "type_mask": IGNORE_ATTITUDE, "q": list(q_now),
                    "body_rates": demand, "thrust": thrust}
        # attitude: a fixed target whose angle error makes the autopilot's angle loop demand omega_d
        h = m.ts_s
        ahead = quat_multiply(q_now, rotation_quaternion((omega[0] * h, omega[1] * h, omega[2] * h)))
        e = [angle_for_rate(w, k, a) for w, k, a in zip(demand, m.angle_gain_1_s, m.angle_accel_limit_rad_s2)]
        if self.integral is not None:
            delta = self.integral.update(omega, airborne)
            self.integral.demanded(demand)
            e = [e[0] + delta[0], e[1] + delta[1], e[2] + delta[2]]
        q_t = quat_multiply(ahead, rotation_quaternion(e))
        n = math.sqrt(sum(c * c for c in q_t))
        return {"message": "SET_ATTITUDE_TARGET", "type_mask": IGNORE_RATES, "q": [c / n for c in q_t],
                "body_rates": list(_ZERO), "thrust": thrust}

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
        """A level-attitude setpoint (yaw held, zero body rates) at ``thrust_n``: what failsafes send while
        the link lives.  The rate-error integral starts again after it."""
        if self.integral is not None:
            self.integral.reset()
        q = euler_to_quaternion(0.0, 0.0, state.yaw)
        return self.mav.set_attitude_target_encode(time_boot_ms & 0xFFFFFFFF, self.target_system,
                                                   self.target_component, IGNORE_RATES, q, 0.0, 0.0, 0.0,
                                                   self.model.thrust_norm(thrust_n))


def build_adapter(kind: str, model, fc, out, ts_s: float, mav, target_system: int,
                  target_component: int) -> OutputAdapter:
    """The adapter for ``kind`` from the controller's model (``mass_kg``, ``gravity_m_s2``), the
    config's ``[flight]`` section ``fc`` and what the autopilot profile read (``out``:
    :class:`gcs.vehicles.ardupilot.OutputParams`)."""
    return OutputAdapter(OutputModel(
        kind=kind, mass_kg=model.mass_kg, gravity_m_s2=model.gravity_m_s2, hover_throttle=out.hover_throttle,
        inertia_kg_m2=fc.inertia_kg_m2, max_torque_nm=fc.max_torque_nm, rate_gain_1_s=fc.rate_gain_1_s,
        angle_gain_1_s=out.angle_gain_1_s, angle_accel_limit_rad_s2=out.angle_accel_limit_rad_s2,
        rate_limit_rad_s=out.rate_limit_rad_s, ts_s=ts_s, rate_integral_max_rad=fc.rate_integral_max_rad,
        rate_response_s=fc.rate_response_s), mav, target_system, target_component)
