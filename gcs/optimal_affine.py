"""The true optimum of the altitude (z-psi) subproblem, and each controller's optimality gap.

The pieces, each in its own module (this one re-exports them):

* the problem: eq. 16 at theta = phi = 0 in error coordinates around the mission reference,
  ``x(k+1) = A x(k) + B v(k) + c(k)``, with eq. 17's weights (:mod:`gcs.optimal_problem`:
  :class:`AltitudeProblem`, :func:`altitude_problem`; the matrices are
  :func:`gcs.model.z_psi_affine_model`);
* its exact optimum: the affine-LQ Riccati recursion :func:`gcs.control.riccati.affine_lqr`
  (:func:`affine_lqr_cost`), the general case of LOC's recursion;
* a rollout of any policy on that model with its eq. 17 cost (:mod:`gcs.optimal_rollout`:
  :func:`simulate_policy`, :class:`OptimalAffinePolicy`, :func:`eq17_cost`).

The comparison (:func:`optimality_table`): each controller of :data:`gcs.control.CONTROLLERS`
is designed by :func:`gcs.control.make_controller` for a copy of the config whose horizon is
set to the one studied and whose thrust and angular-acceleration limits are raised to
:data:`UNCONSTRAINED` (the LQ optimum is unconstrained; the floor ``thrust >= 0`` of
:class:`gcs.control.Limits` cannot be lifted, so the steps where it acts are counted).  It
is flown on the same affine model (not the SITL: no drag, no ground contact, no sensor
noise; theta = phi = 0, lateral axes at rest) from rest at z = 0 with the mission reference
(its takeoff ramp and hold, held after the mission ends), and its eq. 17 cost is evaluated
under both input conventions (``compensated``: R weighs thrust - m g, what ``nlsoc``
minimises; ``literal``: the thrust, the printed law).  ``J_controller / J_optimal >= 1`` by
construction.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from gcs.config import Config
from gcs.control import CONTROLLERS, make_controller
from gcs.control.riccati import affine_lqr, affine_lqr_cost
from gcs.model import z_psi_affine_model
from gcs.optimal_problem import (
    COST_CONVENTIONS, UNCONSTRAINED, AltitudeProblem, altitude_problem, check_convention, reference_offsets,
    unconstrained_config,
)
from gcs.optimal_rollout import OptimalAffinePolicy, Rollout, eq17_cost, simulate_policy

__all__ = [
    "affine_lqr", "affine_lqr_cost", "z_psi_affine_model", "reference_offsets",
    "AltitudeProblem", "altitude_problem", "unconstrained_config", "OptimalAffinePolicy",
    "Rollout", "simulate_policy", "eq17_cost", "GapRow", "optimality_table", "format_table",
    "UNCONSTRAINED", "COST_CONVENTIONS",
]


@dataclass(frozen=True)
class GapRow:
    """One line of :func:`optimality_table` (costs are eq. 17 with the NLSOC z-psi weights).

    Attributes
    ----------
    experiment : str
    horizon_s : float
    convention : {"compensated", "literal"}
    controller : str
    J_controller, J_optimal : float
    ratio : float
        ``J_controller / J_optimal``.
    excess : float
        ``J_controller - J_optimal``.
    thrust_floor_steps : int
        Steps where the controller's thrust sat on the floor 0 N.
    min_z_m : float
        Lowest altitude of the controller's flight on the affine model.
    optimal_min_thrust_n : float
        Lowest thrust of the optimal (unconstrained) input sequence [N].
    optimal_min_z_m : float
        Lowest altitude of the optimal flight [m] (negative: the optimum dives through the
        ground, which the affine model lacks).
    """

    experiment: str
    horizon_s: float
    convention: str
    controller: str
    J_controller: float
    J_optimal: float
    ratio: float
    excess: float
    thrust_floor_steps: int
    min_z_m: float
    optimal_min_thrust_n: float
    optimal_min_z_m: float


def optimality_table(config: Config, horizons_s: Iterable[float] = (1, 5, 20, 60),
                     controllers: Sequence[str] = CONTROLLERS,
                     conventions: Sequence[str] = COST_CONVENTIONS) -> list[GapRow]:
    """``J_controller / J_optimal`` of the altitude subproblem per horizon, convention and controller.

    Parameters
    ----------
    config : Config
    horizons_s : iterable of float
        Horizons [s]; each controller is designed for that horizon (see
        :func:`unconstrained_config`) and flown over it.
    controllers : sequence of str
        Names for :func:`gcs.control.make_controller`.
    conventions : sequence of {"compensated", "literal"}

    Returns
    -------
    list of GapRow
        Ordered by horizon, convention, controller.
    """
    for conv in conventions:
        check_convention(conv)
    rows: list[GapRow] = []
    for h in horizons_s:
        cfg = unconstrained_config(config, h)
        problems = {conv: altitude_problem(config, h, conv) for conv in conventions}
        rollouts = {name: simulate_policy(problems[conventions[0]], make_controller(name, cfg)) for name in controllers}
        for conv in conventions:
            prob = problems[conv]
            K, kff, P, p, s = prob.solve()
            j_opt = affine_lqr_cost(P, p, s, prob.x0())
            opt = simulate_policy(prob, OptimalAffinePolicy(prob, K, kff))
            for name in controllers:
                ro = rollouts[name]
                jc = ro.cost[conv]
                rows.append(GapRow(prob.experiment, float(h), conv, name, jc, j_opt, jc / j_opt, jc - j_opt,
                                   ro.thrust_floor_steps, ro.min_z_m, float(opt.command[:, 0].min()),
                                   opt.min_z_m))
    return rows


def format_table(rows: Iterable[GapRow]) -> str:
    """The rows as a fixed-width text table (one block per experiment and convention)."""
    rows = list(rows)
    out: list[str] = []
    keys: list[tuple[str, str]] = []
    for r in rows:
        if (r.experiment, r.convention) not in keys:
            keys.append((r.experiment, r.convention))
    what = {"compensated": "u = thrust - m g", "literal": "u = thrust"}
    for exp, conv in keys:
        sel = [r for r in rows if r.experiment == exp and r.convention == conv]
        out.append(f"{exp}: eq. 17 with {what[conv]} ({conv})")
        out.append(f"{'T [s]':>6} {'controller':<14} {'J_controller':>14} {'J_optimal':>14} {'ratio':>10} "
                   f"{'excess':>12} {'floor':>5} {'min z [m]':>10} {'opt min u [N]':>13} {'opt min z [m]':>13}")
        for r in sel:
            out.append(f"{r.horizon_s:>6g} {r.controller:<14} {r.J_controller:>14.6g} {r.J_optimal:>14.6g} "
                       f"{r.ratio:>10.5g} {r.excess:>12.5g} {r.thrust_floor_steps:>5d} {r.min_z_m:>10.4g} "
                       f"{r.optimal_min_thrust_n:>13.4g} {r.optimal_min_z_m:>13.4g}")
        out.append("")
    return "\n".join(out).rstrip("\n")
