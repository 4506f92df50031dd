"""The review tools behind ``gcs log``: info, metrics, compare and CSV export (data, not text).

Each function reads what it needs with :func:`gcs.log.reader.read_log`, works on a
truncated log (and says so: ``truncated`` and ``problem`` in every result), and
raises :class:`gcs.errors.LogError` for input that is not an MCAP log.
Formatting for the terminal is in :mod:`gcs.log.cli`; figures in :mod:`gcs.log.plot`.
"""

from __future__ import annotations

import bisect
import csv
import json
import os
from pathlib import Path
from typing import Any, Iterable, Sequence

from gcs.errors import LogError
from gcs.log import topics as T
from gcs.log.flights import log_config, split_flights, stream_metrics
from gcs.log.reader import read_log

__all__ = ["log_info", "log_metrics", "compare_logs", "export_csv", "flatten"]


def _s(ns: int | None, origin: int | None) -> float | None:
    return None if ns is None or origin is None else (ns - origin) / 1e9


def log_info(path: str | os.PathLike) -> dict:
    """Summary of a log: duration, controllers, experiment, flights, channels (counts, rates), events.

    Returns
    -------
    dict
        ``file``, ``bytes``, ``truncated``, ``problem``, ``profile``, ``library``, ``metadata``,
        ``experiment``, ``controllers``, ``duration_s``, ``messages``, ``flights`` (index,
        controller, run, seed, start_s, duration_s, steps), ``channels`` (topic, messages,
        rate_hz, schema, first_s, last_s), ``events`` (t_s, kind, text, ...), ``attachments``
        (name, media_type, bytes).  Times in seconds from the first message.
    """
    log = read_log(path, [T.FLIGHT, T.EVENTS])
    origin = log.start_ns
    md = log.metadata_dict("flight") or {}
    flights = split_flights(log)
    ctl_names: list[str] = []
    for fl in flights:
        if fl.controller not in ctl_names:
            ctl_names.append(fl.controller)
    if md.get("controller") and not log.messages.get(T.FLIGHT):
        ctl_names = [c for c in md["controller"].split(",") if c]
    out_flights = []
    for fl in flights:
        last = log.end_ns if fl.end_ns is None else min(fl.end_ns, log.end_ns or fl.end_ns)
        flown = None if last is None else (last - fl.start_ns) / 1e9
        planned = fl.steps * fl.ts_s if fl.steps is not None and fl.ts_s else None
        dur = flown if planned is None else planned if flown is None else min(planned, flown)
        out_flights.append({"flight": fl.index, "controller": fl.controller, "run": fl.run, "seed": fl.seed,
                            "experiment": fl.experiment, "start_s": _s(fl.start_ns, origin), "duration_s": dur,
                            "steps": fl.steps, "source": fl.source,
                            "partial": bool(planned is not None and dur is not None and dur < planned - 1e-9)})
    by_id = {c.topic: c for c in log.channels.values()}
    # Several flights (a simulation): rates per second of flight, not of the gaps between flights.
    flown = sum(f["duration_s"] for f in out_flights) if len(out_flights) > 1 and all(
        f["duration_s"] for f in out_flights) else None
    channels = []
    for topic in log.topics:
        n = log.counts[topic]
        span = (log.last_ns[topic] - log.first_ns[topic]) / 1e9
        ch = by_id.get(topic)
        rate = n / flown if flown else ((n - 1) / span if span > 0 and n > 1 else None)
        channels.append({"topic": topic, "messages": n, "rate_hz": rate,
                         "schema": ch.schema_name if ch else "", "first_s": _s(log.first_ns[topic], origin),
                         "last_s": _s(log.last_ns[topic], origin)})
    events = []
    for t, d in log.decoded(T.EVENTS):
        ev = {"t_s": _s(t, origin)}
        ev.update(d if isinstance(d, dict) else {"kind": "?", "text": str(d)})
        events.append(ev)
    experiment = md.get("experiment") or next((f.experiment for f in flights if f.experiment), "")
    return {
        "file": str(log.path), "bytes": log.path.stat().st_size, "truncated": log.truncated, "problem": log.problem,
        "profile": log.profile, "library": log.library, "metadata": {n: d for n, d in log.metadata},
        "experiment": experiment, "controllers": ctl_names,
        "duration_s": _s(log.end_ns, origin) if origin is not None else 0.0,
        "messages": log.message_count, "flights": out_flights, "channels": channels, "events": events,
        "attachments": [{"name": a.name, "media_type": a.media_type, "bytes": len(a.data)} for a in log.attachments],
    }


def _summaries(rows: Iterable[dict], key) -> dict[str, dict]:
    from gcs.metrics import summarize

    groups: dict[str, list[dict]] = {}
    for r in rows:
        groups.setdefault(key(r), []).append(r["metrics"])
    return {name: summarize(ms) for name, ms in groups.items()}


def log_metrics(path: str | os.PathLike, config: Any = None) -> dict:
    """The metrics of every flight of a log, recomputed from it, and their mean and standard deviation.

    Parameters
    ----------
    path : path-like
    config : gcs.config.Config or None
        None: the config attached to the log.

    Returns
    -------
    dict
        ``file``, ``truncated``, ``problem``, ``experiment``, ``flights`` (see
        :func:`gcs.log.flights.logged_metrics`; ``in_run_match`` tells whether they equal
        the metrics logged in the run) and ``results`` ``{controller: {metric: {"mean",
        "std"}}}`` — the shape of ``gcs sim --json``'s ``results``.
    """
    log, rows = stream_metrics(path, config)
    cfg = config if config is not None else log_config(log)
    for r in rows:
        r["in_run_match"] = None if r["in_run"] is None else _same(r["in_run"], r["metrics"])
    return {"file": str(log.path), "truncated": log.truncated, "problem": log.problem,
            "experiment": cfg.experiment.name, "flights": rows, "results": _summaries(rows, lambda r: r["controller"])}


def _same(a: dict, b: dict) -> bool:
    return set(a) == set(b) and all(a[k] == b[k] or abs(a[k] - b[k]) <= 1e-12 * max(abs(a[k]), abs(b[k]))
                                    for k in a)


def compare_logs(paths: Sequence[str | os.PathLike], config: Any = None) -> dict:
    """Flights of several logs side by side, grouped by controller (and experiment, when they differ).

    Returns
    -------
    dict
        ``files`` (file, truncated, problem, flights), ``experiments``, ``groups``
        ``{name: {"controller", "experiment", "flights"}}`` and ``results``
        ``{name: {metric: {"mean", "std"}}}``.
    """
    if not paths:
        raise LogError("no log files to compare")
    rows, files = [], []
    for p in paths:
        m = log_metrics(p, config)
        files.append({"file": m["file"], "truncated": m["truncated"], "problem": m["problem"],
                      "flights": len(m["flights"])})
        rows.extend(m["flights"])
    experiments = sorted({r["experiment"] for r in rows})
    several = len(experiments) > 1

    def key(r: dict) -> str:
        return f"{r['controller']} @ {r['experiment']}" if several else r["controller"]

    groups: dict[str, dict] = {}
    for r in rows:
        g = groups.setdefault(key(r), {"controller": r["controller"], "experiment": r["experiment"], "flights": 0})
        g["flights"] += 1
    return {"files": files, "experiments": experiments, "groups": groups, "results": _summaries(rows, key)}


def flatten(obj: Any, prefix: str = "") -> dict[str, Any]:
    """A JSON value as flat ``{"a.b.0": value}`` columns (a scalar becomes ``{"value": ...}``)."""
    out: dict[str, Any] = {}
    if isinstance(obj, dict):
        for k, v in obj.items():
            name = f"{prefix}.{k}" if prefix else str(k)
            if isinstance(v, (dict, list)):
                out.update(flatten(v, name))
            else:
                out[name] = v
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            name = f"{prefix}.{i}" if prefix else str(i)
            if isinstance(v, (dict, list)):
                out.update(flatten(v, name))
            else:
                out[name] = v
    else:
        out[prefix or "value"] = obj
    return out


def _csv_name(topic: str, taken: set[str]) -> str:
    base = "".join(c if c.isalnum() or c in "-_." else "_" for c in topic.strip("/").replace("/", "_")) or "root"
    name, i = base, 2
    while name in taken:
        name, i = f"{base}_{i}", i + 1
    taken.add(name)
    return name + ".csv"


def _cell(v: Any) -> Any:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    return v


def export_csv(path: str | os.PathLike, out_dir: str | os.PathLike) -> dict:
    """One CSV per channel in ``out_dir``: ``log_time_ns``, ``t_s`` (from the first message),
    ``flight`` (when the log has several) and the flattened fields.

    Returns
    -------
    dict
        ``file``, ``truncated``, ``problem``, ``dir`` and ``channels`` (topic, csv, rows, columns).
    """
    log = read_log(path, "all")
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise LogError(f"{out}: cannot create the directory: {exc.strerror or exc}") from None
    origin = log.start_ns or 0
    flights = split_flights(log) if log.messages.get(T.FLIGHT) else []
    starts = [f.start_ns for f in flights]
    encodings = {c.topic: c.message_encoding for c in log.channels.values()}
    taken: set[str] = set()
    written = []
    for topic in sorted(log.messages):
        msgs = log.messages[topic]
        as_json = encodings.get(topic, "json") == "json"
        rows, columns, seen = [], [], set()
        for t, data in msgs:
            if as_json:
                try:
                    fields = flatten(json.loads(data))
                except ValueError:
                    fields = {"data_hex": bytes(data).hex()}
            else:
                fields = {"data_hex": bytes(data).hex()}
            for c in fields:
                if c not in seen:
                    seen.add(c)
                    columns.append(c)
            rows.append((t, fields))
        lead = ["log_time_ns", "t_s"] + (["flight"] if len(flights) > 1 else [])
        # A field called like a lead column keeps its data under a prefixed name.
        header = lead + [c if c not in lead else f"field.{c}" for c in columns]
        name = _csv_name(topic, taken)
        target = out / name
        try:
            with open(target, "w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow(header)
                for t, fields in rows:
                    row: list[Any] = [t, f"{(t - origin) / 1e9:.9f}"]
                    if len(flights) > 1:
                        i = bisect.bisect_right(starts, t) - 1
                        row.append(flights[i].index if i >= 0 else "")
                    row.extend(_cell(fields.get(c)) for c in columns)
                    w.writerow(row)
        except OSError as exc:
            raise LogError(f"{target}: cannot write: {exc.strerror or exc}") from None
        written.append({"topic": topic, "csv": str(target), "rows": len(rows), "columns": len(header)})
    return {"file": str(log.path), "truncated": log.truncated, "problem": log.problem, "dir": str(out),
            "channels": written}
