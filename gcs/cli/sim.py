"""``gcs sim`` and ``gcs configs`` on the command line."""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from contextlib import nullcontext
from pathlib import Path
from typing import Any
from collections.abc import Sequence

from gcs.cli.args import nonneg_int, positive_float, positive_int
from gcs.config import MATRIX_MODES, bundled_configs, load_config
from gcs.control import CONTROLLERS, make_controller
from gcs.errors import LogError
from gcs.log.meta import LOG_DIR, default_log_path, run_attachments, run_metadata
from gcs.log.simrecorder import BYTES_PER_TICK
from gcs.log.sink import BackgroundSink
from gcs.report import format_table
from gcs.sim import SimOptions, check_run, run_experiment

__all__ = ["add_sim_parser", "cmd_sim", "cmd_configs", "DEFAULT_SIM_CONFIG", "add_sim_log_arguments", "open_sim_log"]

DEFAULT_SIM_CONFIG = "outdoor-altitude"


def add_sim_parser(sub) -> argparse.ArgumentParser:
    s = sub.add_parser("sim", help="closed-loop in-process simulation of the paper's experiments",
                       description="Fly the controllers on the reduced plant (RK4 at 1 ms, zero-order hold over "
                                   "the 10 ms control period) and print the paper's metrics, mean and standard "
                                   "deviation over runs.")
    s.add_argument("--config", default=DEFAULT_SIM_CONFIG,
                   help=f"experiment config: a TOML path or a bundled name ({', '.join(bundled_configs())}); "
                        f"default {DEFAULT_SIM_CONFIG}")
    s.add_argument("--controller", default="all", choices=CONTROLLERS + ("all",),
                   help="controller to fly, or all of them (default all)")
    s.add_argument("--runs", type=positive_int, help="runs per controller (default: the config's sim.runs)")
    s.add_argument("--seed", type=nonneg_int, help="base seed (default: the config's sim.seed)")
    s.add_argument("--duration", type=positive_float, metavar="SECONDS",
                   help="simulated seconds per run (default: the config's experiment.duration_s)")
    s.add_argument("--matrices", choices=MATRIX_MODES,
                   help="fly the corrected or the literal printed matrices (default: the config's)")
    wind = s.add_mutually_exclusive_group()
    wind.add_argument("--wind", dest="wind", action="store_true", default=None, help="blow the config's wind")
    wind.add_argument("--no-wind", dest="wind", action="store_false", help="calm air")
    s.add_argument("--no-noise", action="store_true", help="ideal sensors: feed the true state back")
    s.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    s.add_argument("--quiet", "-q", action="store_true", help="no progress on stderr")
    return s


def cmd_sim(args: argparse.Namespace, open_log) -> int:
    """Run ``gcs sim``; ``open_log(args, config, controllers, options)`` is the log's context manager."""
    config = load_config(args.config)
    if args.matrices is not None and args.matrices != config.experiment.matrices:
        config = config.with_matrices(args.matrices)
    controllers = list(CONTROLLERS) if args.controller == "all" else [args.controller]
    options = SimOptions(duration_s=args.duration, wind=args.wind, noise=not args.no_noise)
    check_run(config, args.runs, options)  # before the log is sized: a clear refusal, exit 2
    show = not (args.quiet or args.json or not sys.stderr.isatty())

    def progress(name: str, i: int, n: int) -> None:
        print(f"\r  flying {name:<14} run {i + 1}/{n}", end="", file=sys.stderr, flush=True)

    with open_log(args, config, controllers, options) as log:
        result = run_experiment(config, controllers, runs=args.runs, seed=args.seed, options=options,
                                progress=progress if show else None, log=log)
    if show:
        print("\r" + " " * 40 + "\r", end="", file=sys.stderr, flush=True)
    doc = result.to_json()
    if args.json:
        print(json.dumps(doc))
        return 0
    e = config.experiment
    blow = config.sim.wind_enabled if args.wind is None else args.wind
    w = config.sim.wind
    wind = f"wind {w.mean_speed_m_s:g} m/s + gusts {w.gust_std_m_s:g} m/s" if blow else "wind off"
    sensors = "ideal" if (args.no_noise or config.sim.sensors.is_ideal) else config.sim.sensors.altitude
    title = (f"{e.name}: {result.runs} run(s) x {result.duration_s:g} s, Ts = {e.ts_s * 1000:g} ms, "
             f"horizon {e.horizon_s:g} s then {e.after_horizon}, matrices {e.matrices}, {wind}, sensors {sensors}")
    print(format_table(doc, title))
    return 0


def cmd_configs() -> int:
    for name in bundled_configs():
        print(f"{name:20s} {load_config(name).experiment.description}")
    return 0


# --------------------------------------------------------------------------- gcs sim --log

def add_sim_log_arguments(parser: argparse.ArgumentParser) -> None:
    """``--log PATH`` / ``--no-log`` for ``gcs sim``."""
    g = parser.add_mutually_exclusive_group()
    g.add_argument("--log", metavar="PATH",
                   help="MCAP log of every control tick of every flight, one file for the whole run "
                        f"(default {LOG_DIR}/<UTC time>_<controller>_<experiment>.mcap)")
    g.add_argument("--no-log", action="store_true", help="write no log")


def open_sim_log(args: argparse.Namespace, config: Any, controllers: Sequence[str], options: Any) -> Any:
    """The log of a ``gcs sim`` run (a context manager; a null one with ``--no-log``).

    Checks the directory and the free space first (:class:`gcs.errors.LogError`), starts the
    writer process, and writes the ``flight`` metadata, the config and the designed gains.
    Leaving the ``with`` block finishes the file and, unless ``--quiet``/``--json``, says where
    it is on stderr.
    """
    if getattr(args, "no_log", False):
        return nullcontext(None)
    e = config.experiment
    path = Path(args.log) if args.log else default_log_path(args.controller, e.name)
    runs = args.runs if args.runs is not None else config.sim.runs
    duration = options.duration_s if options.duration_s is not None else e.duration_s
    ticks = round(duration / e.ts_s) * runs * len(controllers)
    try:
        log = BackgroundSink(path, expected_bytes=ticks * BYTES_PER_TICK, overflow="wait")
    except LogError as exc:
        raise LogError(f"{exc} (--log PATH writes elsewhere, --no-log writes none)") from None
    try:
        blow = config.sim.wind_enabled if options.wind is None else options.wind
        log.metadata("flight", run_metadata(
            config, controllers, source="sim", runs=runs, seed=args.seed if args.seed is not None else config.sim.seed,
            duration_s=duration, wind=blow, noise=options.noise))
        for name, media, data in run_attachments(config, {n: make_controller(n, config) for n in controllers}):
            log.attachment(name, media, data)
    except BaseException:
        log.close()
        raise
    quiet = bool(getattr(args, "quiet", False) or getattr(args, "json", False))
    return _Announce(log, quiet)


class _Announce:
    """Closes the log and says where it is."""

    def __init__(self, log: Any, quiet: bool) -> None:
        self.log, self.quiet = log, quiet

    def __enter__(self) -> Any:
        return self.log

    def __exit__(self, exc_type, exc, tb) -> None:
        self.log.__exit__(exc_type, exc, tb)
        st = self.log.stats
        if exc_type is not None and not st.get("flights"):
            # Nothing was flown (e.g. an option rejected by the simulation): leave no empty log behind.
            with contextlib.suppress(OSError):
                self.log.path.unlink()
            return
        if not self.quiet or exc_type is not None:
            size = f" ({st['bytes'] / 1e6:.1f} MB, {st['flights']} flight(s))" if st else ""
            clear = "\r" + " " * 40 + "\r" if sys.stderr.isatty() else ""
            print(f"{clear}gcs: log: {self.log.path}{size}", file=sys.stderr)
