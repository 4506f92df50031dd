"""The campaign's figures (PNG), like the paper's Figs. 4-22, drawn from the flight logs.

Per experiment, into ``figures/<experiment>/``:

* ``<controller>.png``: one representative run per controller (the completed run with
  the lowest index), the six panels of ``gcs log plot`` (:func:`gcs.log.review.plot.plot_log`):
  altitude vs reference, x-y track, thrust, angular-acceleration commands, attitude,
  velocities (Figs. 4-6, 8-22 show these per controller);
* ``overlay_altitude.png``: altitude of every controller against the reference (Fig. 7);
* ``overlay_control.png``: thrust and the three angular-acceleration commands (Figs. 4B,
  5B, 6B, 8B-10B, 12, 16, 20);
* ``overlay_track.png``: x-y track against the reference (Figs. 11, 15, 19);
* ``overlay_attitude.png`` and ``overlay_velocity.png``: roll, pitch, yaw and vx, vy, vz
  (Figs. 13, 14, 17, 18, 21, 22).

The logs are read with :func:`gcs.log.mcap.reader.read_log` and
:func:`gcs.log.review.flights.flight_arrays` (the estimate the ground station flew on; a
simulation log's truth).  matplotlib is optional: without it (or without logs) the
figures are skipped and :func:`draw_figures` says why.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any
from collections.abc import Sequence

import numpy as np

from gcs.errors import LogError
from gcs.log.mcap.reader import read_log
from gcs.log.review.flights import METRIC_TOPICS, flight_arrays, split_flights
from gcs.log.review.plot import plot_log

__all__ = ["draw_figures", "representative_runs", "overlay_figures", "OVERLAYS"]

OVERLAYS = ("overlay_altitude", "overlay_control", "overlay_track", "overlay_attitude", "overlay_velocity")


def representative_runs(results: Sequence[Any]) -> dict[tuple[str, str], Any]:
    """``(experiment, controller) -> result`` of the completed run with a log and the lowest index."""
    out: dict[tuple[str, str], Any] = {}
    for r in sorted(results, key=lambda r: (r.experiment, r.controller, r.run)):
        if r.ok and r.log_path and Path(r.log_path).exists():
            out.setdefault((r.experiment, r.controller), r)
    return out


def _arrays(path: str) -> dict:

    log = read_log(path, METRIC_TOPICS)
    flights = split_flights(log)
    return flight_arrays(log, flights[0])


def _figure(rows: int, cols: int, title: str) -> tuple[Any, Any]:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.5 * cols, 3.6 * rows), layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, cols))
    fig.suptitle(title)
    return fig, axes


def _finish(fig: Any, axes: Any, path: Path) -> str:
    for ax in np.ravel(axes):
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="best", fontsize="small")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90, format="png")
    return str(path)


def overlay_figures(experiment: str, arrays: dict[str, dict], out_dir: Path) -> list[str]:
    """The overlay figures of one experiment from ``controller -> flight_arrays``; returns the files written."""
    files = []
    ref = next((a for a in arrays.values() if a["reference"].shape[0]), None)
    what = "truth" if any(bool(a["truth"]) for a in arrays.values()) else "estimate"

    fig, axes = _figure(1, 1, f"{experiment}: altitude, every controller ({what})")
    ax = axes[0]
    if ref is not None:
        ax.plot(ref["t_reference"], ref["reference"][:, 2], "k--", lw=1.0, label="reference")
    for ctl, a in arrays.items():
        if a["state"].shape[0]:
            ax.plot(a["t_state"], a["state"][:, 2], lw=1.0, label=ctl)
    ax.set(xlabel="time [s]", ylabel="altitude z (up) [m]")
    files.append(_finish(fig, axes, out_dir / "overlay_altitude.png"))

    fig, axes = _figure(2, 2, f"{experiment}: control signals")
    names = ("thrust [N]", "roll angular acceleration [rad/s$^2$]", "pitch angular acceleration [rad/s$^2$]",
             "yaw angular acceleration [rad/s$^2$]")
    for i, ax in enumerate(np.ravel(axes)):
        for ctl, a in arrays.items():
            if a["command"].shape[0]:
                ax.plot(a["t_command"], a["command"][:, i], lw=0.7, label=ctl)
        ax.set(xlabel="time [s]", ylabel=names[i])
    files.append(_finish(fig, axes, out_dir / "overlay_control.png"))

    fig, axes = _figure(1, 1, f"{experiment}: x-y track ({what})")
    ax = axes[0]
    if ref is not None:
        ax.plot(ref["reference"][:, 1], ref["reference"][:, 0], "k--", lw=1.0, label="reference")
    for ctl, a in arrays.items():
        if a["state"].shape[0]:
            ax.plot(a["state"][:, 1], a["state"][:, 0], lw=1.0, label=ctl)
    ax.set(xlabel="y east [m]", ylabel="x north [m]")
    ax.set_aspect("equal", adjustable="datalim")
    files.append(_finish(fig, axes, out_dir / "overlay_track.png"))

    for name, cols, labels, scale, unit in (
            ("overlay_attitude", (6, 7, 8), ("roll", "pitch", "yaw"), 180.0 / np.pi, "deg"),
            ("overlay_velocity", (3, 4, 5), ("vx (north)", "vy (east)", "vz (up)"), 1.0, "m/s")):
        fig, axes = _figure(3, 1, f"{experiment}: {name.split('_')[1]} ({what}; dashed: reference)")
        for ax, col, label in zip(np.ravel(axes), cols, labels, strict=True):
            for ctl, a in arrays.items():
                if a["state"].shape[0]:
                    ax.plot(a["t_state"], a["state"][:, col] * scale, lw=0.8, label=ctl)
            if name == "overlay_velocity" and ref is not None:
                ax.plot(ref["t_reference"], ref["reference"][:, col], "k--", lw=0.8, label="reference")
            ax.set(xlabel="time [s]", ylabel=f"{label} [{unit}]")
        files.append(_finish(fig, axes, out_dir / f"{name}.png"))
    return files


def _representative_figure(log_path: str, target: str, key: str) -> tuple[list[str], list[str]]:
    """One task: the six-panel figure of one run."""

    Path(target).parent.mkdir(parents=True, exist_ok=True)
    try:
        plot_log(log_path, target)
    except (LogError, OSError, ValueError) as exc:
        return [], [f"{key}: {exc}"]
    return [target], []


def _overlay_task(experiment: str, logs: dict[str, str], out_dir: str) -> tuple[list[str], list[str]]:
    """One task: the overlay figures of one experiment."""
    arrays, problems = {}, []
    for ctl, path in logs.items():
        try:
            arrays[ctl] = _arrays(path)
        except (LogError, OSError, ValueError) as exc:
            problems.append(f"{experiment}/{ctl}: {exc}")
    if not arrays:
        return [], problems
    return overlay_figures(experiment, arrays, Path(out_dir)), problems


_TASKS = {"representative": _representative_figure, "overlay": _overlay_task}


def _run_tasks(tasks: Sequence[tuple[str, list]]) -> list[tuple[list[str], list[str]]]:
    return [_TASKS[name](*args) for name, args in tasks]


def _in_children(tasks: Sequence[tuple[str, list]], workers: int) -> list[tuple[list[str], list[str]]]:
    """Run ``tasks`` split over ``workers`` child interpreters (``python -m gcs.campaign.figures``)."""
    import json
    import subprocess
    import sys
    from concurrent.futures import ThreadPoolExecutor

    chunks = [list(tasks[i::workers]) for i in range(min(workers, len(tasks)))]

    def run(chunk: list) -> list:
        proc = subprocess.run([sys.executable, "-m", "gcs.campaign.figures"], input=json.dumps(chunk),
                              capture_output=True, text=True)
        for line in reversed(proc.stdout.splitlines()):
            if line.startswith("["):
                return [tuple(x) for x in json.loads(line)]
        why = (proc.stderr.strip().splitlines() or [f"exit code {proc.returncode}"])[-1]
        return [([], [f"figure task {name} failed: {why}"]) for name, _ in chunk]

    with ThreadPoolExecutor(len(chunks)) as pool:
        return [r for rs in pool.map(run, chunks) for r in rs]


def draw_figures(results: Sequence[Any], out_dir: str | Path, *, workers: int = 1) -> dict:
    """Every figure of the campaign into ``out_dir/figures``.

    Parameters
    ----------
    results : sequence of RunResult
    out_dir : path
    workers : int
        Draw in this many processes (matplotlib is slow: seconds a figure).

    Returns
    -------
    dict
        ``{"files": [paths], "skipped": reason or "", "problems": [...]}``.  A log that cannot
        be read is reported in ``problems`` and left out; it never stops the campaign.
    """
    import importlib.util

    if importlib.util.find_spec("matplotlib") is None:
        return {"files": [], "skipped": "matplotlib is not installed (a dependency of quadrotor-gcs: "
                                        "pip install -e . or pip install matplotlib)", "problems": []}
    reps = representative_runs(results)
    if not reps:
        return {"files": [], "skipped": "no completed run has a flight log", "problems": []}
    base = Path(out_dir) / "figures"
    tasks: list[tuple[Any, tuple]] = []
    for exp in sorted({e for e, _ in reps}):
        mine = {ctl: r for (e, ctl), r in sorted(reps.items()) if e == exp}
        for ctl, r in mine.items():
            tasks.append(("representative", [r.log_path, str(base / exp / f"{ctl}.png"), r.key]))
        tasks.append(("overlay", [exp, {c: r.log_path for c, r in mine.items()}, str(base / exp)]))
    if workers > 1 and len(tasks) > 1:
        done = _in_children(tasks, workers)
    else:
        done = _run_tasks(tasks)
    files = [f for fs, _ in done for f in fs]
    problems = [p for _, ps in done for p in ps]
    return {"files": files, "skipped": "", "problems": problems}


if __name__ == "__main__":
    import json
    import sys

    print(json.dumps(_run_tasks(json.loads(sys.stdin.read()))))
