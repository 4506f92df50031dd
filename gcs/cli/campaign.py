"""``gcs campaign``: the paper's experiments through the full flight stack, one command.

::

    gcs campaign --experiment all --runs 10                      # Tables 1-5, figures, RESULTS.md
    gcs campaign --experiment outdoor-circle --runs 10 --workers 2 --out campaigns/circle
    gcs campaign --experiment all --runs 10 --results docs/RESULTS.md
    gcs campaign --experiment all --runs 2 --duration 15         # a quick look: every mission cut at 15 s
    gcs campaign --experiment all --runs 10 --executor dask --scheduler tcp://10.0.0.5:8786
    gcs campaign --optimality-only --experiment all              # the altitude optimality gap only

:func:`add_campaign_parser` adds the subcommand to ``gcs``; :func:`cmd_campaign` runs it.
Exit codes: 0 every run completed, 1 some runs failed (they are listed in the report and
left out of the means), 2 bad options, 130 interrupted.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from gcs.campaign.campaign import command_line, copy_results, run_campaign, utc_stamp, write_optimality
from gcs.campaign.errors import CampaignError
from gcs.campaign.executors import _distributed, make_executor
from gcs.campaign.plan import (
    EXPERIMENT_CHOICES,
    CampaignOptions,
    DisturbanceModel,
    parse_durations,
    resolve_experiments,
)
from gcs.cli.fly import fly_overrides
from gcs.control import CONTROLLERS

__all__ = ["add_campaign_parser", "cmd_campaign"]


def _float(minimum_exclusive: float | None = None, minimum: float | None = None):
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if v != v or v in (float("inf"), float("-inf")):
            raise argparse.ArgumentTypeError(f"must be finite, got {text}")
        if minimum_exclusive is not None and not v > minimum_exclusive:
            raise argparse.ArgumentTypeError(f"must be > {minimum_exclusive:g}, got {text}")
        if minimum is not None and v < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum:g}, got {text}")
        return v
    return parse


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None


def add_campaign_parser(sub: Any) -> None:
    """Add ``gcs campaign`` to the ``gcs`` subparsers ``sub``."""
    c = sub.add_parser(
        "campaign", help="fly the paper's experiments through the full flight stack; Tables 1-5, figures, RESULTS.md",
        description="Fly every controller --runs times per experiment with `gcs fly --sitl lockstep` (the built-in "
                    "SITL, MAVLink, the 100 Hz loop), in parallel, with seeded disturbances that every controller "
                    "meets alike; write Tables 1-5 (Markdown and JSON), the flight logs, figures, the optimality gap "
                    "and RESULTS.md into --out. Exit 0 when every run completed, 1 when some failed (listed, left "
                    "out of the means), 2 for bad options.")
    c.add_argument("--experiment", default="all", metavar="|".join(EXPERIMENT_CHOICES),
                   help="experiment(s), comma-separated, or all (default all)")
    c.add_argument("--runs", type=_int, default=10, help="runs per controller and experiment (default 10)")
    c.add_argument("--controllers", default=",".join(CONTROLLERS),
                   help=f"comma-separated controllers (default {','.join(CONTROLLERS)})")
    c.add_argument("--workers", type=_int, default=None, help="parallel flights (default: the CPU count)")
    c.add_argument("--out", metavar="DIR", help="output folder (default campaigns/<UTC time>/)")
    c.add_argument("--seed", type=_int, default=1,
                   help="campaign seed: every run's disturbances derive from it (default 1)")
    c.add_argument("--duration", action="append", default=[], metavar="[EXPERIMENT=]SECONDS",
                   help="cut the mission at this time, then land (gcs fly --duration); for every experiment, or one "
                        "with EXPERIMENT=SECONDS; repeatable (default: outdoor-altitude 120 s, the others whole)")
    c.add_argument("--duration-scale", type=_float(minimum_exclusive=0.0), default=1.0, metavar="F",
                   help="multiply every mission length by F (<= 1; default 1)")
    c.add_argument("--wind-scale", type=_float(minimum=0.0), default=1.0, metavar="F",
                   help="multiply the configs' [sim.wind] speed and gusts (0 = calm air, as the paper's simulations; "
                        "default 1)")
    c.add_argument("--tilt", type=_float(minimum=0.0), default=2.0, metavar="DEG",
                   help="initial roll and pitch drawn within +-DEG (default 2)")
    c.add_argument("--yaw", type=_float(minimum=0.0), default=10.0, metavar="DEG",
                   help="initial yaw drawn within +-DEG (default 10)")
    c.add_argument("--timeout", type=_float(minimum_exclusive=0.0), metavar="S",
                   help="wall seconds per run before it is stopped as hung (default 120 + 1.5 x the mission)")
    c.add_argument("--fly-arg", action="append", default=[], metavar="ARG",
                   help="extra option for every gcs fly, repeatable (e.g. --fly-arg=--output=rates)")
    c.add_argument("--executor", choices=("local", "dask"), default="local",
                   help="local worker processes, or a Dask cluster (pip install 'quadrotor-gcs[dask]')")
    c.add_argument("--scheduler", metavar="ADDRESS",
                   help="Dask scheduler address (default with --executor dask: a LocalCluster of --workers processes)")
    c.add_argument("--results", metavar="PATH", help="also copy RESULTS.md here (e.g. docs/RESULTS.md)")
    c.add_argument("--no-figures", action="store_true", help="draw no figures")
    c.add_argument("--optimality-only", action="store_true",
                   help="fly nothing: write (and print) the altitude optimality gap of the experiments")
    c.add_argument("--horizons", default="1,5,20,60", metavar="S,S,...",
                   help="optimality horizons [s] (default 1,5,20,60)")
    c.add_argument("--quiet", "-q", action="store_true", help="no progress bar; only the final lines")


def _horizons(text: str) -> tuple[float, ...]:
    try:
        hs = tuple(float(h) for h in text.split(",") if h.strip())
    except ValueError:
        raise CampaignError("--horizons", "", f"expected comma-separated seconds, got {text!r}") from None
    if not hs or not all(h > 0 for h in hs):
        raise CampaignError("--horizons", "", f"expected seconds > 0, got {text!r}")
    return hs


def _options(args: argparse.Namespace, out: str) -> CampaignOptions:
    ctls = tuple(c.strip() for c in args.controllers.split(",") if c.strip())
    for c in ctls:
        if c not in CONTROLLERS:
            raise CampaignError("--controllers", "", f"unknown controller {c!r} (choose from {', '.join(CONTROLLERS)})")
    if not ctls:
        raise CampaignError("--controllers", "", "no controller given")
    return CampaignOptions(experiments=tuple(args.experiment.split(",")), runs=args.runs, seed=args.seed, out=out,
                           controllers=ctls, durations=parse_durations(args.duration),
                           duration_scale=args.duration_scale,
                           disturbances=DisturbanceModel(args.wind_scale, args.tilt, args.yaw),
                           timeout_s=args.timeout, fly_overrides=fly_overrides(args.fly_arg))


class _Progress:
    """A tqdm bar on stderr (none when stderr is not a terminal, or with -q)."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.bar = None
        self.failed = 0

    def start(self, plan) -> None:
        if not self.enabled:
            return
        from tqdm import tqdm

        self.bar = tqdm(total=len(plan.jobs), unit="flight", file=sys.stderr, dynamic_ncols=True,
                        desc="gcs campaign")

    def __call__(self, r) -> None:
        if not r.ok:
            self.failed += 1
        if self.bar is not None:
            self.bar.set_postfix_str(f"{r.key} {r.status}" + (f", {self.failed} failed" if self.failed else ""))
            self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def cmd_campaign(args: argparse.Namespace, argv: list[str] | None = None) -> int:
    """Run ``gcs campaign`` (see the module docstring); returns the exit code.

    ``argv`` is the whole ``gcs`` command line (without the program name), for the report.
    """

    # Absolute: the workers (a remote Dask worker too) write the runs' files there.
    out = str(Path(args.out or Path("campaigns") / utc_stamp()).absolute())
    horizons = _horizons(args.horizons)
    options = _options(args, out)
    if args.optimality_only:
        exps = [e.name for e in resolve_experiments(options.experiments)]
        Path(out).mkdir(parents=True, exist_ok=True)
        _rows, files = write_optimality(Path(out), exps, horizons, options.controllers)
        if not files:
            raise CampaignError("--experiment", "", "none of these experiments has an optimality table "
                                "(indoor-4dof and outdoor-altitude do)")
        print(Path(files["optimality.md"]).read_text(), end="")
        print(f"written: {files['optimality.md']}, {files['optimality.json']}")
        return 0
    workers = args.workers if args.workers is not None else (os.cpu_count() or 1)
    if workers < 1:
        raise CampaignError("--workers", "", f"must be >= 1, got {workers}")
    if args.scheduler is not None and args.executor != "dask":
        raise CampaignError("--scheduler", "", "only with --executor dask")
    if args.executor == "dask":
        _distributed()  # fail before flying anything when Dask is missing
    progress = _Progress(not args.quiet and sys.stderr.isatty())
    try:
        result = run_campaign(options, lambda: make_executor(args.executor, workers, args.scheduler),
                              command=command_line(argv) if argv else "",
                              progress=progress, on_plan=progress.start, figures=not args.no_figures,
                              horizons_s=horizons, executor_name=args.executor, workers=workers)
    finally:
        progress.close()
    plan = result.plan
    for name, why in plan.skipped.items():
        print(f"gcs campaign: skipped {name}: {why}", file=sys.stderr)
    for note in plan.notes:
        print(f"gcs campaign: note: {note}", file=sys.stderr)
    if not args.quiet:
        print(Path(result.files["tables.md"]).read_text(), end="")
    for r in result.failed:
        print(f"gcs campaign: failed run {r.key}: {r.status}" + (f" ({r.detail})" if r.detail else "")
              + f"; output {r.output_path}", file=sys.stderr)
    late = [r for r in result.results if r.ok and r.lockstep_timeouts]
    if late:
        print(f"gcs campaign: warning: {len(late)} run(s) had lockstep telemetry timeouts (e.g. {late[0].key}): "
              "their numbers depend on machine load; see RESULTS.md, Reproducibility", file=sys.stderr)
    if args.results:
        copy_results(Path(result.files["RESULTS.md"]), args.results)
    print(f"{len(result.results)} flights ({len(result.failed)} failed) in {result.wall_s:.1f} s on {workers} "
          f"worker(s), {result.vehicle_s:.0f} vehicle-seconds: {result.throughput:.1f} vehicle-s per wall s; "
          f"results in {result.out}" + (f", report copied to {args.results}" if args.results else ""))
    return 1 if result.failed else 0
