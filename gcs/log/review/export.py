"""``gcs log export``: one CSV per channel, the JSON fields flattened into columns.

A ``foxglove.PosesInFrame`` (``/foxglove/reference_path``: thousands of poses in one message) becomes one
row per pose (its index in ``pose``), not one row of thousands of columns.
"""

from __future__ import annotations

import bisect
import csv
import json
import os
from pathlib import Path
from typing import Any

from gcs.errors import LogError
from gcs.log import topics as T
from gcs.log.mcap.reader import read_log
from gcs.log.review.flights import split_flights

__all__ = ["export_csv", "flatten"]


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


def _fields_of(msgs: list, as_json: bool) -> tuple[list[tuple[int, dict]], list[str]]:
    """Each message's flattened fields (the bytes in hex when they are not JSON) and the columns in first-seen order."""
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
    return rows, columns


def _one_row_per_pose(msgs: list) -> list[tuple[int, bytes]]:
    """The poses of ``foxglove.PosesInFrame`` messages, one message each (``pose``: its index)."""
    out = []
    for t, data in msgs:
        try:
            doc = json.loads(data)
            poses = doc.pop("poses")
        except (ValueError, KeyError, AttributeError):  # not a PosesInFrame: as it is
            out.append((t, data))
            continue
        for i, pose in enumerate(poses if isinstance(poses, list) else []):
            out.append((t, json.dumps(dict(doc, pose=i, **(pose if isinstance(pose, dict) else {}))).encode()))
    return out


def _write_csv(target: Path, header: list[str], rows: list[tuple[int, dict]], columns: list[str], origin: int,
               flights: list) -> None:
    starts = [f.start_ns for f in flights]
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
    flights = split_flights(log) if log.messages.get(T.FLIGHT) else []
    encodings = {c.topic: c.message_encoding for c in log.channels.values()}
    taken: set[str] = set()
    written = []
    for topic in sorted(log.messages):
        msgs = log.messages[topic]
        if topic == T.FOXGLOVE_REFERENCE_PATH:
            msgs = _one_row_per_pose(msgs)
        rows, columns = _fields_of(msgs, encodings.get(topic, "json") == "json")
        lead = ["log_time_ns", "t_s"] + (["flight"] if len(flights) > 1 else [])
        # A field called like a lead column keeps its data under a prefixed name.
        header = lead + [c if c not in lead else f"field.{c}" for c in columns]
        target = out / _csv_name(topic, taken)
        _write_csv(target, header, rows, columns, log.start_ns or 0, flights)
        written.append({"topic": topic, "csv": str(target), "rows": len(rows), "columns": len(header)})
    return {"file": str(log.path), "truncated": log.truncated, "problem": log.problem, "dir": str(out),
            "channels": written}
