"""The ``gcs log`` subcommands (hooked into :mod:`gcs.cli`).

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
``gcs log channels FILE [--validate] [--json]``
    Every channel: topic, schema, encodings, messages; ``--validate`` checks the Foxglove
    well-known messages against the schemas in the file.

All of them read truncated logs and say so (stderr, and ``truncated`` in JSON); input that is
not an MCAP log is a one-line error (exit 1).
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from gcs.config import load_config
from gcs.log.review.channels import format_channels, log_channels
from gcs.log.review.export import export_csv
from gcs.log.review.info import log_info
from gcs.log.review.metrics import compare_logs, log_metrics
from gcs.log.review.plot import plot_log
from gcs.metrics import METRICS
from gcs.report import format_table

__all__ = ["add_log_parser", "cmd_log"]


def add_log_parser(sub: Any) -> None:
    """Add ``gcs log`` and its actions to the main parser's subparsers."""
    lg = sub.add_parser("log", help="review MCAP flight logs: info, metrics, plot, compare, export, channels",
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

    ch = actions.add_parser("channels", help="every channel: topic, schema, encodings, message count")
    ch.add_argument("file")
    ch.add_argument("--validate", action="store_true",
                    help="validate the Foxglove well-known messages against the schemas in the file (jsonschema)")
    ch.add_argument("--json", action="store_true", help="print one JSON object")


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
        out.append(f"  {'#':>3}  {'controller':<14} {'run':>4} {'seed':>5} {'start [s]':>10} "
                   f"{'duration [s]':>12} {'steps':>7}")
        for f in info["flights"]:
            run = _num(f["run"], "d") if f["run"] is not None else "-"
            out.append(f"  {f['flight']:>3}  {f['controller']:<14} {run:>4} "
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
    return load_config(args.config)


def _metrics_text(doc: dict) -> str:

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

    n = ", ".join(f"{name}: {g['flights']}" for name, g in doc["groups"].items())
    title = (f"{len(doc['files'])} log(s), experiment(s) {', '.join(doc['experiments'])}; "
             f"flights per column: {n}; mean ± sample std")
    return format_table({"results": doc["results"]}, title)


def cmd_log(args: argparse.Namespace) -> int:
    """Run a ``gcs log`` action (errors are :class:`gcs.errors.GcsError`, printed by :func:`gcs.cli.main`)."""
    action = args.log_command
    if action == "info":
        info = log_info(args.file)
        if args.json:
            print(json.dumps(info))
        else:
            print(_format_info(info, args.events))
        _warn_truncated(info["file"], info["truncated"], info["problem"])
        return 0
    if action == "metrics":
        doc = log_metrics(args.file, _config(args))
        print(json.dumps(doc) if args.json else _metrics_text(doc))
        _warn_truncated(doc["file"], doc["truncated"], doc["problem"])
        return 0
    if action == "plot":
        res = plot_log(args.file, args.output, flight=args.flight)
        print(f"{res['out']}: flight {res['flight']}; panels: {', '.join(res['panels'])}")
        _warn_truncated(res["file"], res["truncated"], res["problem"])
        return 0
    if action == "compare":
        doc = compare_logs(args.files, _config(args))
        print(json.dumps(doc) if args.json else _compare_text(doc))
        for f in doc["files"]:
            _warn_truncated(f["file"], f["truncated"], f["problem"])
        return 0
    if action == "export":
        res = export_csv(args.file, args.csv)
        for c in res["channels"]:
            print(f"{c['csv']}: {c['rows']} rows ({c['topic']})")
        _warn_truncated(res["file"], res["truncated"], res["problem"])
        return 0
    if action == "channels":
        doc = log_channels(args.file, validate=args.validate)
        print(json.dumps(doc) if args.json else format_channels(doc))
        _warn_truncated(doc["file"], doc["truncated"], doc["problem"])
        bad = sum(r.get("validation", {}).get("invalid", 0) for r in doc["channels"])
        return 1 if bad else 0
    raise AssertionError(f"unknown gcs log action {action!r}")  # argparse only lets the known ones through
