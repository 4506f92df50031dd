"""``gcs log channels``: every channel of a log — topic, schema, encodings, message count — and, on request,
its Foxglove well-known messages checked against the schemas the file carries.

The channel list shows what a viewer will find in the file without opening one (which panels of
Foxglove can draw what: a channel whose schema is ``foxglove.*`` is one of its well-known types).
With ``validate``, every message of those channels is validated (``jsonschema``) against the schema
stored in the file (the vendored copy of :mod:`gcs.log.topics` when the file's summary cannot be read,
e.g. a truncated file).
"""

from __future__ import annotations

import json
import os
from typing import Any

from gcs.errors import LogError
from gcs.log import topics as T
from gcs.log.mcap.reader import read_log

__all__ = ["FOXGLOVE_PREFIX", "format_channels", "log_channels"]

#: Schema names of Foxglove's well-known types start with this.
FOXGLOVE_PREFIX = "foxglove."
#: Errors reported per channel (the first ones; the count is complete).
_MAX_ERRORS = 3


def _file_schemas(path: str | os.PathLike) -> dict[str, bytes]:
    """``{topic: schema data}`` from the file's summary (empty when it has none, e.g. truncated)."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
    except (OSError, McapError, ValueError, EOFError):
        return {}
    if summary is None:
        return {}
    return {c.topic: summary.schemas[c.schema_id].data for c in summary.channels.values()
            if c.schema_id in summary.schemas}


def _validator(schema_data: bytes) -> Any:
    try:
        import jsonschema
    except ImportError:
        raise LogError("gcs log channels --validate needs the jsonschema package (pip install jsonschema)") from None
    schema = json.loads(schema_data)
    cls = jsonschema.validators.validator_for(schema)
    return cls(schema)


def _validate(log: Any, topic: str, schema_name: str, schema_data: bytes | None) -> dict:
    """``{"valid", "invalid", "errors", "schema_source"}`` of one Foxglove channel's kept messages."""
    source = "file"
    if not schema_data:
        source = "vendored"
        schema_data = T.foxglove_schema_bytes(schema_name[len(FOXGLOVE_PREFIX):])
    validator = _validator(schema_data)
    valid = invalid = 0
    errors: list[str] = []
    for _, data in log.messages.get(topic, []):
        try:
            doc = json.loads(data)
        except ValueError as exc:
            problems = [f"not JSON: {exc}"]
        else:
            problems = [f"{'/'.join(map(str, e.absolute_path)) or '(message)'}: {e.message}"
                        for e in validator.iter_errors(doc)]
        if problems:
            invalid += 1
            errors.extend(problems[:max(0, _MAX_ERRORS - len(errors))])
        else:
            valid += 1
    return {"valid": valid, "invalid": invalid, "errors": errors, "schema_source": source}


def log_channels(path: str | os.PathLike, *, validate: bool = False) -> dict:
    """The channels of a log.

    Parameters
    ----------
    path : path-like
    validate : bool
        Validate every message of the ``foxglove.*`` channels against their schemas (needs jsonschema).

    Returns
    -------
    dict
        ``file``, ``truncated``, ``problem``, ``messages`` (all), ``channels``: per channel, in topic
        order, ``topic``, ``schema``, ``schema_encoding``, ``message_encoding``, ``messages``,
        ``foxglove`` (a well-known Foxglove schema) and with ``validate``, for those, ``validation``
        (``valid``, ``invalid`` message counts, the first ``errors``, ``schema_source`` "file" or "vendored").

    Raises
    ------
    LogError
        Not a readable MCAP file; ``validate`` without jsonschema.
    """
    by_topic = {}
    log0 = read_log(path, None)
    for c in log0.channels.values():
        by_topic.setdefault(c.topic, c)
    fox = [t for t, c in by_topic.items() if c.schema_name.startswith(FOXGLOVE_PREFIX)]
    log = read_log(path, fox) if validate and fox else log0
    schemas = _file_schemas(path) if validate and fox else {}
    rows = []
    for topic in sorted(set(by_topic) | set(log.counts)):
        c = by_topic.get(topic)
        name = c.schema_name if c else ""
        row = {"topic": topic, "schema": name, "schema_encoding": c.schema_encoding if c else "",
               "message_encoding": c.message_encoding if c else "", "messages": log.counts.get(topic, 0),
               "foxglove": name.startswith(FOXGLOVE_PREFIX)}
        if validate and row["foxglove"]:
            row["validation"] = _validate(log, topic, name, schemas.get(topic))
        rows.append(row)
    return {"file": str(log.path), "truncated": log.truncated, "problem": log.problem,
            "messages": log.message_count, "channels": rows}


def format_channels(doc: dict) -> str:
    """The terminal table of :func:`log_channels`."""
    rows = doc["channels"]
    n_fox = sum(r["foxglove"] for r in rows)
    out = [f"{doc['file']}: {len(rows)} channels ({n_fox} of Foxglove well-known types), {doc['messages']} messages"
           + (f" — TRUNCATED: {doc['problem']}" if doc["truncated"] else "")]
    wt = max([len(r["topic"]) for r in rows] + [5])
    ws = max([len(r["schema"]) for r in rows] + [6])
    we = max([len(f"{r['message_encoding']}/{r['schema_encoding']}") for r in rows] + [8])
    out.append(f"  {'topic':<{wt}}  {'schema':<{ws}}  {'encoding':<{we}}  {'messages':>8}")
    for r in rows:
        line = (f"  {r['topic']:<{wt}}  {r['schema']:<{ws}}  {r['message_encoding'] + '/' + r['schema_encoding']:<{we}}"
                f"  {r['messages']:>8}")
        v = r.get("validation")
        if v is not None:
            line += (f"  valid {v['valid']}/{v['valid'] + v['invalid']} ({v['schema_source']} schema)"
                     + "".join(f"\n      {e}" for e in v["errors"]))
        out.append(line)
    return "\n".join(out)
