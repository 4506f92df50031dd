"""LOC: finite-horizon discrete LQR on the exactly linearised model (paper section 2).

Design (pure, matrices in, arrays out): :func:`design_loc` runs the backward Riccati recursion
(eqs. 6-7, erratum 1: ``A - BF``; :func:`gcs.control.riccati.finite_horizon_lqr`) on the
models of :mod:`gcs.model` (eq. 4 for z and yaw, eq. 8 for y-phi and its x-theta twin);
:func:`design_loc_from_config` reads the matrices from a config.  At time k the law applies
``u = -F(N - k) x`` (eq. 6).  Policy: z through the exact linearisation
``u = m (u1 + g) / (cos(theta) cos(phi))`` (eq. 3), yaw, and the small-angle y-phi and
x-theta subsystems, all in error coordinates (state - reference, attitude references 0).
A disturbance acceleration ``d`` enters the inversions: ``u = m (u1 + g - d_z) / (cos(theta) cos(phi))``
and the attitude references become the tilt that balances it (:func:`gcs.model.disturbance_tilt`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from gcs.config import Config
from gcs.control.base import (NO_DISTURBANCE, Controller, Disturbance, FiniteHorizonController, Limits, StagedLaw,
                              wrap_angle)
from gcs.control.riccati import finite_horizon_lqr
from gcs.errors import DesignError
from gcs.model import ModelParams, disturbance_tilt, linear_psi, linear_x_theta, linear_y_phi, linear_z, tilt_cos
from quadrotor.state import Command, State

__all__ = ["finite_horizon_lqr", "LOC_SUBSYSTEMS", "loc_models", "LocDesign", "design_loc", "design_loc_from_config",
           "LocLaw", "make_loc"]

#: The LOC subsystems, each with its own gain table.
LOC_SUBSYSTEMS = ("z", "psi", "y_phi", "x_theta")


def loc_models(ts_s: float, gravity_m_s2: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``{subsystem: (A, B)}``: eq. 4 (z, and yaw), eq. 8 (y-phi) and its x-theta twin."""
    return {"z": linear_z(ts_s), "psi": linear_psi(ts_s), "y_phi": linear_y_phi(ts_s, gravity_m_s2),
            "x_theta": linear_x_theta(ts_s, gravity_m_s2)}


@dataclass(frozen=True)
class LocDesign:
    """Gain tables of the four LOC subsystems, each shape (N, 1, n) (n = 2 for z and psi, 4 for
    y-phi and x-theta); ``F_<name>[j - 1]`` is the gain with j steps to go."""

    ts_s: float
    horizon_steps: int
    F_z: np.ndarray
    F_psi: np.ndarray
    F_y_phi: np.ndarray
    F_x_theta: np.ndarray


def design_loc(ts_s: float, gravity_m_s2: float, weights: Mapping[str, tuple], horizon_steps: int) -> LocDesign:
    """Riccati gain tables (eqs. 6-7) for z (exact linearisation), psi, y-phi and x-theta.

    Parameters
    ----------
    ts_s : float
        Sampling period T [s].
    gravity_m_s2 : float
        g in eq. 8's A(2,3) = g T [m/s^2].
    weights : mapping
        ``{"z": (Q, R, H), "psi": ..., "y_phi": ..., "x_theta": ...}``: Q, H shape (n, n), R (1, 1).
    horizon_steps : int
        N >= 1.

    Returns
    -------
    LocDesign

    Raises
    ------
    gcs.errors.DesignError
        Bad weights or horizon (message prefixed ``loc.<subsystem>``).
    """
    tables = {}
    for name, (a, b) in loc_models(ts_s, gravity_m_s2).items():
        try:
            tables[name], _ = finite_horizon_lqr(a, b, *weights[name], horizon_steps)
        except DesignError as exc:
            raise DesignError(f"loc.{name}: {exc}") from None
    return LocDesign(ts_s, horizon_steps, tables["z"], tables["psi"], tables["y_phi"], tables["x_theta"])


def design_loc_from_config(config: Config) -> LocDesign:
    """:func:`design_loc` with the config's period, gravity, LOC matrices (in its matrix mode) and horizon."""
    e = config.experiment
    weights = {name: config.loc[name].resolved(e.matrices) for name in LOC_SUBSYSTEMS}
    try:
        return design_loc(e.ts_s, config.vehicle.gravity_m_s2, weights, e.horizon_steps)
    except DesignError as exc:
        raise DesignError(f"{config.source}: {exc}") from None




def _settled_length(table: np.ndarray) -> int:
    """Number of leading rows after which every row equals the last one."""
    differs = np.any(table[:, 0, :] != table[-1, 0, :], axis=1)
    idx = np.flatnonzero(differs)
    return int(idx[-1]) + 2 if idx.size else 1


class LocLaw(StagedLaw):
    """The LOC policy with j steps to go."""

    def __init__(self, design: LocDesign, model: ModelParams, limits: Limits) -> None:
        self.design = design
        self.model = model
        self.limits = limits
        # Plain lists of rows (a lookup and a 2- or 4-term dot product per subsystem), cut
        # where the recursion reached its fixed point: rows past it are all equal.
        tables = (design.F_z, design.F_psi, design.F_y_phi, design.F_x_theta)
        settled = max(_settled_length(t) for t in tables)
        self._settled = settled
        self._fz, self._fpsi, self._fy, self._fx = (t[:settled, 0, :].tolist() for t in tables)

    def step_j(self, j: int, state: State, ref: State, disturbance_m_s2: Disturbance = NO_DISTURBANCE) -> Command:
        i = (j if j < self._settled else self._settled) - 1
        dx, dy, dz = disturbance_m_s2
        m, g = self.model.mass_kg, self.model.gravity_m_s2
        fz = self._fz[i]
        u1 = -(fz[0] * (state[2] - ref[2]) + fz[1] * (state[5] - ref[5]))
        thrust = m * (u1 + (g - dz)) / tilt_cos(state[6], state[7])
        phi_d, th_d = disturbance_tilt(thrust, m, g, dx, dy)
        phi, th = state[6] - phi_d, state[7] - th_d
        fp = self._fpsi[i]
        t_yaw = -(fp[0] * wrap_angle(state[8] - ref[8]) + fp[1] * (state[11] - ref[11]))
        fy = self._fy[i]
        t_roll = -(fy[0] * (state[1] - ref[1]) + fy[1] * (state[4] - ref[4]) + fy[2] * phi + fy[3] * state[9])
        fx = self._fx[i]
        t_pitch = -(fx[0] * (state[0] - ref[0]) + fx[1] * (state[3] - ref[3]) + fx[2] * th + fx[3] * state[10])
        return self.limits.saturate(thrust, t_roll, t_pitch, t_yaw)


def make_loc(config: Config, model: ModelParams, limits: Limits,
             fallback: Controller | None) -> FiniteHorizonController:
    """Design LOC for ``config`` and wrap it in its horizon schedule."""
    design = design_loc_from_config(config)
    e = config.experiment
    return FiniteHorizonController("loc", LocLaw(design, model, limits), e.horizon_steps, e.after_horizon, fallback)
