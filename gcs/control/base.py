"""The one small interface every controller flies behind, and the horizon schedule.

A controller is *designed* once (gain tables, validated matrices: pure
functions in the controller modules) and then *stepped*:
``command = controller.step(k, state, ref)`` with the control step index
``k`` (0 at the start of the flight), the state estimate and the reference,
both :class:`gcs.model.State` in the paper frame.  Commands are saturated to
the vehicle limits, so what a controller returns is what the vehicle gets
(the NLSOC lateral laws need the thrust actually applied).

``step(k, state, ref, disturbance_m_s2=d)`` also takes an estimated steady disturbance
acceleration ``d`` (x, y, z up) [m/s^2], an acceleration eq. 1 does not have: each law
compensates it where its model has gravity (:func:`gcs.model.disturbance_tilt` and the
laws' docstrings).  It is :data:`NO_DISTURBANCE` unless an estimator gives one, and then the
laws compute exactly what they computed without it.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass

from gcs.config import AFTER_HORIZON
from quadrotor.state import Command, State

__all__ = ["Controller", "Limits", "FiniteHorizonController", "StagedLaw", "steps_to_go", "horizon_mode", "wrap_angle",
           "NO_DISTURBANCE", "Disturbance"]


#: A disturbance acceleration (x, y, z up) [m/s^2].
Disturbance = Sequence[float]
#: No disturbance: what every law assumes unless it is given one.
NO_DISTURBANCE: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Limits:
    """Actuator limits: thrust in [0, max_thrust_n], each angular acceleration in +-max_angular_accel_rad_s2."""

    max_thrust_n: float
    max_angular_accel_rad_s2: float

    def saturate(self, thrust_n: float, t_roll: float, t_pitch: float, t_yaw: float) -> Command:
        """The command clipped to the limits."""
        umax, amax = self.max_thrust_n, self.max_angular_accel_rad_s2
        return Command(
            0.0 if thrust_n < 0.0 else umax if thrust_n > umax else thrust_n,
            -amax if t_roll < -amax else amax if t_roll > amax else t_roll,
            -amax if t_pitch < -amax else amax if t_pitch > amax else t_pitch,
            -amax if t_yaw < -amax else amax if t_yaw > amax else t_yaw,
        )


def wrap_angle(a: float) -> float:
    """Angle wrapped to [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def steps_to_go(k: int, horizon_steps: int, after: str) -> int | None:
    """Steps to go j (>= 1) at control step k, or None when the fallback flies.

    Within the horizon j = N - k, so the last step (k = N - 1) has j = 1 and
    uses the terminal weight H.  After it: ``"terminal"`` keeps j = 1,
    ``"restart"`` starts a new horizon, ``"pd"`` returns None.
    """
    if k < 0:
        raise ValueError(f"k must be >= 0, got {k}")
    if k < horizon_steps:
        return horizon_steps - k
    if after == "terminal":
        return 1
    if after == "restart":
        return horizon_steps - (k % horizon_steps)
    if after == "pd":
        return None
    raise ValueError(f"after must be one of {AFTER_HORIZON}, got {after!r}")


def horizon_mode(k: int, horizon_steps: int | None, after: str | None) -> str:
    """What flies step k: ``horizon`` within the horizon, then ``terminal`` / ``restart`` /
    ``fallback_pd`` (per ``after``); ``pd`` for a controller without a horizon (``horizon_steps`` None)."""
    if horizon_steps is None:
        return "pd"
    if k < horizon_steps:
        return "horizon"
    return {"pd": "fallback_pd"}.get(after or "", after or "after")


class Controller(ABC):
    """A policy: one command from the step index, the state estimate and the reference."""

    name: str = "controller"

    @abstractmethod
    def step(self, k: int, state: State, ref: State, disturbance_m_s2: Disturbance = NO_DISTURBANCE) -> Command:
        """Command for control step ``k`` (thrust [N], angular accelerations [rad/s^2]), compensating the
        disturbance acceleration ``disturbance_m_s2`` (x, y, z up) [m/s^2]."""

    def reset(self) -> None:  # noqa: B027  optional hook, the default does nothing
        """Forget any per-flight state (none by default)."""


class StagedLaw(ABC):
    """A finite-horizon law evaluated with j steps to go (j = 1 is the last step)."""

    @abstractmethod
    def step_j(self, j: int, state: State, ref: State, disturbance_m_s2: Disturbance = NO_DISTURBANCE) -> Command:
        """Command with ``j`` steps to go."""


class FiniteHorizonController(Controller):
    """Runs a :class:`StagedLaw` over the horizon, then what ``after`` says.

    Attributes
    ----------
    last_steps_to_go : int or None
        j used by the last step (None when the fallback flew it).
    """

    def __init__(self, name: str, law: StagedLaw, horizon_steps: int, after: str, fallback: Controller | None) -> None:
        if horizon_steps < 1:
            raise ValueError(f"horizon_steps must be >= 1, got {horizon_steps}")
        if after not in AFTER_HORIZON:
            raise ValueError(f"after must be one of {AFTER_HORIZON}, got {after!r}")
        if after == "pd" and fallback is None:
            raise ValueError("after='pd' needs a fallback controller")
        self.name = name
        self.law = law
        self.horizon_steps = horizon_steps
        self.after = after
        self.fallback = fallback
        self.last_steps_to_go: int | None = None

    def step(self, k: int, state: State, ref: State, disturbance_m_s2: Disturbance = NO_DISTURBANCE) -> Command:
        j = steps_to_go(k, self.horizon_steps, self.after)
        self.last_steps_to_go = j
        if j is None:
            return self.fallback.step(k, state, ref, disturbance_m_s2)  # type: ignore[union-attr]
        return self.law.step_j(j, state, ref, disturbance_m_s2)

    def reset(self) -> None:
        self.last_steps_to_go = None
        if self.fallback is not None:
            self.fallback.reset()
