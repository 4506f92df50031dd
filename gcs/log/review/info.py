"""``gcs log info``: what a log holds — duration, controllers, experiment, flights, channels, events."""

from __future__ import annotations

import os

from gcs.log import topics as T
from gcs.log.mcap.reader import McapLog, read_log
from gcs.log.review.flights import LoggedFlight, split_flights

__all__ = ["log_info"]


def _s(ns: int | None, origin: int | None) -> float | None:
    return None if ns is None or origin is None else (ns - origin) / 1e9


def _flight_rows(log: McapLog, flights: list[LoggedFlight]) -> list[dict]:
    """Each flight's index, controller, run, seed, start and duration (flown, at most as planned)."""
    out = []
    for fl in flights:
        last = log.end_ns if fl.end_ns is None else min(fl.end_ns, log.end_ns or fl.end_ns)
        flown = None if last is None else (last - fl.start_ns) / 1e9
        planned = fl.steps * fl.ts_s if fl.steps is not None and fl.ts_s else None
        dur = flown if planned is None else planned if flown is None else min(planned, flown)
        out.append({"flight": fl.index, "controller": fl.controller, "run": fl.run, "seed": fl.seed,
                    "experiment": fl.experiment, "start_s": _s(fl.start_ns, log.start_ns), "duration_s": dur,
                    "steps": fl.steps, "source": fl.source,
                    "partial": bool(planned is not None and dur is not None and dur < planned - 1e-9)})
    return out


def _channel_rows(log: McapLog, flights: list[dict]) -> list[dict]:
    """Each topic's messages, rate, schema, first and last time."""
    by_id = {c.topic: c for c in log.channels.values()}
    origin = log.start_ns
    # Several flights (a simulation): rates per second of flight, not of the gaps between flights.
    flown = sum(f["duration_s"] for f in flights) if len(flights) > 1 and all(
        f["duration_s"] for f in flights) else None
    channels = []
    for topic in log.topics:
        n = log.counts[topic]
        span = (log.last_ns[topic] - log.first_ns[topic]) / 1e9
        ch = by_id.get(topic)
        rate = n / flown if flown else ((n - 1) / span if span > 0 and n > 1 else None)
        channels.append({"topic": topic, "messages": n, "rate_hz": rate,
                         "schema": ch.schema_name if ch else "", "first_s": _s(log.first_ns[topic], origin),
                         "last_s": _s(log.last_ns[topic], origin)})
    return channels


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
    out_flights = _flight_rows(log, flights)
    events = []
    for t, d in log.decoded(T.EVENTS):
        ev = {"t_s": _s(t, origin)}
        ev.update(d if isinstance(d, dict) else {"kind": "?", "text": str(d)})
        events.append(ev)
    experiment = md.get("experiment") or next((f.experiment for f in flights if f.experiment), "")
    return {
        "file": str(log.path), "bytes": log.path.stat().st_size, "truncated": log.truncated, "problem": log.problem,
        "profile": log.profile, "library": log.library, "metadata": dict(log.metadata),
        "experiment": experiment, "controllers": ctl_names,
        "duration_s": _s(log.end_ns, origin) if origin is not None else 0.0,
        "messages": log.message_count, "flights": out_flights, "channels": _channel_rows(log, out_flights),
        "events": events,
        "attachments": [{"name": a.name, "media_type": a.media_type, "bytes": len(a.data)} for a in log.attachments],
    }
