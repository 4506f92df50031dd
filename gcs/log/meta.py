"""What a log says about its run: the ``flight`` metadata, the config and the designed gains.

Attachments written by :func:`write_run_header`:

* ``config.json`` — the resolved config (``Config.raw`` after overrides such as
  ``--matrices``), from which ``gcs log metrics`` rebuilds the config;
* ``config.toml`` — the config file as read, when there is one;
* ``gains/<controller>.json`` — :func:`designed_gains` of each controller flown.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import os
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from gcs import __version__
from gcs.config import resolve_config_path

__all__ = ["default_log_path", "LOG_DIR", "designed_gains", "run_attachments", "run_metadata", "utc_stamp",
           "write_run_header"]


def utc_stamp(now: _dt.datetime | None = None) -> str:
    """``YYYYmmddTHHMMSSZ`` of now (or ``now``) in UTC, for file names."""
    now = now or _dt.datetime.now(_dt.UTC)
    return now.astimezone(_dt.UTC).strftime("%Y%m%dT%H%M%SZ")


def _settled_rows(table: np.ndarray) -> int:
    """Leading rows after which every row equals the last one."""
    rows = table.reshape(table.shape[0], -1)
    idx = np.flatnonzero(np.any(rows != rows[-1], axis=1))
    return int(idx[-1]) + 2 if idx.size else 1


def designed_gains(controller: Any) -> dict:
    """The designed gains of a controller as JSON-able data.

    LOC: the Riccati gain tables ``F_<subsystem>[j - 1]`` (gain row with j steps to go), cut
    where the recursion reached its fixed point (later rows equal the last); NLSOC: the
    weights Q, R, H of each affine subsystem (its gain is evaluated on line); PD: the gains.
    A finite-horizon controller also gives its horizon, what follows it and the fallback's gains.
    """
    out: dict[str, Any] = {"controller": getattr(controller, "name", type(controller).__name__)}
    gains = getattr(controller, "gains", None)
    if gains is not None and dataclasses.is_dataclass(gains):
        out["kind"] = "pd"
        out["gains"] = dataclasses.asdict(gains)
        return out
    law = getattr(controller, "law", None)
    design = getattr(law, "design", None)
    out["horizon_steps"] = getattr(controller, "horizon_steps", None)
    out["after_horizon"] = getattr(controller, "after", None)
    if design is not None and hasattr(design, "F_z"):
        tables = {n: np.asarray(getattr(design, f"F_{n}")) for n in ("z", "psi", "y_phi", "x_theta")}
        settled = max(_settled_rows(t) for t in tables.values())
        out["kind"] = "loc"
        out["settled_steps"] = settled
        out["note"] = ("u = -F[j - 1] x with j steps to go (j = 1 is the last step of the horizon); "
                       "rows from settled_steps on equal the last row")
        out["tables"] = {n: t[:settled].reshape(settled, -1).tolist() for n, t in tables.items()}
    elif design is not None and hasattr(design, "z_psi"):
        out["kind"] = "nlsoc"
        out["gravity_compensated"] = bool(getattr(design, "gravity_compensated", True))
        out["subsystems"] = {}
        for n in ("z_psi", "y_phi", "x_theta"):
            sub = getattr(design, n)
            out["subsystems"][n] = {"Q": np.asarray(sub.Q).tolist(), "R": np.asarray(sub.R).tolist(),
                                    "H": np.asarray(sub.H).tolist()}
    else:
        out["kind"] = "unknown"
    fallback = getattr(controller, "fallback", None)
    if fallback is not None:
        out["fallback"] = designed_gains(fallback)
    return out


def run_metadata(config: Any, controllers: Iterable[str], **extra: Any) -> dict[str, str]:
    """The ``flight`` metadata record: controller(s), experiment, config, software version, start time."""
    md = {
        "controller": ",".join(controllers),
        "experiment": config.experiment.name,
        "config": str(config.source),
        "software_version": __version__,
        "start_time_utc": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "command_line": " ".join(sys.argv),
        "ts_s": repr(config.experiment.ts_s),
        "matrices": config.experiment.matrices,
    }
    md.update({k: "" if v is None else str(v) for k, v in extra.items()})
    return md


def run_attachments(config: Any, designed: Mapping[str, Any] = {}) -> list[tuple[str, str, bytes]]:
    """``(name, media type, data)`` of ``config.json``, ``config.toml`` (if readable) and ``gains/<name>.json``."""
    out = [("config.json", "application/json", json.dumps(dict(config.raw), indent=1).encode())]
    try:
        text = resolve_config_path(config.source).read_bytes()
    except (OSError, ValueError, TypeError):  # ConfigError is a ValueError: no file behind the source
        text = None
    if text is not None:
        out.append(("config.toml", "application/toml", text))
    for name, ctl in designed.items():
        out.append((f"gains/{name}.json", "application/json", json.dumps(designed_gains(ctl)).encode()))
    return out


def write_run_header(log: Any, config: Any, controllers: Iterable[str], designed: Mapping[str, Any] = {},
                     **extra: Any) -> None:
    """Write the ``flight`` metadata and the config and gains attachments to ``log``."""
    controllers = list(controllers)
    log.metadata("flight", run_metadata(config, controllers, **extra))
    for name, media, data in run_attachments(config, designed):
        log.attachment(name, media, data)


#: Where flight and simulation logs go by default.
LOG_DIR = "logs"


def default_log_path(controller: str, experiment: str, directory: str | os.PathLike = LOG_DIR) -> Path:
    """``logs/<UTC time>_<controller>_<experiment>.mcap`` (``_2``, ``_3`` ... when taken)."""
    def safe(s: str) -> str:
        return "".join(c if c.isalnum() or c in "-_." else "-" for c in s)

    base = Path(directory) / f"{utc_stamp()}_{safe(controller)}_{safe(experiment)}"
    p, i = base.with_suffix(".mcap"), 2
    while p.exists():
        p, i = Path(f"{base}_{i}.mcap"), i + 1
    return p
