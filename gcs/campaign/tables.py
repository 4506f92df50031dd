"""Aggregation of the runs and the reproduced Tables 1-5 (Markdown and JSON).

:func:`aggregate` turns the runs' results into mean and sample standard deviation per
experiment, controller and metric (:func:`gcs.metrics.summarize`, the same as
``gcs sim``), over the runs that completed (``status == "ok"``), taken in run order so
that the numbers do not depend on which run finished first.  Failed runs are listed,
never averaged.

:func:`paper_tables` lays the aggregate out as the paper's tables, our columns beside
the paper's simulation columns (:mod:`gcs.campaign.paper`):

* Tables 1, 2, 4: every metric of :data:`gcs.metrics.METRICS`, mean ± std per controller;
* Tables 3, 5: the standard deviation over the runs of the error metrics (J_e, RMS and
  steady-state error): the paper's "error standard deviation".

Both are plain data (dicts and lists) with nothing that depends on wall time, so the
same seed gives the same ``tables.json``, byte for byte.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

from gcs.campaign.paper import PAPER_CONTROLLERS, PAPER_TABLES
from gcs.campaign.runner import RunResult
from gcs.metrics import METRICS, summarize

__all__ = ["aggregate", "paper_tables", "format_tables_markdown", "METRIC_UNITS", "METRIC_LABELS", "ERROR_METRICS",
           "fmt"]

#: Units of our metrics (SI).
METRIC_UNITS = {
    "J": "-", "J_u": "N", "J_u_hover": "N", "J_u_all": "N + rad/s^2", "J_e": "m, m/s", "J_e_setpoint": "m, m/s",
    "steady_state_error_m": "m", "overshoot_m": "m", "rms_error_m": "m",
}

METRIC_LABELS = {
    "J": "J (eq. 5 LOC / eq. 17 NLSOC)",
    "J_u": "J_u = Σ|u|",
    "J_u_hover": "J_u_hover = Σ|u − mg|",
    "J_u_all": "J_u_all = Σ(|u| + |τφ| + |τθ| + |τψ|)",
    "J_e": "J_e = Σ‖e‖ vs reference",
    "J_e_setpoint": "J_e vs final set point",
    "steady_state_error_m": "steady-state error",
    "overshoot_m": "overshoot",
    "rms_error_m": "RMS position error",
}

#: The metrics of Tables 3 and 5 (their standard deviation over the runs).
ERROR_METRICS = ("J_e", "J_e_setpoint", "rms_error_m", "steady_state_error_m")


def aggregate(results: Iterable[RunResult], experiments: Sequence[str], controllers: Sequence[str],
              runs: int) -> dict:
    """Mean and sample standard deviation per experiment, controller and metric.

    Parameters
    ----------
    results : iterable of RunResult
        In any order.
    experiments, controllers : sequence of str
        The campaign's, in table order.
    runs : int
        Runs planned per controller.

    Returns
    -------
    dict
        ``{"experiments": {exp: {"runs_planned", "controllers": {ctl: {"ok", "failed",
        "metrics": {key: {"mean", "std", "n"}}}}}}, "failed": [{"key", "status",
        "exit_code", "exit_reason", "detail"}]}`` (failed sorted by key; their output is
        ``runs/<key>.out`` in the campaign folder).
    """
    results = sorted(results, key=lambda r: (r.experiment, r.controller, r.run))
    out: dict = {"experiments": {}, "failed": []}
    for exp in experiments:
        block = {"runs_planned": runs, "controllers": {}}
        for ctl in controllers:
            mine = [r for r in results if r.experiment == exp and r.controller == ctl]
            ok = [r for r in mine if r.ok and r.metrics]
            stats = {}
            if ok:
                for key, s in summarize([r.metrics for r in ok]).items():
                    stats[key] = {"mean": s["mean"], "std": s["std"], "n": len(ok)}
            block["controllers"][ctl] = {"ok": len(ok), "failed": len(mine) - len(ok), "metrics": stats}
        out["experiments"][exp] = block
    for r in results:
        if not (r.ok and r.metrics):
            out["failed"].append({"key": r.key, "status": r.status, "exit_code": r.exit_code,
                                  "exit_reason": r.exit_reason, "detail": r.detail})
    return out


def _cell(stats: dict | None, what: str = "mean") -> dict | None:
    if not stats:
        return None
    return {"mean": stats["mean"], "std": stats["std"], "n": stats["n"]} if what == "mean" else \
        {"value": stats["std"], "n": stats["n"]}


def paper_tables(agg: dict, controllers: Sequence[str]) -> list[dict]:
    """The reproduced Tables 1-5 of the experiments in ``agg``.

    Returns
    -------
    list of dict
        Per table: ``{"number", "title", "experiment", "kind", "note", "rows": [{"metric",
        "label", "unit", "ours": {ctl: {"mean", "std", "n"} | {"value", "n"} | None},
        "paper_metric", "paper_unit", "paper_sim": {ctl: value | None} | None}]}``.
    """
    tables = []
    for number, t in PAPER_TABLES.items():
        block = agg["experiments"].get(t.experiment)
        if block is None:
            continue
        ctls = block["controllers"]
        printed = {row.metric: row for row in t.rows}
        keys = METRICS if t.kind == "mean" else ERROR_METRICS
        rows = []
        for key in keys:
            if not any(key in ctls[c]["metrics"] for c in controllers if c in ctls) and key not in printed:
                continue
            prow = printed.get(key)
            rows.append({
                "metric": key, "label": METRIC_LABELS.get(key, key) + (" (std over runs)" if t.kind == "std" else ""),
                "unit": METRIC_UNITS.get(key, ""),
                "ours": {c: _cell(ctls[c]["metrics"].get(key), t.kind) if c in ctls else None for c in controllers},
                "paper_metric": prow.printed if prow else None, "paper_unit": prow.unit if prow else None,
                "paper_sim": dict(prow.sim) if prow else None,
            })
        tables.append({"number": number, "title": t.title, "experiment": t.experiment, "kind": t.kind,
                       "note": t.note, "rows": rows})
    return tables


def fmt(v: float | None, digits: int = 4) -> str:
    """A number for a table: 4 significant digits, '-' for None or NaN."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    return f"{v:.{digits}g}"


def _ours(cell: dict | None) -> str:
    if cell is None:
        return "-"
    if "value" in cell:
        return fmt(cell["value"])
    return f"{fmt(cell['mean'])} ± {fmt(cell['std'], 2)}"


def format_tables_markdown(tables: list[dict], controllers: Sequence[str], agg: dict | None = None) -> str:
    """The tables as Markdown: our controllers' columns, then the paper's simulation columns."""
    out = []
    for t in tables:
        out.append(f"### Table {t['number']}: {t['title']}")
        out.append("")
        n = None
        if agg is not None:
            block = agg["experiments"][t["experiment"]]["controllers"]
            n = ", ".join(f"{c} {block[c]['ok']}" for c in controllers if c in block)
        what = "mean ± sample std over the completed runs" if t["kind"] == "mean" else \
            "sample standard deviation over the completed runs"
        out.append(f"`{t['experiment']}`, {what}" + (f" (runs completed: {n})" if n else "") +
                   "; SI units. Paper columns as printed (its J_e appears to be in cm).")
        if t["note"]:
            out.append(f"Paper: {t['note']}.")
        out.append("")
        paper_cols = [f"paper {c.upper()} sim" for c in PAPER_CONTROLLERS]
        header = ["metric", "unit"] + list(controllers) + (paper_cols if t["kind"] == "mean" else [])
        out.append("| " + " | ".join(header) + " |")
        out.append("|" + "|".join(["---"] * 2 + ["---:"] * (len(header) - 2)) + "|")
        for row in t["rows"]:
            label = row["label"] + (f" (paper: {row['paper_metric']}, {row['paper_unit']})"
                                    if row["paper_metric"] else "")
            cells = [label, row["unit"]] + [_ours(row["ours"].get(c)) for c in controllers]
            if t["kind"] == "mean":
                ps = row["paper_sim"]
                cells += [fmt(ps.get(c)) if ps else "" for c in PAPER_CONTROLLERS]
            out.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
        out.append("")
    return "\n".join(out).rstrip() + "\n"
