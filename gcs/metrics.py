"""The paper's performance indices, computed from a flight record.

Per flight (``K`` control steps, ``k = 0 .. K-1``; the record holds K + 1 states):

``J``
    The controller's own quadratic cost, eq. 5 (LOC: state [e_z, e_vz], input u1 of
    the exact linearisation) or eq. 17 (NLSOC: state [e_z, e_vz, e_yaw, e_yaw_rate],
    input [thrust deviation from hover (or thrust, for nlsoc-literal), tau_psi]),
    ``J = 1/2 sum_{k<M} (x'Qx + u'Ru) + 1/2 x(M)' H x(M)`` with M = min(N, K)
    (:func:`gcs.control.cost.flight_cost`; :class:`CostSpec` and :func:`controller_cost`
    live there too and are re-exported here).
    Not defined for PD (the paper prints "-"): the key is absent.
``J_u``
    ``sum |u(k)|`` of the thrust [N] (the issue's definition; includes the hover thrust).
``J_u_hover``
    ``sum |u(k) - m g|``, the thrust spent beyond hover (closer in size to the paper's figures).
``J_u_all``
    ``sum (|u| + |tau_phi| + |tau_theta| + |tau_psi|)`` over all four inputs.
``J_e``
    ``sum ||e(k)||`` with e = [reference position - position, reference velocity - velocity]
    over the experiment's ``error_axes``.
``J_e_setpoint``
    ``sum ||[z_setpoint - z, -vz]||``: against the final altitude set point (Table 1, erratum 11).
``steady_state_error_m``
    Mean of (reference z - z) over the last second of the last hold or circle phase,
    or over the last second of the flight when the flight ends before the hold does
    (``gcs sim --duration``); a flight cut during the takeoff ramp measures ramp lag.
``overshoot_m``
    ``max(0, max z - z_setpoint)`` before landing; ``J_e_setpoint`` and this take the set point
    relative to the take-off point, as the mission is flown.
``rms_error_m``
    RMS of the position error over ``error_axes``.

Figures are in SI units (the paper's tables appear to use centimetres for J_e).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from gcs.config import Config
from gcs.control.cost import CostSpec, controller_cost, flight_cost
from gcs.mission import Mission

__all__ = ["FlightRecord", "CostSpec", "controller_cost", "flight_metrics", "summarize", "METRICS", "AXIS_INDEX"]

#: Metric keys in table order.
METRICS = ("J", "J_u", "J_u_hover", "J_u_all", "J_e", "J_e_setpoint", "steady_state_error_m", "overshoot_m",
           "rms_error_m")

AXIS_INDEX = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True)
class FlightRecord:
    """A flight sampled at the control period.

    Attributes
    ----------
    ts_s : float
    state : ndarray, shape (K + 1, 12)
        State at each control step and after the last one (paper frame).
    ref : ndarray, shape (K + 1, 12)
    command : ndarray, shape (K, 4)
        Applied commands (thrust [N], angular accelerations [rad/s^2]).
    steps_to_go : ndarray of int, shape (K,)
        Horizon steps to go used at each step; 0 where the fallback (PD) flew.
    """

    ts_s: float
    state: np.ndarray
    ref: np.ndarray
    command: np.ndarray
    steps_to_go: np.ndarray

    @property
    def time_s(self) -> np.ndarray:
        return np.arange(self.state.shape[0]) * self.ts_s

    @property
    def duration_s(self) -> float:
        return self.command.shape[0] * self.ts_s


def _window(t: np.ndarray, lo: float, hi: float) -> np.ndarray:
    return (t >= lo - 1e-9) & (t < hi - 1e-9)


def _window_or_last(t: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """:func:`_window`, or the last sample before ``hi`` when no sample falls inside (a window
    shorter than the control period, in a flight of a step or two)."""
    mask = _window(t, lo, hi)
    if not mask.any():
        mask[max(0, int(np.searchsorted(t, hi - 1e-9)) - 1)] = True
    return mask


def flight_metrics(rec: FlightRecord, config: Config, mission: Mission, cost: CostSpec | None) -> dict[str, float]:
    """All metrics of one flight (see the module docstring).

    A flight of one or two steps gets every metric, computed on the steps there are
    (the steady-state error then comes from the last step before the window's end).

    Raises
    ------
    ValueError
        When the record holds no step.
    """
    e = config.experiment
    mass, g = config.vehicle.mass_kg, config.vehicle.gravity_m_s2
    k = rec.command.shape[0]
    if k == 0:
        raise ValueError("empty flight record")
    s, r, u = rec.state[:k], rec.ref[:k], rec.command
    t = rec.time_s[:k]
    axes = [AXIS_INDEX[a] for a in e.error_axes]
    pos_err = r[:, axes] - s[:, axes]
    vel_err = r[:, [a + 3 for a in axes]] - s[:, [a + 3 for a in axes]]
    err = np.hstack([pos_err, vel_err])
    # The mission is flown from the take-off point (a real autopilot's local origin need not be there,
    # PX4's altitude estimate on the ground is often tenths of a metre off): the set point moves with it.
    z_sp = mission.setpoint_z_m + (float(r[0, 2]) - mission.reference(0.0).z if len(r) else 0.0)
    out: dict[str, float] = {}
    if cost is not None:
        out["J"] = flight_cost(rec.state, rec.ref, rec.command, cost, mass, g)
    out["J_u"] = float(np.abs(u[:, 0]).sum())
    out["J_u_hover"] = float(np.abs(u[:, 0] - mass * g).sum())
    out["J_u_all"] = float(np.abs(u).sum())
    out["J_e"] = float(np.linalg.norm(err, axis=1).sum())
    out["J_e_setpoint"] = float(np.hypot(z_sp - s[:, 2], s[:, 5]).sum())
    lo, hi = mission.hold_window(1.0)
    if t[-1] + rec.ts_s < hi - 1e-9:
        # The flight ended before the hold did: the steady state is the end of the flight.
        lo, hi = t[-1] + rec.ts_s - 1.0, t[-1] + rec.ts_s
    mask = _window_or_last(t, lo, hi)
    out["steady_state_error_m"] = float(np.mean(r[mask, 2] - s[mask, 2]))
    f_lo, f_hi = mission.flight_window()
    fmask = _window(t, f_lo, f_hi)
    out["overshoot_m"] = float(max(0.0, s[fmask, 2].max() - z_sp)) if fmask.any() else 0.0
    out["rms_error_m"] = float(np.sqrt(np.mean(np.sum(pos_err ** 2, axis=1))))
    return out


def summarize(runs: Iterable[Mapping[str, float]]) -> dict[str, dict[str, float]]:
    """Mean and standard deviation (sample, ddof = 1; 0 for one run) of each metric across runs."""
    runs = list(runs)
    if not runs:
        raise ValueError("no runs to summarize")
    keys = [k for k in METRICS if all(k in r for r in runs)]
    keys += [k for k in runs[0] if k not in keys and all(k in r for r in runs)]
    out = {}
    for key in keys:
        vals = np.array([r[key] for r in runs], dtype=float)
        out[key] = {"mean": float(vals.mean()), "std": float(vals.std(ddof=1)) if len(vals) > 1 else 0.0}
    return out
