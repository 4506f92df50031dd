"""Safety envelope between the controller and the output adapter.

Applied every tick to the controller's command (thrust [N], Euler-angle
accelerations [rad/s^2]) with the state estimate (paper frame):

* thrust is clipped to ``[0, max_thrust_n]``; each angular acceleration to
  ``+-max_angular_accel_rad_s2``;
* tilt: when |roll| or |pitch| exceeds ``max_tilt_rad`` and the demand would
  tilt further, the demand on that axis is replaced by a levelling PD demand;
* a command with a NaN or an infinity is flagged ``non-finite`` (the loop fails safe and
  sends none of it): NaN would pass every comparison of the limits;
* geofence: x or y farther than ``fence_half_width_m`` from the takeoff point, or
  z more than ``ceiling_m`` above it, is reported as a breach (the failsafe lands; the
  envelope itself does not steer).

:meth:`SafetyEnvelope.apply` returns the limited command and the set of
limits that acted this tick, for the console and the log.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from quadrotor.state import Command, State

__all__ = ["EnvelopeLimits", "SafetyEnvelope", "LIMIT_FLAGS", "envelope_for"]

LIMIT_FLAGS = ("thrust", "torque", "tilt", "geofence", "ceiling", "non-finite")


@dataclass(frozen=True)
class EnvelopeLimits:
    """Limits of the envelope (SI units)."""

    max_thrust_n: float
    max_angular_accel_rad_s2: float
    max_tilt_rad: float
    fence_half_width_m: float
    ceiling_m: float
    level_kp: float = 170.0
    level_kd: float = 63.0

    def __post_init__(self) -> None:
        for name in ("max_thrust_n", "max_angular_accel_rad_s2", "max_tilt_rad", "fence_half_width_m", "ceiling_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")


class SafetyEnvelope:
    """Limits commands and watches the fence."""

    def __init__(self, limits: EnvelopeLimits, origin: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        self.limits = limits
        self.origin = origin

    def breaches(self, state: State) -> frozenset[str]:
        """Fence breaches of the estimated state relative to :attr:`origin`, the takeoff point."""
        lim = self.limits
        ox, oy, oz = self.origin
        out = set()
        if abs(state.x - ox) > lim.fence_half_width_m or abs(state.y - oy) > lim.fence_half_width_m:
            out.add("geofence")
        if state.z - oz > lim.ceiling_m:
            out.add("ceiling")
        return frozenset(out)

    def apply(self, state: State, cmd: Command) -> tuple[Command, frozenset[str]]:
        """The limited command and the flags of the limits that acted."""
        lim = self.limits
        if not all(math.isfinite(v) for v in cmd):
            # NaN passes every comparison below: such a command is never limited into something
            # that looks valid; the loop fails safe on this flag and sends nothing of it.
            return Command(0.0, 0.0, 0.0, 0.0), frozenset({"non-finite"})
        flags = set()
        thrust = cmd.thrust_n
        if thrust < 0.0 or thrust > lim.max_thrust_n:
            thrust = min(max(thrust, 0.0), lim.max_thrust_n)
            flags.add("thrust")
        acc = [cmd.roll_accel_rad_s2, cmd.pitch_accel_rad_s2, cmd.yaw_accel_rad_s2]
        for i, (angle, rate) in enumerate(((state.roll, state.roll_rate), (state.pitch, state.pitch_rate))):
            if abs(angle) > lim.max_tilt_rad and acc[i] * angle > 0.0:
                acc[i] = -lim.level_kp * angle - lim.level_kd * rate
                flags.add("tilt")
        a = lim.max_angular_accel_rad_s2
        for i in range(3):
            if acc[i] > a or acc[i] < -a:
                acc[i] = a if acc[i] > a else -a
                flags.add("torque")
        flags |= self.breaches(state)
        return Command(thrust, acc[0], acc[1], acc[2]), frozenset(flags)

    def level(self, state: State, thrust_n: float) -> Command:
        """A levelling command at ``thrust_n`` (roll and pitch PD to zero; yaw rate damped), within the limits.

        For vehicles that take thrust and angular accelerations (the rig) when no controller flies.
        """
        lim = self.limits
        a = lim.max_angular_accel_rad_s2

        def clip(v):
            return a if v > a else -a if v < -a else v

        return Command(min(max(thrust_n, 0.0), lim.max_thrust_n),
                       clip(-lim.level_kp * state.roll - lim.level_kd * state.roll_rate),
                       clip(-lim.level_kp * state.pitch - lim.level_kd * state.pitch_rate),
                       clip(-lim.level_kd * state.yaw_rate))


def envelope_for(config) -> SafetyEnvelope:
    """The envelope of a config: the vehicle's limits, ``[flight]``'s tilt, fence and ceiling, PD levelling gains."""
    fc = config.flight
    return SafetyEnvelope(EnvelopeLimits(
        max_thrust_n=config.vehicle.max_thrust_n, max_angular_accel_rad_s2=config.vehicle.max_angular_accel_rad_s2,
        max_tilt_rad=math.radians(fc.max_tilt_deg), fence_half_width_m=fc.fence_half_width_m,
        ceiling_m=fc.ceiling_m, level_kp=config.pd.kp_phi, level_kd=config.pd.kd_phi))
