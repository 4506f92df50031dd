"""The ``gcs log`` subcommands and ``gcs sim``'s ``--log`` / ``--no-log`` (hooked into :mod:`gcs.cli`).

``gcs log info FILE``
    Duration, controllers, experiment, flights, channels with message counts and rates, events.
``gcs log metrics FILE [--json] [--config C]``
    The metrics of ``gcs sim`` recomputed from the log, per flight and mean ± std per controller.
``gcs log plot FILE -o OUT.png [--flight I]``
    Altitude, x-y track, the four control signals, attitude, velocities (needs matplotlib).
``gcs log compare A.mcap B.mcap ... [--json] [--config C]``
    The paper's tables across logs: flights grouped by controller, mean ± std.
``gcs log export FILE --csv DIR``
    One CSV per channel, fields flattened.

All of them read truncated logs and say so (stderr, and ``truncated`` in JSON); input that is
not an MCAP log is a one-line error (exit 1).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from contextlib import nullcontext
from pathlib import Path
from typing import Any, Sequence

__all__ = ["add_log_parser", "cmd_log", "add_sim_log_arguments", "open_sim_log", "default_log_path"]

LOG_DIR = "logs"


# --------------------------------------------------------------------------- gcs sim --log

def add_sim_log_arguments(parser: argparse.ArgumentParser) -> None:
    """``--log PATH`` / ``--no-log`` for ``gcs sim``."""
    g = parser.add_mutually_exclusive_group()
    g.add_argument("--log", metavar="PATH",
                   help="MCAP log of every control tick of every flight, one file for the whole run "
                        f"(default {LOG_DIR}/<UTC time>_<controller>_<experiment>.mcap)")
    g.add_argument("--no-log", action="store_true", help="write no log")


def default_log_path(controller: str, experiment: str, directory: str | os.PathLike = LOG_DIR) -> Path:
    """``logs/<UTC time>_<controller>_<experiment>.mcap`` (``_2``, ``_3`` ... when taken)."""
    from gcs.log.meta import utc_stamp

    safe = lambda s: "".join(c if c.isalnum() or c in "-_." else "-" for c in s)
    base = Path(directory) / f"{utc_stamp()}_{safe(controller)}_{safe(experiment)}"
    p, i = base.with_suffix(".mcap"), 2
    while p.exists():
        p, i = Path(f"{base}_{i}.mcap"), i + 1
    return p


def open_sim_log(args: argparse.Namespace, config: Any, controllers: Sequence[str], options: Any) -> Any:
    """The log of a ``gcs sim`` run (a context manager; a null one with ``--no-log``).

    Checks the directory and the free space first (:class:`gcs.errors.LogError`), starts the
    writer process, and writes the ``flight`` metadata, the config and the designed gains.
    Leaving the ``with`` block finishes the file and, unless ``--quiet``/``--json``, says where
    it is on stderr.
    """
    if getattr(args, "no_log", False):
        return nullcontext(None)
    from gcs.control import make_controller
    from gcs.log.meta import run_metadata, run_attachments
    from gcs.log.simlog import BYTES_PER_TICK, BackgroundSimLog

    e = config.experiment
    path = Path(args.log) if args.log else default_log_path(args.controller, e.name)
    runs = args.runs if args.runs is not None else config.sim.runs
    duration = options.duration_s if options.duration_s is not None else e.duration_s
    ticks = int(round(duration / e.ts_s)) * runs * len(controllers)
    from gcs.errors import LogError
    try:
        log = BackgroundSimLog(path, expected_bytes=ticks * BYTES_PER_TICK)
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
            try:
                self.log.path.unlink()
            except OSError:
                pass
            return
        if not self.quiet or exc_type is not None:
            size = f" ({st['bytes'] / 1e6:.1f} MB, {st['flights']} flight(s))" if st else ""
            clear = "\r" + " " * 40 + "\r" if sys.stderr.isatty() else ""
            print(f"{clear}gcs: log: {self.log.path}{size}", file=sys.stderr)


# --------------------------------------------------------------------------- gcs log ...

def add_log_parser(sub: Any) -> None:
    """Add ``gcs log`` and its actions to the main parser's subparsers."""
    lg = sub.add_parser("log", help="review MCAP flight logs: info, metrics, plot, compare, export",
                        description="Review MCAP flight logs written by gcs sim / gcs fly. Every action reads "
                                    "truncated logs (a killed writer) and says so.")
    actions = lg.add_subparsers(dest="log_command", metavar="ACTION", parser_class=type(lg))
    actions.required = True

    a = actions.add_parser("info", help="duration, controllers, channels with counts and rates, events")
    a.add_argument("file")
    a.add_argument("--events", type=int, default=40, metavar="N", help="events to list (default 40; 0 = all)")
    a.add_argument("--json", action="store_true", help="print one JSON object")

    m = actions.add_parser("metrics", help="the gcs sim metrics recomputed from the log")
    m.add_argument("file")
    m.add_argument("--config", help="experiment config (default: the one attached to the log)")
    m.add_argument("--json", action="store_true", help="print one JSON object")

    p = actions.add_parser("plot", help="altitude, x-y track, control signals, attitude, velocities as a PNG")
    p.add_argument("file")
    p.add_argument("-o", "--output", required=True, metavar="OUT.png", help="PNG to write")
    p.add_argument("--flight", type=int, default=0, help="flight to draw: its position in the log (default 0)")

    c = actions.add_parser("compare", help="a table across logs: flights grouped by controller, mean ± std")
    c.add_argument("files", nargs="+")
    c.add_argument("--config", help="experiment config for logs without one attached")
    c.add_argument("--json", action="store_true", help="print one JSON object")

    x = actions.add_parser("export", help="one CSV per channel")
    x.add_argument("file")
    x.add_argument("--csv", required=True, metavar="DIR", help="directory for the CSV files")


def _warn_truncated(file: str, truncated: bool, problem: str) -> None:
    if truncated:
        print(f"gcs: warning: {file} is TRUNCATED: {problem}", file=sys.stderr)


def _num(v: Any, fmt: str = ".3f") -> str:
    return "-" if v is None else format(v, fmt)


def _format_info(info: dict, max_events: int) -> str:
    out = [f"file        {info['file']} ({info['bytes'] / 1e6:.2f} MB)"]
    if info["truncated"]:
        out.append(f"status      TRUNCATED: {info['problem']}")
    else:
        out.append("status      complete")
    md = info["metadata"].get("flight", {})
    out.append(f"experiment  {info['experiment'] or '-'}")
    out.append(f"controllers {', '.join(info['controllers']) or '-'}")
    if md:
        out.append(f"software    gcs {md.get('software_version', '?')}, started {md.get('start_time_utc', '?')}, "
                   f"config {md.get('config', '?')}")
    out.append(f"duration    {_num(info['duration_s'])} s of log time, {info['messages']} messages")
    if info["flights"]:
        out.append(f"flights     {len(info['flights'])}")
        out.append(f"  {'#':>3}  {'controller':<14} {'run':>4} {'seed':>5} {'start [s]':>10} {'duration [s]':>12} {'steps':>7}")
        for f in info["flights"]:
            out.append(f"  {f['flight']:>3}  {f['controller']:<14} {_num(f['run'], 'd') if f['run'] is not None else '-':>4} "
                       f"{f['seed'] if f['seed'] is not None else '-':>5} {_num(f['start_s']):>10} "
                       f"{_num(f['duration_s']):>12} {f['steps'] if f['steps'] is not None else '-':>7}"
                       f"{'  (partial)' if f.get('partial') else ''}")
    out.append("channels")
    width = max([len(c["topic"]) for c in info["channels"]] + [5])
    out.append(f"  {'topic':<{width}} {'messages':>9} {'rate [Hz]':>10}  schema")
    for c in info["channels"]:
        out.append(f"  {c['topic']:<{width}} {c['messages']:>9} {_num(c['rate_hz'], '.1f'):>10}  {c['schema']}")
    events = info["events"]
    out.append(f"events      {len(events)}")
    shown = events if max_events <= 0 else events[:max_events]
    for ev in shown:
        extra = {k: v for k, v in ev.items() if k not in ("t_s", "kind", "text")}
        more = "  " + json.dumps(extra) if extra else ""
        out.append(f"  {_num(ev['t_s']):>10} s  {ev.get('kind', '?'):<13} {ev.get('text', '')}{more}")
    if len(shown) < len(events):
        out.append(f"  ... {len(events) - len(shown)} more (--events 0 lists all)")
    if info["attachments"]:
        out.append("attachments")
        for a in info["attachments"]:
            out.append(f"  {a['name']} ({a['media_type']}, {a['bytes']} bytes)")
    return "\n".join(out)


def _config(args: argparse.Namespace) -> Any:
    if not getattr(args, "config", None):
        return None
    from gcs.config import load_config
    return load_config(args.config)


def _metrics_text(doc: dict) -> str:
    from gcs.cli import format_table
    from gcs.metrics import METRICS

    lines = []
    for f in doc["flights"]:
        run = f" run {f['run']}" if f["run"] is not None else ""
        note = " (partial)" if f["partial"] else ""
        check = {True: ", equal to the in-run metrics", False: ", DIFFERENT from the in-run metrics",
                 None: ""}[f.get("in_run_match")]
        lines.append(f"flight {f['flight']}: {f['controller']}{run}, {f['steps']} steps{note}{check}")
        m = f["metrics"]
        lines.append("  " + ", ".join(f"{k} = {m[k]:.6g}" for k in METRICS if k in m))
    runs = {}
    for f in doc["flights"]:
        runs[f["controller"]] = runs.get(f["controller"], 0) + 1
    title = (f"{doc['experiment']}: {len(doc['flights'])} flight(s) in {doc['file']} "
             f"({', '.join(f'{c} x{n}' for c, n in runs.items())})")
    lines.append("")
    lines.append(format_table({"results": doc["results"]}, title))
    return "\n".join(lines)


def _compare_text(doc: dict) -> str:
    from gcs.cli import format_table

    n = ", ".join(f"{name}: {g['flights']}" for name, g in doc["groups"].items())
    title = (f"{len(doc['files'])} log(s), experiment(s) {', '.join(doc['experiments'])}; "
             f"flights per column: {n}; mean ± sample std")
    return format_table({"results": doc["results"]}, title)


def cmd_log(args: argparse.Namespace) -> int:
    """Run a ``gcs log`` action (errors are :class:`gcs.errors.GcsError`, printed by :func:`gcs.cli.main`)."""
    action = args.log_command
    if action == "info":
        from gcs.log.review import log_info
        info = log_info(args.file)
        if args.json:
            print(json.dumps(info))
        else:
            print(_format_info(info, args.events))
        _warn_truncated(info["file"], info["truncated"], info["problem"])
        return 0
    if action == "metrics":
        from gcs.log.review import log_metrics
        doc = log_metrics(args.file, _config(args))
        print(json.dumps(doc) if args.json else _metrics_text(doc))
        _warn_truncated(doc["file"], doc["truncated"], doc["problem"])
        return 0
    if action == "plot":
        from gcs.log.plot import plot_log
        res = plot_log(args.file, args.output, flight=args.flight)
        print(f"{res['out']}: flight {res['flight']}; panels: {', '.join(res['panels'])}")
        _warn_truncated(res["file"], res["truncated"], res["problem"])
        return 0
    if action == "compare":
        from gcs.log.review import compare_logs
        doc = compare_logs(args.files, _config(args))
        print(json.dumps(doc) if args.json else _compare_text(doc))
        for f in doc["files"]:
            _warn_truncated(f["file"], f["truncated"], f["problem"])
        return 0
    if action == "export":
        from gcs.log.review import export_csv
        res = export_csv(args.file, args.csv)
        for c in res["channels"]:
            print(f"{c['csv']}: {c['rows']} rows ({c['topic']})")
        _warn_truncated(res["file"], res["truncated"], res["problem"])
        return 0
    raise AssertionError(f"unknown gcs log action {action!r}")  # argparse only lets the known ones through
