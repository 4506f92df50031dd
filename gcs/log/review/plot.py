"""``gcs log plot``: one flight of a log as a PNG (matplotlib, Agg; a dependency of the main install).

Six panels, SI units on every axis: altitude vs reference, x-y track vs reference,
thrust, the three angular-acceleration commands, attitude (in degrees), velocities
vs reference.  The state drawn is the truth in a simulation log (what the metrics
use), with the estimate dotted; the estimate in a flight log.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from gcs.errors import LogError
from gcs.log import topics as T
from gcs.log.mcap.reader import read_log
from gcs.log.review.flights import METRIC_TOPICS, flight_arrays, split_flights

__all__ = ["MATPLOTLIB_HINT", "PANELS", "plot_log"]

#: Panel titles, in the order they are drawn (row by row).
PANELS = ("Altitude", "x-y track", "Thrust command", "Angular acceleration commands", "Attitude", "Velocities")

#: What a user whose installation lacks matplotlib (a dependency of quadrotor-gcs since the review must work
#: after the main install) is told.
MATPLOTLIB_HINT = ("gcs log plot needs matplotlib, a dependency of quadrotor-gcs missing here: reinstall it "
                   "(pip install -e . in a checkout) or pip install matplotlib")


def _figure_class() -> Any:
    try:
        from matplotlib.figure import Figure
    except ImportError:
        raise LogError(MATPLOTLIB_HINT) from None
    return Figure


def _read_flight(path: str | os.PathLike, index: int) -> tuple[Any, Any]:
    """The log with the messages of its ``index``-th flight only (read as a stream: big logs fit), and that flight."""
    keep: dict[str, list] = {}
    announced: list[tuple[int, bytes]] = []

    def sink(topic: str, t: int, data: bytes) -> None:
        if topic == T.FLIGHT:
            announced.append((t, data))
            return
        if len(announced) - 1 == index or (index == 0 and not announced):
            keep.setdefault(topic, []).append((t, data))

    log = read_log(path, METRIC_TOPICS, sink=sink)
    n = max(len(announced), 1)
    if index >= n:
        raise LogError(f"{log.path}: no flight {index}: the log has {n} (0 .. {n - 1})")
    log.messages = {topic: sorted(msgs, key=lambda m: m[0]) for topic, msgs in keep.items()}
    if announced:
        log.messages[T.FLIGHT] = [announced[index]]
    fl = split_flights(log)[0]
    fl.index = index
    return log, fl


def _position_panels(axes: Any, a: dict) -> None:
    """Altitude vs reference and the x-y track."""
    s, t_s, r, t_r = a["state"], a["t_state"], a["reference"], a["t_reference"]
    est, t_e = a["estimate"], a["t_estimate"]
    truth = bool(a["truth"])
    what = "truth" if truth else "estimate"
    ax = axes[0, 0]
    if s.shape[0]:
        ax.plot(t_s, s[:, 2], label=f"z ({what})")
    if truth and est.shape[0]:
        ax.plot(t_e, est[:, 2], ":", lw=0.8, label="z (estimate)")
    if r.shape[0]:
        ax.plot(t_r, r[:, 2], "--", label="z reference")
    ax.set(title=PANELS[0], xlabel="time [s]", ylabel="altitude z (up) [m]")
    ax = axes[0, 1]
    if s.shape[0]:
        ax.plot(s[:, 1], s[:, 0], label=what)
    if r.shape[0]:
        ax.plot(r[:, 1], r[:, 0], "--", label="reference")
    ax.set(title=PANELS[1], xlabel="y east [m]", ylabel="x north [m]")
    ax.set_aspect("equal", adjustable="datalim")


def _command_panels(axes: Any, a: dict) -> None:
    """Thrust and the three angular-acceleration commands."""
    u, t_u = a["command"], a["t_command"]
    ax = axes[1, 0]
    if u.shape[0]:
        ax.plot(t_u, u[:, 0], label="thrust")
    ax.set(title=PANELS[2], xlabel="time [s]", ylabel="thrust [N]")
    ax = axes[1, 1]
    for i, name in ((1, "roll"), (2, "pitch"), (3, "yaw")):
        if u.shape[0]:
            ax.plot(t_u, u[:, i], lw=0.8, label=name)
    ax.set(title=PANELS[3], xlabel="time [s]", ylabel="angular acceleration [rad/s$^2$]")


def _state_panels(axes: Any, a: dict) -> None:
    """Attitude (degrees) and velocities vs reference."""
    s, t_s, r, t_r = a["state"], a["t_state"], a["reference"], a["t_reference"]
    ax = axes[2, 0]
    for i, name in ((6, "roll"), (7, "pitch"), (8, "yaw")):
        if s.shape[0]:
            ax.plot(t_s, np.degrees(s[:, i]), lw=0.8, label=name)
    ax.set(title=PANELS[4], xlabel="time [s]", ylabel="angle [deg]")
    ax = axes[2, 1]
    for i, name in ((3, "vx (north)"), (4, "vy (east)"), (5, "vz (up)")):
        if s.shape[0]:
            line, = ax.plot(t_s, s[:, i], lw=0.8, label=name)
            if r.shape[0]:
                ax.plot(t_r, r[:, i], "--", lw=0.8, color=line.get_color())
    ax.set(title=PANELS[5] + " (dashed: reference)", xlabel="time [s]", ylabel="velocity [m/s]")


def plot_log(path: str | os.PathLike, out: str | os.PathLike, *, flight: int = 0, dpi: int = 100) -> dict:
    """Draw flight ``flight`` (its position in the log, 0 = first) of a log into ``out`` (PNG).

    Returns
    -------
    dict
        ``file``, ``out``, ``flight`` (label), ``panels`` (titles), ``truncated``, ``problem``.

    Raises
    ------
    LogError
        matplotlib missing, no such flight, nothing to plot, or ``out`` not writable.
    """
    Figure = _figure_class()
    if flight < 0:
        raise LogError(f"{path}: flight must be >= 0, got {flight}")
    log, fl = _read_flight(path, flight)
    a = flight_arrays(log, fl)
    if a["state"].shape[0] == 0 and a["command"].shape[0] == 0:
        raise LogError(f"{log.path}: flight {fl.label} has no state or command messages to plot")

    fig = Figure(figsize=(13, 12), layout="constrained")
    axes = fig.subplots(3, 2)
    title = f"{Path(log.path).name}: flight {fl.label}" + (f" ({fl.experiment})" if fl.experiment else "")
    if log.truncated:
        title += " - TRUNCATED log"
    fig.suptitle(title)
    _position_panels(axes, a)
    _command_panels(axes, a)
    _state_panels(axes, a)
    for ax in axes.flat:
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="best", fontsize="small")
    target = Path(out)
    try:
        fig.savefig(target, dpi=dpi, format="png")
    except OSError as exc:
        raise LogError(f"{target}: cannot write the figure: {exc.strerror or exc}") from None
    return {"file": str(log.path), "out": str(target), "flight": fl.label,
            "panels": [ax.get_title() for ax in axes.flat],
            "truncated": log.truncated, "problem": log.problem}
