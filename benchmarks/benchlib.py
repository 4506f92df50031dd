"""Shared helpers of the ``bench_*.py`` scripts (not a benchmark itself).

Every benchmark builds one JSON-able document::

    {"bench": "link", "quick": true, "data": {raw figures}, "rows": [row, ...],
     "skipped": null or "why"}

where a row puts one figure beside its baseline (:func:`row`).  :func:`emit` prints
the human-readable text on stdout; with ``--json`` the same text goes to stderr and
the document alone to stdout, so ``run.py`` builds its report from data and still
keeps every line of text.  Timings are medians over repeats; nothing here asserts on
a time.
"""

from __future__ import annotations

import json
import math
import statistics
import sys
import time
from collections.abc import Callable, Iterable


def median_us(fn: Callable[[], None], per_call: int, repeats: int) -> float:
    """Median over ``repeats`` calls of ``fn`` of its wall time divided by ``per_call``, in microseconds."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) / per_call * 1e6)
    return statistics.median(times)


def percentile(values: Iterable[float], q: float) -> float:
    """The ``q`` quantile (0..1) of ``values``, nearest rank."""
    v = sorted(values)
    if not v:
        return math.nan
    return v[min(len(v) - 1, int(q * len(v)))]


def row(figure: str, value: float | None, unit: str = "", *, baseline: str | None = None,
        baseline_value: float | None = None, target: str | None = None, met: bool | None = None,
        note: str = "") -> dict:
    """One line of a report table: a figure, its baseline and ``ratio = value / baseline_value``.

    ``target`` is a text such as ``"<= 15 us"``; ``met`` says whether ``value`` meets it
    (the benchmark decides, None when there is no target).
    """
    ratio = None
    if value is not None and baseline_value not in (None, 0) and math.isfinite(value) and math.isfinite(baseline_value):
        ratio = value / baseline_value
    return {"figure": figure, "value": value, "unit": unit, "baseline": baseline, "baseline_value": baseline_value,
            "ratio": ratio, "target": target, "met": met, "note": note}


def document(bench: str, quick: bool, data: dict, rows: list[dict], skipped: str | None = None) -> dict:
    return {"bench": bench, "quick": quick, "data": data, "rows": rows, "skipped": skipped}


def emit(doc: dict, text: str, as_json: bool) -> None:
    """Print ``text`` (stdout, or stderr with ``--json``) and, with ``--json``, ``doc`` on stdout."""
    if as_json:
        print(text, file=sys.stderr, flush=True)
        print(json.dumps(doc, allow_nan=True), flush=True)
    else:
        print(text, flush=True)


def met_text(met: bool | None) -> str:
    return "-" if met is None else ("met" if met else "MISSED")
