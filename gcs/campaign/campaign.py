"""Run a campaign: plan, fly every job on an executor, write the tables, figures and report.

Output folder layout::

    campaign.json        the plan (every job's command line and disturbances), command, timing
    runs.json            every run's result (status, exit code, metrics, wall time)
    tables.md/.json      Tables 1-5 (mean ± sample std per controller, beside the paper's)
    trends.json          the paper's trends checked on its numbers and ours
    optimality.md/.json  the altitude optimality gap (indoor-4dof, outdoor-altitude)
    RESULTS.md           the report (gcs.campaign.report)
    runs/<experiment>/<controller>/runNN.{out,json,mcap}   output, summary, flight log
    figures/<experiment>/*.png

``tables.json``, ``trends.json`` and ``optimality.json`` hold no wall time: the same
seed gives the same files.
"""

from __future__ import annotations

import datetime as _dt
import json
import shlex
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Callable, Sequence

from gcs.campaign.errors import CampaignError
from gcs.campaign.executors import Executor
from gcs.campaign.figures import draw_figures
from gcs.campaign.optimality import DEFAULT_HORIZONS_S, format_optimality_markdown, optimality_rows
from gcs.campaign.plan import EXPERIMENTS, CampaignOptions, Plan, plan_campaign, resolve_experiments
from gcs.campaign.report import results_markdown
from gcs.campaign.runner import RunResult
from gcs.campaign.tables import aggregate, format_tables_markdown, paper_tables
from gcs.campaign.trends import trend_checks

__all__ = ["CampaignResult", "run_campaign", "execute", "write_outputs", "write_optimality", "utc_stamp",
           "copy_results", "command_line"]


def utc_stamp() -> str:
    """``20261201T081129Z``: the default output folder's name."""
    return _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%SZ")


@dataclass(frozen=True)
class CampaignResult:
    """What :func:`run_campaign` did.

    Attributes
    ----------
    out : Path
    plan : Plan
    results : tuple of RunResult
        In plan order.
    wall_s : float
        Wall time of the flights.
    vehicle_s : float
        Mission seconds flown (all runs).
    files : dict
        Name -> path of what was written.
    """

    out: Path
    plan: Plan
    results: tuple[RunResult, ...]
    wall_s: float
    vehicle_s: float
    files: dict

    @property
    def failed(self) -> list[RunResult]:
        return [r for r in self.results if not r.ok]

    @property
    def throughput(self) -> float:
        """Simulated vehicle-seconds per wall second."""
        return self.vehicle_s / self.wall_s if self.wall_s > 0 else 0.0


def execute(jobs: Sequence, executor: Executor,
            progress: Callable[[RunResult], None] | None = None) -> list[RunResult]:
    """Submit ``jobs`` to ``executor`` and collect their results (in plan order)."""
    for job in jobs:
        executor.submit(job)
    got: dict[str, RunResult] = {}
    for r in executor.as_completed():
        got[r.key] = r
        if progress is not None:
            progress(r)
    missing = [j.key for j in jobs if j.key not in got]
    if missing:
        raise CampaignError("campaign", "", f"the executor returned no result for {', '.join(missing[:3])}")
    return [got[j.key] for j in jobs]


def _write(path: Path, text: str) -> str:
    try:
        path.write_text(text)
    except OSError as exc:
        raise CampaignError(str(path), "", f"cannot write: {exc.strerror or exc}") from None
    return str(path)


def _json(obj) -> str:
    return json.dumps(obj, indent=1, sort_keys=False, allow_nan=True) + "\n"


def write_optimality(out: Path, experiments: Sequence[str], horizons_s: Sequence[float],
                     controllers: Sequence[str]) -> tuple[list[dict], dict]:
    """``optimality.json`` and ``optimality.md`` for the experiments that have one; returns (rows, files)."""

    configs = [EXPERIMENTS[e].config for e in experiments if EXPERIMENTS[e].optimality]
    if not configs:
        return [], {}
    rows = optimality_rows(configs, horizons_s, controllers)
    files = {"optimality.json": _write(out / "optimality.json", _json({"horizons_s": list(horizons_s), "rows": rows})),
             "optimality.md": _write(out / "optimality.md", "# Optimality gap of the altitude subproblem\n\n"
                                     + format_optimality_markdown(rows))}
    return rows, files


def write_outputs(out: Path, plan: Plan, results: Sequence[RunResult], campaign_doc: dict, *,
                  figures: bool = True, horizons_s: Sequence[float] | None = None, workers: int = 1) -> dict:
    """Tables, trends, optimality, figures and RESULTS.md from the results; returns name -> path."""

    o = plan.options
    exps = [e.name for e in plan.experiments]
    agg = aggregate(results, exps, o.controllers, o.runs)
    tables = paper_tables(agg, o.controllers)
    checks = trend_checks(agg, exps)
    files = {
        "runs.json": _write(out / "runs.json", _json([r.to_json() for r in results])),
        "tables.json": _write(out / "tables.json", _json({"seed": o.seed, "runs": o.runs,
                                                          "durations_s": plan.durations_s,
                                                          "aggregate": agg, "tables": tables})),
        "tables.md": _write(out / "tables.md", "# Tables 1–5 (gcs campaign)\n\n" +
                            format_tables_markdown(tables, o.controllers, agg)),
        "trends.json": _write(out / "trends.json", _json(checks)),
    }
    requested = [e.name for e in resolve_experiments(o.experiments)]
    opt_rows, opt_files = write_optimality(out, requested, horizons_s or DEFAULT_HORIZONS_S, o.controllers)
    files.update(opt_files)
    fig = {"files": [], "skipped": "not asked for (--no-figures)", "problems": []}
    if figures:

        fig = draw_figures(results, out, workers=workers)
    files["figures"] = fig["files"]
    files["RESULTS.md"] = _write(out / "RESULTS.md",
                                 results_markdown(campaign_doc, tables, agg, checks, opt_rows, fig, base=out,
                                                  results=results))
    return files


def run_campaign(options: CampaignOptions, executor_factory: Callable[[], Executor], *,
                 command: str = "", progress: Callable[[RunResult], None] | None = None,
                 on_plan: Callable[[Plan], None] | None = None, figures: bool = True,
                 horizons_s: Sequence[float] | None = None, executor_name: str = "local",
                 workers: int = 1) -> CampaignResult:
    """Plan, fly and write a whole campaign into ``options.out``.

    Parameters
    ----------
    options : CampaignOptions
    executor_factory : callable
        Makes the :class:`Executor` (called after planning, so a bad option fails fast).
    command : str
        The command line, for the report.
    progress : callable (RunResult) or None
        Called as each run completes.
    on_plan : callable (Plan) or None
        Called once the plan is made (e.g. to size a progress bar).
    figures : bool
    horizons_s : sequence of float or None
        Optimality horizons.
    executor_name : str
    workers : int
        For the report.

    Returns
    -------
    CampaignResult
    """
    plan = plan_campaign(options)
    out = Path(options.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CampaignError(str(out), "", f"cannot create the output folder: {exc.strerror or exc}") from None
    if on_plan is not None:
        on_plan(plan)
    doc = {"command": command or "gcs campaign", "started_utc": _dt.datetime.now(_dt.UTC).isoformat(),
           "plan": plan.to_json()}
    _write(out / "campaign.json", _json(doc))
    t0 = time.monotonic()
    with executor_factory() as ex:
        results = execute(plan.jobs, ex, progress)
    wall = time.monotonic() - t0
    vehicle = sum(r.flown_s for r in results)
    doc["timing"] = {"runs": len(results), "wall_s": wall, "vehicle_s": vehicle,
                     "throughput": vehicle / wall if wall > 0 else 0.0, "executor": executor_name, "workers": workers,
                     "failed": sum(1 for r in results if not r.ok)}
    _write(out / "campaign.json", _json(doc))
    t1 = time.monotonic()
    files = write_outputs(out, plan, results, doc, figures=figures, horizons_s=horizons_s,
                          workers=workers if executor_name == "local" else 1)
    doc["timing"]["outputs_s"] = time.monotonic() - t1  # tables, optimality, figures, report
    files["campaign.json"] = _write(out / "campaign.json", _json(doc))
    return CampaignResult(out, plan, tuple(results), wall, vehicle, files)


def copy_results(src: Path, dest: str | Path) -> str:
    """Copy RESULTS.md to ``dest`` (e.g. ``docs/RESULTS.md``)."""
    d = Path(dest)
    try:
        d.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, d)
    except OSError as exc:
        raise CampaignError(str(d), "", f"cannot write: {exc.strerror or exc}") from None
    return str(d)


def command_line(argv: Sequence[str]) -> str:
    """``gcs campaign ...`` as a shell would read it."""
    return "gcs " + " ".join(shlex.quote(a) for a in argv)
