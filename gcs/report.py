"""Metric tables as text: the paper's Tables 1-5 layout (one row per metric, one column per controller).

Used by ``gcs sim``, ``gcs fly``'s end-of-flight table and ``gcs log compare``.
"""

from __future__ import annotations

from gcs.metrics import METRICS

__all__ = ["format_table", "METRIC_LABELS"]

METRIC_LABELS = {
    "J": "J (eq. 5 / eq. 17)",
    "J_u": "J_u = sum|u| [N]",
    "J_u_hover": "J_u_hover = sum|u - mg| [N]",
    "J_u_all": "J_u_all (u, tau_phi, tau_theta, tau_psi)",
    "J_e": "J_e = sum||e|| vs reference",
    "J_e_setpoint": "J_e vs final set point",
    "steady_state_error_m": "steady-state error [m]",
    "overshoot_m": "overshoot [m]",
    "rms_error_m": "RMS position error [m]",
}


def format_table(result: dict, title: str) -> str:
    """A metrics table: ``result["results"][controller][metric] = {"mean", "std"}`` as 'mean ± std' cells."""
    results = result["results"]
    names = list(results)
    keys = [k for k in METRICS if any(k in results[n] for n in names)]
    cells = [[METRIC_LABELS.get(k, k)] for k in keys]
    for row, key in zip(cells, keys):
        for n in names:
            m = results[n].get(key)
            row.append("-" if m is None else f"{m['mean']:.4g} ± {m['std']:.2g}")
    header = ["metric"] + names
    widths = [max(len(r[i]) for r in cells + [header]) for i in range(len(header))]

    def line(r: list[str]) -> str:
        return "  ".join(c.ljust(widths[0]) if i == 0 else c.rjust(widths[i]) for i, c in enumerate(r))

    out = [title, line(header), "  ".join("-" * w for w in widths)]
    out += [line(r) for r in cells]
    return "\n".join(out)
