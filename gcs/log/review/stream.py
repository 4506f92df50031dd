"""``gcs log metrics`` on logs too big to hold: the flights' metrics from the log read as a stream.

:func:`stream_metrics` computes what :func:`gcs.log.review.flights.logged_metrics` computes,
holding one flight's series at a time (a default ``gcs sim`` log is over a gigabyte).
"""

from __future__ import annotations

import json
from array import array
from pathlib import Path
from typing import Any

import numpy as np

from gcs.errors import LogError
from gcs.log import topics as T
from gcs.log.mcap.reader import McapLog, read_attachment, read_log
from gcs.log.review.flights import METRIC_TOPICS, as_int, log_config, logged_metrics, positive_float, record_from_arrays
from gcs.metrics import controller_cost, flight_metrics
from gcs.mission import Mission

__all__ = ["stream_metrics"]

class _Disorder(Exception):
    """The log's messages are not in flight order: read it whole instead."""


_SERIES = {T.TRUTH: T.STATE_FIELDS, T.STATE: T.STATE_FIELDS, T.REFERENCE: T.STATE_FIELDS,
           T.COMMAND: T.COMMAND_FIELDS, T.COMMAND_LIMITED: T.COMMAND_FIELDS}


class _StreamedFlight:
    """One flight's series as they stream by, as flat arrays of doubles."""

    def __init__(self, info: dict | None, start_ns: int) -> None:
        self.info = info
        self.start_ns = start_ns
        self.series = {topic: array("d") for topic in _SERIES}
        self.steps_to_go = array("q")


class _MetricsStream:
    """Computes each flight's metrics when the next one begins, holding one flight at a time."""

    def __init__(self, path: Any, cfg: Any) -> None:

        self.path = path
        self.cfg = cfg
        self.mission = Mission(cfg.mission, zero_velocity=cfg.experiment.zero_velocity_reference)
        self.flight: _StreamedFlight | None = None
        self.closed: list[tuple[dict, Any]] = []  # (flight info, (metrics or record, steps, partial) or LogError)
        self.in_run: dict[int, dict] = {}
        self.count = 0

    def __call__(self, topic: str, t: int, data: bytes) -> None:
        if topic == T.FLIGHT:
            self.close()
            try:
                info = json.loads(data.decode())
            except ValueError:
                raise LogError(f"{self.path}: a /flight message is not JSON") from None
            if not isinstance(info, dict):
                raise LogError(f"{self.path}: a /flight message is not a JSON object")
            self.flight = _StreamedFlight(info, t)
            return
        if topic in T.RUN_METRICS:
            d = json.loads(data.decode())
            if isinstance(d, dict) and isinstance(d.get("flight"), int):
                self.in_run[d["flight"]] = {k: v for k, v in d.items() if k not in ("flight", "controller", "run")}
            return
        fl = self.flight
        if fl is None:
            fl = self.flight = _StreamedFlight(None, t)
        elif t < fl.start_ns:
            raise _Disorder()
        try:
            d = json.loads(data.decode())
            if topic == T.HORIZON:
                fl.steps_to_go.append(int(d.get("steps_to_go", 0)))
            else:
                fl.series[topic].extend([d[f] for f in _SERIES[topic]])
        except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as exc:
            raise LogError(f"{self.path}: {topic}: a message lacks or mangles a field ({exc})") from None

    def close(self) -> None:
        fl = self.flight
        if fl is None:
            return
        self.flight = None
        arr = {topic: np.frombuffer(a, dtype=float).reshape(-1, len(_SERIES[topic])) for topic, a in fl.series.items()}
        truth = arr[T.TRUTH].shape[0] > 0
        limited = arr[T.COMMAND_LIMITED]
        info = fl.info or {}
        ts = positive_float(info.get("ts_s")) or self.cfg.experiment.ts_s
        label = f"{self.path}: flight #{len(self.closed)}"
        try:
            rec = record_from_arrays(arr[T.TRUTH] if truth else arr[T.STATE], arr[T.REFERENCE],
                                     limited if limited.shape[0] else arr[T.COMMAND],
                                     np.frombuffer(fl.steps_to_go, dtype=np.int64), ts,
                                     as_int(info.get("steps")), label)
        except LogError as exc:
            self.closed.append((info, exc))
            return
        record, partial = rec
        steps = int(record.command.shape[0])
        if "controller" in info:  # measure now and let the series go
            self.closed.append((info, (self.measure(record, str(info["controller"])), steps, partial)))
        else:  # a log without /flight: the controller is in the metadata, read at the end
            self.closed.append((info, (record, steps, partial)))

    def measure(self, record: Any, controller: str) -> dict[str, float]:

        try:
            cost = controller_cost(controller, self.cfg)
        except (KeyError, ValueError):
            cost = None
        return flight_metrics(record, self.cfg, self.mission, cost)


def stream_metrics(path: Any, config: Any = None) -> tuple[McapLog, list[dict]]:
    """:func:`logged_metrics` of a log read as a stream, one flight in memory at a time.

    Needs the flights' messages in time order (what :class:`gcs.log.writer.FlightLog`
    writes); otherwise it reads the log whole.

    Returns
    -------
    (McapLog without the messages, per-flight rows as :func:`logged_metrics`)
    """
    if config is None:
        att = read_attachment(path, "config.json")
        config = log_config(McapLog(Path(path), attachments=[att] if att is not None else []))
    stream = _MetricsStream(path, config)
    try:
        log = read_log(path, METRIC_TOPICS, sink=stream)
    except _Disorder:
        log = read_log(path, METRIC_TOPICS)
        return log, logged_metrics(log, config)
    stream.close()
    md = log.metadata_dict("flight") or {}
    rows = []
    for i, (info, result) in enumerate(stream.closed):
        last = i == len(stream.closed) - 1
        if isinstance(result, LogError):
            if log.truncated and last and len(stream.closed) > 1:
                break  # the writer died as this flight began: nothing of it to measure
            raise result
        metrics, steps, partial = result
        controller = str(info.get("controller", md.get("controller", "?")))
        if not isinstance(metrics, dict):  # a record still to measure (no /flight message)
            metrics = stream.measure(metrics, controller)
        index = as_int(info.get("flight"), i)
        rows.append({"flight": index, "controller": controller, "run": as_int(info.get("run")),
                     "seed": as_int(info.get("seed")),
                     "experiment": str(info.get("experiment", "")) or md.get("experiment") or config.experiment.name,
                     "steps": steps, "partial": partial or (log.truncated and last), "metrics": metrics,
                     "in_run": stream.in_run.get(index)})
    if not rows:
        raise LogError(f"{path}: no flight to compute metrics on")
    return log, rows
