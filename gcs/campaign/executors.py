"""Where the flights run: a small executor interface with two backends.

An :class:`Executor` takes jobs (:meth:`Executor.submit`) and yields their
:class:`gcs.campaign.runner.RunResult` as they complete (:meth:`Executor.as_completed`);
the order of completion does not matter to the tables, which sort by run.

* :class:`LocalExecutor`: ``workers`` long-lived worker interpreters on this machine
  (``python -m gcs.campaign.runner``, jobs and results as JSON lines over pipes), each
  flying one job at a time in its main thread (:func:`gcs.campaign.runner.run_job`:
  imports paid once per worker).  A worker that dies is reported as a crashed run and
  replaced; one that overruns a job's deadline by :data:`gcs.campaign.runner.GRACE_S` is
  killed with everything it started, reported as a timeout, and replaced.
* :class:`DaskExecutor`: a Dask ``distributed`` cluster (``pip install
  'quadrotor-gcs[dask]'``): the scheduler at ``--scheduler ADDRESS``, or a
  ``LocalCluster`` of ``workers`` single-threaded worker processes.  Dask tasks run on
  worker threads, so each flight runs in a child interpreter
  (:func:`gcs.campaign.runner.run_job_isolated`).  Remote workers need this package
  installed and the output folder on a shared file system.
"""

from __future__ import annotations

import contextlib
import os
import select
import subprocess
import time
from abc import ABC, abstractmethod
from collections import deque
from typing import Any
from collections.abc import Iterator

from gcs.campaign.errors import CampaignError
from gcs.campaign.plan import Job
from gcs.campaign.runner import (
    GRACE_S,
    RunResult,
    failed_result,
    job_to_json,
    kill_tree,
    parse_result_line,
    run_job_isolated,
    worker_command,
)

__all__ = ["Executor", "LocalExecutor", "DaskExecutor", "make_executor", "EXECUTORS", "DASK_HINT"]

EXECUTORS = ("local", "dask")

DASK_HINT = "the dask executor needs dask.distributed: pip install 'quadrotor-gcs[dask]'"


class Executor(ABC):
    """Runs campaign jobs; use as a context manager."""

    @abstractmethod
    def submit(self, job: Job) -> None:
        """Queue ``job``."""

    @abstractmethod
    def as_completed(self) -> Iterator[RunResult]:
        """Yield the result of every submitted job, as each completes."""

    def close(self) -> None:  # noqa: B027  optional hook, the default does nothing
        """Stop the workers (idempotent)."""

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


# --------------------------------------------------------------------------- local processes
class _Worker:
    """A worker interpreter (:func:`gcs.campaign.runner.serve`) and the job it is flying."""

    def __init__(self, errors: Any) -> None:
        self.proc = subprocess.Popen(worker_command(), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=errors, bufsize=0)
        self.fd = self.proc.stdout.fileno()
        self.buffer = b""
        self.job: Job | None = None
        self.started = 0.0

    def give(self, job: Job) -> None:
        self.job = job
        self.started = time.monotonic()
        self.proc.stdin.write((job_to_json(job) + "\n").encode())
        self.proc.stdin.flush()

    def deadline(self, grace_s: float) -> float:
        assert self.job is not None
        return self.started + self.job.timeout_s + grace_s

    def read(self) -> tuple[list[RunResult], bool]:
        """The results that arrived, and whether the worker is still there (False at EOF)."""
        try:
            data = os.read(self.fd, 1 << 16)
        except OSError:
            data = b""
        self.buffer += data
        results = []
        *lines, self.buffer = self.buffer.split(b"\n")
        for line in lines:
            r = parse_result_line(line.decode(errors="replace"))
            if r is not None:
                results.append(r)
        return results, bool(data)

    def kill(self) -> None:
        if self.proc.poll() is None:
            kill_tree(self.proc.pid)
        self._reap()

    def stop(self) -> None:
        with contextlib.suppress(OSError):
            self.proc.stdin.close()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            kill_tree(self.proc.pid)
        self._reap()

    def _reap(self) -> None:
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.proc.wait(5)
        for f in (self.proc.stdin, self.proc.stdout):
            with contextlib.suppress(OSError):
                f.close()


class LocalExecutor(Executor):
    """A pool of worker interpreters on this machine (see the module docstring).

    Parameters
    ----------
    workers : int
        Number of worker processes (>= 1).
    errors : file or None
        Where the workers' own stderr goes (the flights' goes to their output files);
        default: this process's stderr.
    grace_s : float
        How long past a job's deadline a worker may stay silent before it is killed.
    """

    def __init__(self, workers: int, *, errors: Any = None, grace_s: float = GRACE_S) -> None:
        if workers < 1:
            raise CampaignError("--workers", "", f"must be >= 1, got {workers}")
        self.workers = workers
        self.grace_s = grace_s
        self._errors = errors
        self._pending: deque[Job] = deque()
        self._pool: list[_Worker] = []
        self._closed = False

    def submit(self, job: Job) -> None:
        self._pending.append(job)

    def _assign(self) -> None:
        for w in self._pool:
            if w.job is None and self._pending:
                w.give(self._pending.popleft())
        while self._pending and len(self._pool) < self.workers:
            w = _Worker(self._errors)
            self._pool.append(w)
            w.give(self._pending.popleft())

    def as_completed(self) -> Iterator[RunResult]:
        while self._pending or any(w.job is not None for w in self._pool):
            self._assign()
            busy = [w for w in self._pool if w.job is not None]
            wait_s = max(0.0, min(w.deadline(self.grace_s) for w in busy) - time.monotonic())
            ready, _, _ = select.select([w.fd for w in busy], [], [], wait_s)
            now = time.monotonic()
            for w in busy:
                job = w.job
                assert job is not None
                alive = True
                if w.fd in ready:
                    results, alive = w.read()
                    if results:
                        w.job = None
                        yield from results
                        continue
                if not alive:
                    w.kill()
                    self._pool.remove(w)
                    yield failed_result(job, "crashed", f"the worker process died (exit code {w.proc.returncode})",
                                        wall_s=now - w.started)
                elif now >= w.deadline(self.grace_s):
                    w.kill()
                    self._pool.remove(w)
                    yield failed_result(job, "timeout",
                                        f"killed after {job.timeout_s + self.grace_s:g} s without an answer",
                                        wall_s=now - w.started)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._pending.clear()
        for w in self._pool:
            if w.job is not None:
                w.kill()
            else:
                w.stop()
        self._pool.clear()


# --------------------------------------------------------------------------- dask
def _distributed() -> Any:
    try:
        import distributed
    except ImportError:
        raise CampaignError("--executor dask", "", DASK_HINT) from None
    return distributed


class DaskExecutor(Executor):
    """Jobs as Dask tasks (see the module docstring).

    Parameters
    ----------
    scheduler : str or None
        Address of a running scheduler (``tcp://host:8786``); None starts a
        ``LocalCluster`` of ``workers`` processes with one thread each.
    workers : int
        Workers of the local cluster.
    """

    def __init__(self, scheduler: str | None = None, workers: int = 1) -> None:
        distributed = _distributed()
        self._distributed = distributed
        self.cluster = None
        try:
            if scheduler is None:
                self.cluster = distributed.LocalCluster(n_workers=max(1, workers), threads_per_worker=1,
                                                        processes=True, dashboard_address=None)
                self.client = distributed.Client(self.cluster)
            else:
                self.client = distributed.Client(scheduler, timeout=30)
        except (OSError, TimeoutError, ValueError) as exc:
            self.close()
            raise CampaignError("--scheduler", "",
                                f"cannot reach the Dask scheduler {scheduler or '(local)'}: {exc}") from None
        self._futures: list[Any] = []
        self._jobs: dict[str, Job] = {}

    def submit(self, job: Job) -> None:
        fut = self.client.submit(run_job_isolated, job,
                                 key=f"gcs-campaign-{job.key}-{os.getpid()}-{len(self._futures)}", pure=False)
        self._jobs[fut.key] = job
        self._futures.append(fut)

    def as_completed(self) -> Iterator[RunResult]:
        for fut in self._distributed.as_completed(self._futures):
            job = self._jobs[fut.key]
            try:
                yield fut.result()
            except Exception as exc:  # noqa: BLE001 - a task that died on its worker is a crashed run
                yield failed_result(job, "crashed", f"the Dask task failed: {type(exc).__name__}: {exc}")
        self._futures = []

    def close(self) -> None:
        client = getattr(self, "client", None)
        if client is not None:
            client.close()
            self.client = None
        if self.cluster is not None:
            self.cluster.close()
            self.cluster = None


def make_executor(kind: str, workers: int, scheduler: str | None = None) -> Executor:
    """The executor named ``kind`` (``local`` or ``dask``).

    Raises
    ------
    CampaignError
        Unknown kind, ``--scheduler`` without ``--executor dask``, or Dask missing.
    """
    if kind == "local":
        if scheduler is not None:
            raise CampaignError("--scheduler", "", "only with --executor dask")
        return LocalExecutor(workers)
    if kind == "dask":
        return DaskExecutor(scheduler, workers)
    raise CampaignError("--executor", "", f"unknown executor {kind!r} (choose from {', '.join(EXECUTORS)})")
