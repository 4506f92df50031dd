"""Flying a policy on the affine z-psi model of an :class:`gcs.optimal_problem.AltitudeProblem`.

:func:`simulate_policy` is a small rollout of its own (eq. 16 at theta = phi = 0, no ground,
no sensors), separate from the shared mission loop; :class:`OptimalAffinePolicy` flies the
exact optimum behind the controller interface.  The cost of a rollout is eq. 17
(:mod:`gcs.control.cost`) under both input conventions.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gcs.control import Controller
from gcs.control.base import NO_DISTURBANCE, Disturbance, wrap_angle
from gcs.control.cost import cost_input, quadratic_cost
from gcs.model import z_psi_affine_model
from gcs.optimal_problem import COST_CONVENTIONS, Z_PSI, AltitudeProblem, check_convention
from quadrotor.state import Command, State

__all__ = ["OptimalAffinePolicy", "Rollout", "eq17_cost", "simulate_policy"]


class OptimalAffinePolicy(Controller):
    """The optimal policy of an :class:`AltitudeProblem` behind the controller interface.

    ``u = -K x - k_ff`` on the z-psi error; the thrust is ``u_1`` plus the problem's hover
    offset; roll and pitch demands are 0.  Valid for k = 0 .. N-1.
    """

    name = "optimal"

    def __init__(self, problem: AltitudeProblem, K: np.ndarray, k_ff: np.ndarray) -> None:
        self.problem = problem
        self.K, self.k_ff = K, k_ff

    def step(self, k: int, state: State, ref: State, disturbance_m_s2: Disturbance = NO_DISTURBANCE) -> Command:
        """The optimum of the problem's model, which has no disturbance (``disturbance_m_s2`` is not used)."""
        N = self.problem.horizon_steps
        if not 0 <= k < N:
            raise ValueError(f"k must be in 0 .. {N - 1}, got {k}")
        x = np.asarray(state, float)[Z_PSI] - np.asarray(ref, float)[Z_PSI]
        u = -self.K[N - k - 1] @ x - self.k_ff[N - k - 1]
        return Command(float(u[0]) + self.problem.hover_offset_n, 0.0, 0.0, float(u[1]))


@dataclass(frozen=True)
class Rollout:
    """A policy flown on the affine model over the horizon.

    Attributes
    ----------
    x : ndarray, shape (N + 1, 4)
        Error state [e_z, e_vz, e_yaw, e_yaw_rate] at k = 0 .. N.
    z_ref : ndarray, shape (N + 1,)
        Altitude reference [m] at k = 0 .. N.
    command : ndarray, shape (N, 4)
        Commands as returned by the policy (thrust [N], angular accelerations [rad/s^2]).
    cost : dict {convention: float}
        Eq. 17 cost under each input convention of :data:`COST_CONVENTIONS`.
    thrust_floor_steps : int
        Steps where the thrust was exactly 0 (the floor of :class:`gcs.control.Limits`,
        a constraint the LQ optimum does not have).
    """

    x: np.ndarray
    z_ref: np.ndarray
    command: np.ndarray
    cost: dict
    thrust_floor_steps: int

    @property
    def min_z_m(self) -> float:
        """Lowest altitude reached [m] (negative: through the ground, which the affine model lacks)."""
        return float(np.min(self.x[:, 0] + self.z_ref))


def eq17_cost(problem: AltitudeProblem, x: np.ndarray, thrust: np.ndarray, tau_psi: np.ndarray,
              convention: str | None = None) -> float:
    """Eq. 17 of an error trajectory ``x`` (N + 1, 4) and inputs (N,) under ``convention``
    (default: the problem's), with the problem's Q, R, H."""
    conv = problem.convention if convention is None else convention
    check_convention(conv)
    N = problem.horizon_steps
    if x.shape != (N + 1, 4) or thrust.shape != (N,) or tau_psi.shape != (N,):
        raise ValueError(f"trajectory shapes {x.shape}, {thrust.shape}, {tau_psi.shape}; "
                         f"expected ({N + 1}, 4), ({N},), ({N},)")
    # theta = phi = 0: the hover thrust of eq. 17's u is m g
    u = np.column_stack(cost_input("nlsoc", thrust, tau_psi, 1.0, problem.mass_kg, problem.gravity_m_s2,
                                   gravity_compensated=(conv == "compensated")))
    return quadratic_cost(x, u, problem.Q, problem.R, problem.H)


def simulate_policy(problem: AltitudeProblem, policy: Controller,
                    start: Sequence[float] = (0.0, 0.0, 0.0, 0.0)) -> Rollout:
    """Fly ``policy`` on the affine z-psi model of ``problem`` for N steps.

    The policy gets ``policy.step(k, state, ref)`` with a :class:`gcs.model.State` whose z,
    vz, yaw and yaw rate are the model's and everything else (lateral axes, roll, pitch)
    0, and the mission reference row k.  Its thrust and yaw demand drive eq. 16 with
    theta = phi = 0 (:func:`gcs.model.z_psi_affine_model`, literal: ``s+ = A s + B [thrust,
    tau_psi] + [0, -g Ts, 0, 0]``, the same physics for both conventions); roll and pitch
    demands are ignored.  The model has no ground.

    Parameters
    ----------
    problem : AltitudeProblem
    policy : Controller
        Reset before the flight.
    start : sequence of 4 floats
        Absolute initial [z, vz, yaw, yaw_rate]; default at rest on the ground.

    Returns
    -------
    Rollout
        With the eq. 17 cost under both conventions.
    """
    N = problem.horizon_steps
    a, b, d = z_psi_affine_model(problem.ts_s, problem.mass_kg, problem.gravity_m_s2, gravity_compensated=False)
    s = np.asarray(start, float)
    if s.shape != (4,):
        raise ValueError(f"start has shape {s.shape}, expected (4,)")
    policy.reset()
    refs = problem.refs
    states = np.empty((N + 1, 4))
    cmds = np.empty((N, 4))
    full = [0.0] * 12
    for k in range(N):
        states[k] = s
        full[2], full[5], full[8], full[11] = (float(v) for v in s)
        cmd = policy.step(k, State(*full), State(*refs[k]))
        cmds[k] = cmd
        s = a @ s + b @ np.array([cmd[0], cmd[3]]) + d
    states[N] = s
    x = states - refs[:, Z_PSI]
    x[:, 2] = wrap_angle(x[:, 2])
    costs = {conv: eq17_cost(problem, x, cmds[:, 0], cmds[:, 3], conv) for conv in COST_CONVENTIONS}
    floor = int(np.count_nonzero(cmds[:, 0] == 0.0))
    return Rollout(x, refs[:, 2].copy(), cmds, costs, floor)
