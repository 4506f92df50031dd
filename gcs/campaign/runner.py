"""One flight of a campaign: fly its :class:`gcs.api.FlightSpec` and keep its summary.

:func:`run_job` calls :func:`gcs.api.fly` in the calling process (a campaign worker:
the imports are paid once per worker, not once per flight), with stdout and stderr
(file descriptors 1 and 2, so the flight's own children's output too) sent to the run's
output file and a wall-clock deadline (``SIGALRM``: the main thread only).  At the
deadline :class:`RunTimeout` is raised inside the flight, whose ``finally`` blocks close
the link and stop its built-in SITL.

:func:`run_job_isolated` runs the same in a child interpreter (``python -m
gcs.campaign.runner``), for executors whose tasks do not run on a main thread (Dask);
the parent kills the child and its descendants if it overruns the deadline by
:data:`GRACE_S`.

Outcomes (:class:`RunResult.status`): ``ok`` (exit code 0 and a summary), ``failed``
(exit code != 0, or no summary), ``timeout`` (hung), ``crashed`` (an exception, or the
process died).  Only ``ok`` runs enter the tables.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import os
import signal
import subprocess
import sys
import threading
import time
import traceback
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any
from collections.abc import Callable, Iterator

from gcs.api import FlightSpec
from gcs.campaign.plan import Disturbances, Job
from quadrotor.errors import QuadrotorError

__all__ = ["RunResult", "RunTimeout", "run_job", "run_job_isolated", "failed_result", "kill_tree", "GRACE_S",
           "STATUSES", "job_to_json", "job_from_json", "serve", "worker_command", "parse_result_line",
           "RESULT_PREFIX"]

#: Extra wall seconds a hung run gets to stop by itself before its process is killed.
GRACE_S = 30.0

STATUSES = ("ok", "failed", "timeout", "crashed")


class RunTimeout(BaseException):
    """Raised inside a flight at its deadline.  A BaseException, so that no
    ``except Exception`` of the flight stack swallows it; its ``finally`` blocks run."""


@dataclass(frozen=True)
class RunResult:
    """What one flight gave.

    Attributes
    ----------
    key, experiment, controller : str
    run : int
    seed : int
        The flight's SITL seed.
    status : {"ok", "failed", "timeout", "crashed"}
    exit_code : int or None
        ``gcs`` exit code (None when it never returned).
    exit_reason : str or None
        The summary's ``exit_reason``.
    metrics : dict
        The summary's metrics (keys of :data:`gcs.metrics.METRICS`).
    flown_s : float
        Simulated seconds flown (the summary's ``duration_s``).
    wall_s : float
        Wall seconds of the run.
    detail : str
        Why it failed (the last line of its output, the exception, ...); "" when ok.
    output_path, summary_path : str
    log_path : str or None
    lockstep_timeouts : int
        Ticks where the lockstep loop stopped waiting for the vehicle's step and went on
        without it (the summary's ``loop.telemetry_timeouts``): such a run depends on how
        busy the machine was, not only on its seed.
    armed_s : float or None
        Vehicle time of arming (the summary's ``arming`` event): the same for every
        controller of a run when preflight is reproducible.
    """

    key: str
    experiment: str
    controller: str
    run: int
    seed: int
    status: str
    exit_code: int | None
    exit_reason: str | None
    metrics: dict = field(default_factory=dict)
    flown_s: float = 0.0
    wall_s: float = 0.0
    detail: str = ""
    output_path: str = ""
    summary_path: str = ""
    log_path: str | None = None
    lockstep_timeouts: int = 0
    armed_s: float | None = None

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, doc: dict) -> RunResult:
        return cls(**doc)


def failed_result(job: Job, status: str, detail: str, *, wall_s: float = 0.0,
                  exit_code: int | None = None) -> RunResult:
    """A result for a run that gave no usable summary (timeout, crash)."""
    return RunResult(job.key, job.experiment, job.controller, job.run, job.disturbances.seed, status, exit_code,
                     None, {}, 0.0, wall_s, detail, job.output_path, job.summary_path, job.log_path)


def _entry(name: str) -> Callable[..., Any]:
    module, _, func = name.partition(":")
    return getattr(importlib.import_module(module), func)


def _quiet(line: str) -> None:
    """``gcs fly -q``'s console: warnings, failsafes and the landing only."""
    if line.startswith(("[failsafe]", "[warning]", "[interrupt]", "[landed]")):
        print(line, flush=True)


def _fly_job(job: Job) -> int:
    """Fly the job's spec, write its summary; the exit code (2 for a spec the config refuses)."""
    try:
        result = _entry(job.entry)(job.spec, console=_quiet, report=lambda text: print(text, file=sys.stderr))
    except QuadrotorError as exc:
        print(f"gcs: error: {exc}", file=sys.stderr)
        return exc.exit_code
    Path(job.summary_path).write_text(json.dumps(result.to_json(), indent=1))
    if result.exit_reason != "completed":
        print(f"gcs fly: {result.exit_reason} (exit {result.exit_code})" + (f": {result.detail}" if result.detail
                                                                           else ""), file=sys.stderr)
    return result.exit_code


@contextlib.contextmanager
def _redirected(path: str) -> Iterator[Any]:
    """Send fds 1 and 2 (and sys.stdout/sys.stderr) to ``path`` for the duration."""
    for s in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError, AttributeError):
            s.flush()
    with open(path, "w", buffering=1, encoding="utf-8", errors="replace") as f:
        saved = []
        for fd in (1, 2):
            try:
                saved.append((fd, os.dup(fd)))
                os.dup2(f.fileno(), fd)
            except OSError:
                pass
        old = sys.stdout, sys.stderr
        sys.stdout = sys.stderr = f
        try:
            yield f
        finally:
            f.flush()
            sys.stdout, sys.stderr = old
            for fd, copy in saved:
                os.dup2(copy, fd)
                os.close(copy)


class _Deadline:
    """Raise :class:`RunTimeout` ``seconds`` of wall time after entering, unless :meth:`disarm`
    was called first (so a flight that returned just before the deadline still counts).
    Main thread only; elsewhere (no signals) there is no deadline."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self.armed = False
        self._old = None

    def _fire(self, signum, frame) -> None:
        if self.armed:
            self.armed = False
            raise RunTimeout(f"no result after {self.seconds:g} s")

    def disarm(self) -> None:
        self.armed = False

    def __enter__(self) -> _Deadline:
        if threading.current_thread() is threading.main_thread() and hasattr(signal, "setitimer"):
            self._old = signal.signal(signal.SIGALRM, self._fire)
            self.armed = True
            signal.setitimer(signal.ITIMER_REAL, max(self.seconds, 1e-3))
        return self

    def __exit__(self, *exc: Any) -> None:
        self.armed = False
        if self._old is not None:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, self._old)


def _last_line(path: str) -> str:
    try:
        lines = [ln.strip() for ln in Path(path).read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    errors = [ln for ln in lines if "error" in ln.lower() or ln.startswith(("gcs fly:", "[failsafe]"))]
    return (errors or lines or [""])[-1][:300]


def _read_summary(path: str) -> dict | None:
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    return doc if isinstance(doc, dict) else None


def run_job(job: Job) -> RunResult:
    """Fly ``job`` in this process (see the module docstring).

    Returns
    -------
    RunResult
        Never raises for a failing flight: crashes, exit codes and timeouts are results.
    """
    for p in (job.output_path, job.summary_path, job.log_path):
        if p:
            Path(p).parent.mkdir(parents=True, exist_ok=True)
    with contextlib.suppress(FileNotFoundError):
        os.remove(job.summary_path)  # a stale summary must not pass for this run's
    t0 = time.monotonic()
    status, code, detail = "ok", None, ""
    with _redirected(job.output_path) as out:
        try:
            with _Deadline(job.timeout_s) as deadline:
                code = _fly_job(job)
                deadline.disarm()
        except RunTimeout as exc:
            status, detail = "timeout", f"timed out: {exc}"
            print(f"[campaign] {detail}", file=out)
        except Exception as exc:  # noqa: BLE001 - a crashing flight is a result, not the campaign's end
            traceback.print_exc(file=out)
            status, detail = "crashed", f"{type(exc).__name__}: {exc}"
    wall = time.monotonic() - t0
    if status != "ok":
        return failed_result(job, status, detail, wall_s=wall, exit_code=code)
    code = 0 if code is None else int(code)
    summary = _read_summary(job.summary_path)
    if code != 0 or summary is None or summary.get("exit_code", 0) != 0:
        why = _last_line(job.output_path)
        if summary is None:
            why = f"no summary written; {why}" if code == 0 else why
        return RunResult(job.key, job.experiment, job.controller, job.run, job.disturbances.seed, "failed", code,
                         (summary or {}).get("exit_reason"), {}, float((summary or {}).get("duration_s", 0.0)), wall,
                         f"exit {code}: {why}" if why else f"exit {code}", job.output_path, job.summary_path,
                         job.log_path)
    metrics = {k: float(v) for k, v in (summary.get("metrics") or {}).items()}
    log = job.log_path if job.log_path and os.path.exists(job.log_path) else None
    return RunResult(job.key, job.experiment, job.controller, job.run, job.disturbances.seed, "ok", code,
                     summary.get("exit_reason"), metrics, float(summary.get("duration_s", 0.0)), wall, "",
                     job.output_path, job.summary_path, log, *_reproducibility(summary))


def _reproducibility(summary: dict) -> tuple[int, float | None]:
    """``(lockstep timeouts, arming time [s])`` from a summary (see :class:`RunResult`)."""
    loop = summary.get("loop") or {}
    timeouts = loop.get("telemetry_timeouts", 0)
    armed = None
    for e in summary.get("events") or []:
        if isinstance(e, dict) and e.get("kind") == "arming" and e.get("text") == "armed":
            armed = e.get("t_ns", 0) / 1e9
            break
    return (int(timeouts) if isinstance(timeouts, (int, float)) else 0), armed


# --------------------------------------------------------------------------- child interpreter
def job_to_json(job: Job) -> str:
    d = {f.name: getattr(job, f.name) for f in fields(job)}
    d["disturbances"] = asdict(job.disturbances)
    d["spec"] = job.spec.to_json()
    return json.dumps(d)


def job_from_json(text: str) -> Job:
    d = json.loads(text)
    dist = d.pop("disturbances")
    dist = Disturbances(dist["seed"], tuple(dist["wind"]) if dist["wind"] else None,
                        tuple(dist["start_attitude_deg"]) if dist["start_attitude_deg"] else None)
    d["spec"] = FlightSpec.from_json(d["spec"])
    return Job(disturbances=dist, **d)


def _descendants(pid: int) -> list[int]:
    """Child processes of ``pid``, recursively (Linux ``/proc``; empty elsewhere)."""
    out: list[int] = []
    todo = [pid]
    while todo:
        p = todo.pop()
        try:
            tasks = os.listdir(f"/proc/{p}/task")
        except OSError:
            continue
        for t in tasks:
            try:
                kids = [int(c) for c in Path(f"/proc/{p}/task/{t}/children").read_text().split()]
            except (OSError, ValueError):
                continue
            out += kids
            todo += kids
    return out


def kill_tree(pid: int) -> None:
    """Kill ``pid`` and every process it started (they may sit in sessions of their own:
    the built-in SITL does), children first found, then all killed."""
    victims = _descendants(pid) + [pid]
    for p in victims:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(p, signal.SIGKILL)


RESULT_PREFIX = "@@gcs-campaign-result "


def worker_command() -> list[str]:
    """The command line of a worker interpreter (:func:`serve`)."""
    return [sys.executable, "-m", "gcs.campaign.runner"]


def run_job_isolated(job: Job) -> RunResult:
    """Fly ``job`` in a child interpreter (``python -m gcs.campaign.runner``).

    The child applies the job's deadline itself; if it has not answered
    :data:`GRACE_S` later, or dies without answering, the run is a timeout or a crash.
    """
    t0 = time.monotonic()
    Path(job.output_path).parent.mkdir(parents=True, exist_ok=True)
    proc = subprocess.Popen(worker_command(), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        out, err = proc.communicate(job_to_json(job) + "\n", timeout=job.timeout_s + GRACE_S)
    except subprocess.TimeoutExpired:
        kill_tree(proc.pid)
        proc.communicate()
        return failed_result(job, "timeout", f"killed after {job.timeout_s + GRACE_S:g} s without an answer",
                             wall_s=time.monotonic() - t0)
    for line in out.splitlines():
        result = parse_result_line(line)
        if result is not None:
            return result
    tail = (err.strip().splitlines() or [""])[-1]
    return failed_result(job, "crashed", f"the run's interpreter exited with code {proc.returncode}: {tail}",
                         wall_s=time.monotonic() - t0)


def parse_result_line(line: str) -> RunResult | None:
    """The :class:`RunResult` of a worker's result line, or None for any other line."""
    if not line.startswith(RESULT_PREFIX):
        return None
    return RunResult.from_json(json.loads(line[len(RESULT_PREFIX):]))


def serve() -> int:
    """A worker: read one job (JSON) per line on stdin, fly it, answer one result line on stdout."""
    # Ctrl-C at the terminal reaches every process of the group: the campaign decides.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    out = os.fdopen(os.dup(1), "w", buffering=1)  # the flights' fd 1 goes to their files
    for line in sys.stdin:
        if not line.strip():
            continue
        result = run_job(job_from_json(line))
        out.write(RESULT_PREFIX + json.dumps(result.to_json()) + "\n")
        out.flush()
    return 0


if __name__ == "__main__":
    sys.exit(serve())
