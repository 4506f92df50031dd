"""``gcs log metrics`` and ``gcs log compare``: the metrics recomputed from logs, per flight and per controller."""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from typing import Any

from gcs.errors import LogError
from gcs.log.review.flights import log_config
from gcs.log.review.stream import stream_metrics
from gcs.metrics import summarize

__all__ = ["compare_logs", "log_metrics"]


def _summaries(rows: Iterable[dict], key) -> dict[str, dict]:

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
        :func:`gcs.log.review.flights.logged_metrics`; ``in_run_match`` tells whether they equal
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
