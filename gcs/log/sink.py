"""Where records go: into a log of this process (:class:`InlineSink`) or of a writer process (:class:`BackgroundSink`).

Both take lists of records (:mod:`gcs.log.records`) with :meth:`put_many` — or of records in
their wire form (:mod:`gcs.log.framing`) with :meth:`put_wire`, what the flight recorder
builds on the control loop's path — and finish the file on :meth:`close`, returning
``{"messages", "bytes", "flights", "undecodable", "dropped"}``.

:class:`BackgroundSink` hands the records, framed (:mod:`gcs.log.framing`), to
``python -m gcs.log.worker``, so that the JSON formatting, the decoding of link frames, the
compression and the disk never run on the producer's interpreter.  Should the producer die
(even by SIGKILL), the writer sees its input end, writes what it has and finishes the file.
When the writer falls behind, ``overflow`` decides:

* ``"drop"`` (``gcs fly``): the records are written to a non-blocking pipe from the
  producer's thread — the control loop pays for one pickling and one ``os.write`` — and kept
  in a local buffer of up to :data:`MAX_BACKLOG_BYTES` while the pipe is full; beyond that they
  are dropped and counted: the loop never waits for the log.  The writer runs niced; the pipe
  is enlarged to :data:`PIPE_BYTES` so that a backlog while it is starved of CPU sits in the
  kernel, not here: records handed over survive a SIGKILL of the producer.
* ``"wait"`` (``gcs sim``): every record reaches the file.  A sender thread writes the
  frames, so the simulation neither waits for the writer to start nor for each block to be
  taken; it waits only when ``max_pending`` frames are queued.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import queue
import subprocess
import sys
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from gcs.errors import LogError
from gcs.log.foxglove_encoder import FoxgloveEncoder
from gcs.log.framing import from_wire, pack, pack_wire, read_frame
from gcs.log.mcap.writer import check_writable
from gcs.log.records import Attachment, CloseLog, FlightStart, LogDone, LogFailed, Metadata, OpenLog
from gcs.log.writer import FlightLog

__all__ = ["MAX_BACKLOG_BYTES", "PIPE_BYTES", "WRITER_NICE", "BackgroundSink", "InlineSink", "spawn_writer"]

#: Records kept here while the writer process cannot take them, before they are dropped [bytes].
MAX_BACKLOG_BYTES = 8 << 20
#: Size asked for the pipe to the writer (Linux; capped by /proc/sys/fs/pipe-max-size) [bytes].
PIPE_BYTES = 1 << 20
#: Niceness of a writer beside a real-time loop (the loop, and a SITL beside it, come first).
WRITER_NICE = 10

_STOPPED = "the log writer process stopped early"


class _SinkBase:
    """What both sinks share: the header conveniences and the context manager."""

    path: Path
    stats: dict

    def put_many(self, records: list) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def put_wire(self, wire: list) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def close(self) -> dict:  # pragma: no cover - overridden
        raise NotImplementedError

    def put(self, record: Any) -> None:
        self.put_many([record])

    def metadata(self, name: str, data: Mapping[str, Any]) -> None:
        """An MCAP metadata record (values as str)."""
        self.put_many([Metadata(name, {str(k): str(v) for k, v in data.items()})])

    def attachment(self, name: str, media_type: str, data: bytes | str) -> None:
        """An MCAP attachment (str as UTF-8)."""
        self.put_many([Attachment(name, media_type, data.encode() if isinstance(data, str) else bytes(data))])

    def __enter__(self) -> Any:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            self.close()
        except LogError:
            if exc_type is None:
                raise


class InlineSink(_SinkBase):
    """Records written at once into a :class:`FlightLog` of this process (tests, tools, in-process simulation)."""

    def __init__(self, log: FlightLog) -> None:
        self.log = log
        self.path = log.path
        self.encoder = FoxgloveEncoder(log)
        self.dropped = 0
        self.stats: dict = {}

    @property
    def flight_count(self) -> int:
        """Flights in the file so far."""
        return self.log.flight_count

    def put_many(self, records: list) -> None:
        self.encoder.write_all(records)

    def put_wire(self, wire: list) -> None:
        self.encoder.write_all(map(from_wire, wire))

    def close(self) -> dict:
        self.log.close()
        self.stats = {"messages": self.log.message_count, "bytes": self.path.stat().st_size,
                      "flights": self.log.flight_count, "undecodable": self.encoder.undecodable, "dropped": 0}
        return self.stats


def spawn_writer(path: Path) -> subprocess.Popen:
    """Start ``python -m gcs.log.worker`` (stdin/stdout pipes) for the log at ``path``.

    Its own session: a Ctrl-C at the terminal reaches this process only, which decides when
    the log ends.  ``-P``: the ``gcs`` it runs is this process's, whatever the working
    directory holds.

    Raises
    ------
    LogError
        When the process cannot start.
    """
    import gcs

    env = dict(os.environ)
    root = str(Path(gcs.__file__).resolve().parent.parent)
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    try:
        proc = subprocess.Popen([sys.executable, "-P", "-m", "gcs.log.worker"], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, env=env, start_new_session=True)
    except OSError as exc:
        raise LogError(f"{path}: cannot start the log writer process: {exc.strerror or exc}") from None
    enlarge_pipe(proc.stdin.fileno())  # type: ignore[union-attr]
    return proc


def enlarge_pipe(fd: int, size: int = PIPE_BYTES) -> int:
    """Ask for a pipe of ``size`` bytes (or the system's maximum); the size it has now [bytes]."""
    setsz = getattr(fcntl, "F_SETPIPE_SZ", None)
    if setsz is None:  # not Linux: the default pipe
        return 0
    try:
        cap = int(Path("/proc/sys/fs/pipe-max-size").read_text())
    except (OSError, ValueError):
        cap = size
    for want in (size, min(size, cap)):
        try:
            return fcntl.fcntl(fd, setsz, want)
        except OSError:  # EPERM above the cap for an unprivileged process, EBUSY: keep what it has
            continue
    return fcntl.fcntl(fd, fcntl.F_GETPIPE_SZ)


class _NonBlockingPipe:
    """Frames written from the caller's thread without ever blocking; dropped when the backlog is full."""

    def __init__(self, proc: subprocess.Popen, max_backlog_bytes: int) -> None:
        self._stdin = proc.stdin
        self._fd = proc.stdin.fileno()  # type: ignore[union-attr]
        self._backlog = bytearray()
        self._max = max_backlog_bytes
        self.broken = False

    def start(self, first: bytes) -> None:
        try:
            self._stdin.write(first)  # type: ignore[union-attr]
            self._stdin.flush()  # type: ignore[union-attr]
        except OSError:
            self.broken = True
            raise
        flags = fcntl.fcntl(self._fd, fcntl.F_GETFL)
        fcntl.fcntl(self._fd, fcntl.F_SETFL, flags | os.O_NONBLOCK)

    def send(self, data: bytes, count: int) -> int:
        """Queue a frame of ``count`` records; returns how many were dropped (0 or ``count``)."""
        if len(self._backlog) + len(data) > self._max:
            self._pump()
            return count
        self._backlog += data
        self._pump()
        return 0

    def _pump(self) -> None:
        """Write as much of the backlog as the pipe takes now (never blocks)."""
        while self._backlog:
            try:
                n = os.write(self._fd, self._backlog)
            except BlockingIOError:
                return
            except OSError as exc:
                if exc.errno == errno.EAGAIN:
                    return
                self.broken = True
                raise
            del self._backlog[:n]

    def finish(self, last: bytes) -> str | None:
        """Hand over the backlog and ``last`` (blocking now) and close the pipe; an error text, or None."""
        error = None
        try:
            flags = fcntl.fcntl(self._fd, fcntl.F_GETFL)
            fcntl.fcntl(self._fd, fcntl.F_SETFL, flags & ~os.O_NONBLOCK)
            if self.broken:
                raise BrokenPipeError("broken")
            self._stdin.write(bytes(self._backlog) + last)  # type: ignore[union-attr]
            self._stdin.flush()  # type: ignore[union-attr]
        except (OSError, ValueError):
            error = _STOPPED
        self._backlog.clear()
        with contextlib.suppress(OSError):
            self._stdin.close()  # type: ignore[union-attr]
        return error


class _SenderThread:
    """Frames queued here and written by a thread (the GIL is released while the pipe is full); never dropped."""

    def __init__(self, proc: subprocess.Popen, max_pending: int) -> None:
        self._stdin = proc.stdin
        self._queue: queue.Queue = queue.Queue(maxsize=max_pending)
        self._broken = threading.Event()
        self._thread = threading.Thread(target=self._run, name="gcs-log-sender", daemon=True)

    @property
    def broken(self) -> bool:
        return self._broken.is_set() or not self._thread.is_alive()

    def start(self, first: bytes) -> None:
        self._thread.start()
        self._put(first)

    def _run(self) -> None:
        stdin = self._stdin
        while True:
            frame = self._queue.get()
            if frame is None:
                break
            try:
                stdin.write(frame)  # type: ignore[union-attr]
                stdin.flush()  # type: ignore[union-attr]
            except (OSError, ValueError):
                self._broken.set()
                break
        with contextlib.suppress(OSError):
            stdin.close()  # type: ignore[union-attr]

    def _put(self, frame: bytes | None) -> None:
        """Queue a frame (None: stop the thread); BrokenPipeError when the writer stopped reading."""
        while True:
            if self.broken:
                self._drain()
                raise BrokenPipeError(_STOPPED)
            try:
                self._queue.put(frame, timeout=0.5)
                return
            except queue.Full:
                continue

    def _drain(self) -> None:
        """Empty the queue and stop the thread (after the writer stopped reading)."""
        while True:
            try:
                self._queue.get_nowait()
            except queue.Empty:
                break
        with contextlib.suppress(queue.Full):
            self._queue.put_nowait(None)  # pragma: no cover - just emptied

    def send(self, data: bytes, count: int) -> int:
        """Queue a frame (waits while ``max_pending`` are queued); nothing is dropped."""
        self._put(data)
        return 0

    def finish(self, last: bytes) -> str | None:
        """Queue ``last``, stop the thread once it is written, wait for it; an error text, or None."""
        try:
            self._put(last)
            self._put(None)
        except BrokenPipeError:
            return _STOPPED
        finally:
            self._thread.join()
        return None


class BackgroundSink(_SinkBase):
    """A log written by ``python -m gcs.log.worker`` (see the module docstring).

    Parameters
    ----------
    path : path-like
    expected_bytes : int
        For the free-space check, run here before the process starts.
    overflow : {"drop", "wait"}
        When the writer is far behind: drop and count the records (a flight), or wait (a simulation).
    max_backlog_bytes : int
        ``"drop"``: records kept here while the pipe is full, before they are dropped.
    max_pending : int
        ``"wait"``: frames queued here before the producer waits.
    **log_options
        To :class:`FlightLog` in the writer process; ``live`` (``[HOST:]PORT``, :mod:`gcs.log.foxglove_live`) too.

    Raises
    ------
    LogError
        The path is not writable, the disk is nearly full, or the process cannot start.
    """

    def __init__(self, path: str | os.PathLike, *, expected_bytes: int = 0, overflow: str = "drop",
                 max_backlog_bytes: int = MAX_BACKLOG_BYTES, max_pending: int = 32, **log_options: Any) -> None:
        if overflow not in ("drop", "wait"):
            raise ValueError(f"overflow must be 'drop' or 'wait', got {overflow!r}")
        self.path = check_writable(path, expected_bytes)
        self.overflow = overflow
        self.dropped = 0
        self.closed = False
        self.stats: dict = {}
        self.flight_count = 0
        self._proc = spawn_writer(self.path)
        self._pipe: _NonBlockingPipe | _SenderThread = (
            _NonBlockingPipe(self._proc, max_backlog_bytes) if overflow == "drop" else
            _SenderThread(self._proc, max_pending))
        first = pack([OpenLog(str(self.path), dict(log_options), WRITER_NICE if overflow == "drop" else 0)])
        try:
            self._pipe.start(first)
        except OSError as exc:
            raise LogError(f"{self.path}: the log writer process is not reading: {exc}") from None

    def put_many(self, records: list) -> None:
        """Hand records to the writer (``"drop"``: dropped and counted when it is far behind).

        Raises
        ------
        LogError
            The sink is closed, or the writer process stopped (with its error when it said one).
        """
        self._check()
        self.flight_count += list(map(type, records)).count(FlightStart)
        self._send(pack(records), len(records))

    def put_wire(self, wire: list) -> None:
        """:meth:`put_many` of records in their wire form (a FlightStart among them is not counted
        in :attr:`flight_count`)."""
        self._check()
        self._send(pack_wire(wire), len(wire))

    def _check(self) -> None:
        if self.closed or self._pipe.broken:
            if self.closed:
                raise LogError(f"{self.path}: the log is closed")
            self._fail()

    def _send(self, frame: bytes, count: int) -> None:
        try:
            self.dropped += self._pipe.send(frame, count)
        except OSError as exc:
            self._fail(exc)

    def _fail(self, exc: BaseException | None = None) -> None:
        """The writer stopped reading: collect its last word and raise it."""
        self.closed = True
        self._pipe.finish(b"")
        result = self._result(30.0)
        if isinstance(result, LogFailed):
            raise LogError(f"{self.path}: the log writer failed: {result.error}")
        why = f": {exc.strerror or exc}" if isinstance(exc, OSError) else ""
        raise LogError(f"{self.path}: the log writer process stopped{why}")

    def _result(self, timeout_s: float) -> Any:
        """The writer's answer (:class:`LogDone` / :class:`LogFailed`; None without one), once it has exited."""
        try:
            answer = read_frame(self._proc.stdout)  # type: ignore[arg-type]
        except Exception:  # noqa: BLE001  a garbled answer: as good as none
            answer = None
        try:
            self._proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
        return answer[0] if answer else None

    def close(self, timeout_s: float = 30.0) -> dict:
        """Hand over what is left, wait for the writer to finish the file; its stats (see the module docstring).

        Raises
        ------
        LogError
            When the writer failed.
        """
        if self.closed:
            return self.stats
        self.closed = True
        error = self._pipe.finish(pack([CloseLog()]))
        result = self._result(timeout_s)
        if isinstance(result, LogDone):
            self.stats = dict(result.stats, dropped=self.dropped)
            if error is None:
                return self.stats
        if isinstance(result, LogFailed):
            error = result.error
        raise LogError(f"{self.path}: the log writer failed: {error or f'exit code {self._proc.returncode}'}")
