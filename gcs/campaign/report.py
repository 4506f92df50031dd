"""``RESULTS.md``: the campaign's report (the reproduced tables beside the paper's, the
paper's trends checked on both, the optimality gap, failed runs and figures).

Everything but :data:`EXPLANATION` is computed from the campaign's numbers; the
explanation is the fixed reasoning of the README ("The paper's trends in this
simulation").  :func:`results_markdown` is pure: it returns the text.
"""

from __future__ import annotations

import os
from pathlib import Path
from collections.abc import Sequence

from gcs.campaign.optimality import format_optimality_markdown
from gcs.campaign.tables import format_tables_markdown
from gcs.campaign.trends import format_trends_markdown

__all__ = ["results_markdown", "reproducibility_markdown", "EXPLANATION"]

EXPLANATION = """\
- **PD and LOC behave alike.** The eq. 26 PD gains are almost LOC's converged gains (z: 42/35
  against 42.5/36.1), so their errors and energies are close.
- **Energy beyond hover is mostly the response to noise and wind.** `J_u` is dominated by the
  hover thrust and is nearly the same for every controller; `J_u_hover` (thrust beyond hover)
  is what differs. NLSOC's lateral weights (velocity weight e42 = 8000 against position weight
  e41 = 129, eq. 25) amplify the position noise into attitude activity.
- **NLSOC drifts in a steady wind.** The same weak lateral position weight lets NLSOC drift
  several metres downwind: its outdoor J_e is dominated by that drift whenever the campaign's
  wind blows (`--wind-scale 0` flies calm air, as the paper's simulations did).
- **The literal printed NLSOC law** (`nlsoc-literal`) does not compensate gravity: it sags about
  0.12 m outdoors and cannot lift off the indoor rig (erratum 8).
- **Absolute values are not comparable.** The paper's J_e appears to be in centimetres and its
  J_u to exclude most of the hover thrust; the campaign flies the full flight stack (6-DOF
  SITL, MAVLink, 400 Hz autopilot loops) rather than the paper's reduced model, and outdoor
  altitude is cut at 120 s instead of 10 min.
"""


def _rel(path: str, base: Path) -> str:
    try:
        return os.path.relpath(path, base)
    except ValueError:
        return path


def reproducibility_markdown(results: Sequence) -> str:
    """Whether the runs can have depended on wall time: lockstep timeouts, and arming times
    that differ between the controllers of one run (preflight is the same for all of them)."""
    ok = [r for r in results if r.ok]
    if not ok:
        return "No completed run."
    lines = []
    late = [r for r in ok if r.lockstep_timeouts]
    if late:
        lines.append(f"{len(late)} of {len(ok)} completed runs went on without the vehicle's step at least once "
                     "(lockstep telemetry timeouts: " +
                     ", ".join(f"{r.key} {r.lockstep_timeouts}" for r in late[:12])
                     + (", ..." if len(late) > 12 else "")
                     + "): their numbers depend on how busy the machine was, not only on the seed.")
    groups: dict = {}
    for r in ok:
        if r.armed_s is not None:
            groups.setdefault((r.experiment, r.run), set()).add(round(r.armed_s, 6))
    odd = sorted(f"{e} run {i}" for (e, i), times in groups.items() if len(times) > 1)
    if odd:
        lines.append(f"Arming happened at different vehicle times for the controllers of {len(odd)} run(s) "
                     f"({', '.join(odd[:8])}{', ...' if len(odd) > 8 else ''}): preflight depended on wall time.")
    if not lines:
        lines.append(f"Every completed run ({len(ok)}) stepped in lockstep without a timeout, and the controllers of "
                     "each run armed at the same vehicle time: the numbers are a function of the seed.")
    return " ".join(lines)


def results_markdown(campaign: dict, tables: list[dict], agg: dict, checks: list[dict],
                     optimality: Sequence[dict] | None, figures: dict | None, *, base: str | Path = ".",
                     results: Sequence | None = None) -> str:
    """The text of RESULTS.md.

    Parameters
    ----------
    campaign : dict
        ``campaign.json`` (plan, command line, timing).
    tables : list of dict
        :func:`gcs.campaign.tables.paper_tables`.
    agg : dict
        :func:`gcs.campaign.tables.aggregate`.
    checks : list of dict
        :func:`gcs.campaign.trends.trend_checks`.
    optimality : sequence of dict or None
        :func:`gcs.campaign.optimality.optimality_rows`.
    figures : dict or None
        :func:`gcs.campaign.figures.draw_figures`.
    base : path
        Folder that file paths are shown relative to (the campaign's output folder).
    results : sequence of RunResult or None
        For the reproducibility section.
    """
    out = _header(campaign)
    ctls = campaign["plan"]["controllers"]
    out += ["## Tables 1–5", "", format_tables_markdown(tables, ctls, agg)]
    out += ["## The paper's trends", "",
            "Each row is computed from the numbers: on the paper's simulation column and on this campaign's "
            "means (standard deviations for the dispersion rows). `n/a`: a value is missing.", "",
            format_trends_markdown(checks),
            f"Agreement: {sum(1 for c in checks if c['agree'])} of "
            f"{sum(1 for c in checks if c['agree'] is not None)} comparable checks.", "",
            "### Why they differ", "", EXPLANATION]
    if optimality:
        out += ["## Optimality gap of the altitude subproblem", "",
                "J_controller / J_optimal of eq. 17 on the affine z–ψ model (`gcs/optimal_affine.py`): the "
                "controllers flown from rest at z = 0 with the mission reference, unconstrained, against the exact "
                "affine-LQ optimum, per horizon and for both NLSOC input conventions. 1 is optimal.", "",
                format_optimality_markdown(optimality)]
    out += _failed(agg)
    out += ["## Reproducibility", "", reproducibility_markdown(results or ()), ""]
    out += _figures(figures, Path(base))
    return "\n".join(out).rstrip() + "\n"


def _header(campaign: dict) -> list[str]:
    """The command, what was flown and the timing."""
    plan = campaign["plan"]
    ctls = plan["controllers"]
    dm = plan["disturbance_model"]
    out = ["# Reproduced results", "",
           "Generated by `gcs campaign`; do not edit by hand. Command:", "",
           f"```sh\n{campaign['command']}\n```", "",
           f"Every controller ({', '.join(ctls)}) flew {plan['runs']} run(s) of each experiment through the "
           "full flight stack (`gcs fly --sitl lockstep`: the built-in SITL, MAVLink, the 100 Hz ground-station "
           f"loop), campaign seed {plan['seed']}. Mission lengths: "
           + ", ".join(f"{k} {v:g} s" for k, v in plan["durations_s"].items()) + ". "
           f"Run i of every controller meets the same disturbances, drawn from (seed, experiment, i): SITL seed "
           f"(sensor noise, gusts), wind {dm['wind_scale']:g} x the config's `[sim.wind]` speed (x U(0.5, 1.5), "
           f"random direction) and gusts, initial roll/pitch within ±{dm['tilt_deg']:g}° and yaw within "
           f"±{dm['yaw_deg']:g}° (outdoor; the indoor rig varies its seed only).", ""]
    if plan["skipped"]:
        out += ["Not flown: " + "; ".join(f"`{k}` ({v})" for k, v in plan["skipped"].items()) + ".", ""]
    for note in plan["notes"]:
        out += [f"Note: {note}.", ""]
    t = campaign.get("timing") or {}
    if t:
        out += [f"{t['runs']} flights in {t['wall_s']:.0f} s wall time on {t['workers']} worker(s) "
                f"({t['executor']}): {t['vehicle_s']:.0f} simulated mission seconds, "
                f"{t['throughput']:.1f} vehicle-seconds per wall second.", ""]
    return out


def _failed(agg: dict) -> list[str]:
    out = ["## Failed runs", ""]
    if not agg["failed"]:
        return out + ["None: every run completed.", ""]
    out += ["Listed here and left out of every mean.", "",
            "| run | status | exit code | reason | detail | output |", "|---|---|---:|---|---|---|"]
    for f in agg["failed"]:
        detail = (f["detail"] or "").replace("|", "\\|")
        out.append(f"| {f['key']} | {f['status']} | {'-' if f['exit_code'] is None else f['exit_code']} | "
                   f"{f['exit_reason'] or '-'} | {detail} | `runs/{f['key']}.out` |")
    return out + [""]


def _figures(figures: dict | None, base: Path) -> list[str]:
    out = ["## Figures", ""]
    if figures and figures.get("files"):
        out += [f"In the campaign's output folder ({len(figures['files'])} PNG files):", ""]
        out += [f"- `{_rel(f, base)}`" for f in figures["files"]]
        return out + [""]
    return out + [f"None ({(figures or {}).get('skipped') or 'not drawn'}).", ""]
