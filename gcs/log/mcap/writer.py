"""``McapWriter``: a chunked, compressed MCAP file that survives the death of its writer.

Built on :class:`mcap.writer.Writer` (through :class:`~gcs.log.mcap.fast.FastWriter`, same
bytes): messages are ``(topic, bytes)`` at a log time; each topic becomes a channel the first
time it is written, with the schema a ``schema_of(topic)`` callback gives.  The writer knows
nothing of what the messages mean.

Chunking and compression are options (``chunk_size_bytes``; ``compression`` zstd when
``zstandard`` imports, else lz4 when ``lz4`` imports, else none).  Nothing is lost when the
process dies: completed chunks reach the operating system at least every
``flush_interval_s`` of wall time (0.5 s by default; a background thread does it even when
nothing is being written, and the write path does it too should that thread be starved), and
on :meth:`McapWriter.flush`.  A process killed with SIGKILL therefore leaves a file that
:func:`gcs.log.mcap.reader.read_log` opens, marked truncated, with everything up to about the
last ``flush_interval_s``.  With ``fsync=True`` the background thread also ``fsync``s what it
flushed (power loss), outside the writing thread's path.
"""

from __future__ import annotations

import contextlib
import importlib.util
import os
import shutil
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

from mcap.writer import CompressionType, IndexType

from gcs.errors import LogError
from gcs.log.mcap.fast import FastWriter

__all__ = ["COMPRESSIONS", "MIN_FREE_BYTES", "McapWriter", "best_compression", "check_writable"]

#: Free space that must remain on the disk besides the expected log size [bytes].
MIN_FREE_BYTES = 64 * 1024 * 1024
#: Chunk compressions by name.
COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}


def best_compression() -> str:
    """``"zstd"`` if ``zstandard`` imports, else ``"lz4"`` if ``lz4`` imports, else ``"none"``."""
    if importlib.util.find_spec("zstandard") is not None:
        return "zstd"
    if importlib.util.find_spec("lz4") is not None:
        return "lz4"
    return "none"


def _size(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if abs(n) < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000.0
    return f"{n:.1f} TB"  # pragma: no cover


def _probe(parent: Path) -> None:
    """Create the directory and write and remove a file in it."""
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise LogError(f"{parent}: cannot create the log directory: {exc.strerror or exc}") from None
    if not parent.is_dir():
        raise LogError(f"{parent}: not a directory")
    try:
        fd, probe = tempfile.mkstemp(prefix=".gcs-write-test-", dir=parent)
        try:
            os.write(fd, b"\0")
        finally:
            os.close(fd)
            os.unlink(probe)
    except OSError as exc:
        raise LogError(f"{parent}: cannot write logs there: {exc.strerror or exc}") from None


def check_writable(path: str | os.PathLike, expected_bytes: int = 0, *, min_free_bytes: int = MIN_FREE_BYTES) -> Path:
    """Pre-flight check that a log can be written at ``path``.

    Creates the directory if needed, writes and removes a probe file in it, and checks the
    free space (``expected_bytes`` for the log plus ``min_free_bytes`` to spare).

    Returns
    -------
    Path
        ``path`` as a :class:`~pathlib.Path`.

    Raises
    ------
    LogError
        The directory cannot be created or written, ``path`` is a directory or
        read-only, or the disk has less than ``expected_bytes + min_free_bytes`` free.
    """
    p = Path(path)
    if p.is_dir():
        raise LogError(f"{p}: is a directory, not a log file name")
    if p.exists() and not p.is_file():
        raise LogError(f"{p}: not a regular file (a device or a pipe cannot hold a log)")
    parent = p.parent if str(p.parent) else Path(".")
    _probe(parent)
    if p.exists() and not os.access(p, os.W_OK):
        raise LogError(f"{p}: exists and is not writable")
    try:
        free = shutil.disk_usage(parent).free
    except OSError as exc:  # pragma: no cover - statvfs failing on a directory we just wrote to
        raise LogError(f"{parent}: cannot read the free disk space: {exc.strerror or exc}") from None
    need = int(expected_bytes) + int(min_free_bytes)
    if free < need:
        raise LogError(f"{parent}: disk nearly full: {_size(free)} free, need about {_size(expected_bytes)} for the "
                       f"log plus {_size(min_free_bytes)} to spare (free space, or log elsewhere)")
    return p


class McapWriter:
    """An MCAP file being written.  Use as a context manager (the file is always finished).

    Parameters
    ----------
    path : path-like
        File to write (its directory is created).
    schema_of : callable (topic) -> (schema name, schema data as bytes)
        The schema of a topic's channel, asked once per topic.
    message_encoding, schema_encoding : str
        Of every channel and schema (JSON messages with ``jsonschema`` schemas by default).
    compression : {"auto", "zstd", "lz4", "none"}
        ``"auto"`` = :func:`best_compression`.
    chunk_size_bytes : int
        A chunk is closed when its uncompressed size passes this.
    flush_interval_s : float
        Wall time between flushes of the chunk in progress to the OS (<= 1 s keeps a killed
        process's loss under a second).
    fsync : bool
        Also ``os.fsync`` after the periodic flushes (in the background thread).
    background_flush : bool
        Run the flushing thread (else only the write path flushes, when it runs).
    check : bool
        Run :func:`check_writable` first (with ``expected_bytes``).
    profile, library : str
        Of the MCAP header.
    """

    def __init__(self, path: str | os.PathLike, *, schema_of: Callable[[str], tuple[str, bytes]],
                 message_encoding: str = "json", schema_encoding: str = "jsonschema", compression: str = "auto",
                 chunk_size_bytes: int = 1 << 20, flush_interval_s: float = 0.5, fsync: bool = True,
                 background_flush: bool = True, check: bool = True, expected_bytes: int = 0, profile: str = "",
                 library: str = "") -> None:
        self.path = Path(path)
        if compression == "auto":
            compression = best_compression()
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression must be one of auto, {', '.join(COMPRESSIONS)}; got {compression!r}")
        if not flush_interval_s > 0:
            raise ValueError(f"flush_interval_s must be > 0, got {flush_interval_s!r}")
        if check:
            check_writable(self.path, expected_bytes)
        self.compression = compression
        self.flush_interval_s = float(flush_interval_s)
        self._schema_of = schema_of
        self._encodings = (message_encoding, schema_encoding)
        self._lock = threading.Lock()
        self._channels: dict[str, int] = {}
        self._schemas: dict[tuple[str, bytes], int] = {}
        self._closed = False
        self._error: BaseException | None = None
        self._pending = False
        self._unsynced = False
        self._fsync = fsync
        self.message_count = 0
        self.start_time_ns: int | None = None
        self.end_time_ns: int | None = None
        self._open(chunk_size_bytes, profile, library)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        if background_flush:
            self._thread = threading.Thread(target=self._flusher, name=f"gcs-log-flush:{self.path.name}", daemon=True)
            self._thread.start()

    def _open(self, chunk_size_bytes: int, profile: str, library: str) -> None:
        try:
            self._file = open(self.path, "wb")  # noqa: SIM115 - open until close()
        except OSError as exc:
            raise LogError(f"{self.path}: cannot open for writing: {exc.strerror or exc}") from None
        self._writer = FastWriter(self._file, chunk_size=chunk_size_bytes, compression=COMPRESSIONS[self.compression],
                                  index_types=IndexType.ALL)
        now = time.monotonic()
        self._last_flush = now
        # The write path flushes too, a little later than the thread would, in case it is starved.
        self._deadline = now + 1.5 * self.flush_interval_s
        try:
            self._writer.start(profile=profile, library=library)
            self._file.flush()
        except OSError as exc:
            with contextlib.suppress(OSError):
                self._file.close()  # closing flushes again into the same full disk
            raise LogError(f"{self.path}: cannot write: {exc.strerror or exc}") from None

    # ------------------------------------------------------------------ life cycle

    def __enter__(self) -> McapWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            self.close()
        except LogError:
            if exc_type is None:
                raise
            # An exception is already propagating: let that one through.

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Finish the file (last chunk, summary, footer) and close it.  Idempotent.

        Raises
        ------
        LogError
            When the final write fails (e.g. the disk filled up); the file is closed anyway.
        """
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join()
        with self._lock:
            if self._closed:
                return
            self._closed = True
            try:
                self._writer.finish()
                self._file.flush()
                if self._fsync:
                    os.fsync(self._file.fileno())
            except OSError as exc:
                raise LogError(f"{self.path}: finishing the log failed: {exc.strerror or exc}") from None
            finally:
                with contextlib.suppress(OSError):
                    self._file.close()
        if self._error is not None:
            raise LogError(f"{self.path}: a background flush failed: {self._error}")

    def flush(self) -> None:
        """Close the chunk in progress and hand everything written so far to the OS now."""
        with self._lock:
            self._check_open()
            self._flush_locked()

    def _flush_locked(self) -> None:
        try:
            self._writer.flush()
        except OSError as exc:
            raise LogError(f"{self.path}: write failed: {exc.strerror or exc}") from None
        self._pending = False
        self._unsynced = True
        now = time.monotonic()
        self._last_flush = now
        self._deadline = now + 1.5 * self.flush_interval_s

    def _flusher(self) -> None:
        period = self.flush_interval_s
        while not self._stop.wait(period / 4.0):
            fd = -1
            with self._lock:
                if self._closed:
                    return
                if self._pending and time.monotonic() - self._last_flush >= period:
                    try:
                        self._flush_locked()
                    except LogError as exc:
                        self._error = exc
                        return
                if self._fsync and self._unsynced:
                    self._unsynced = False
                    fd = self._file.fileno()
            if fd >= 0:
                # Outside the lock: the writing thread keeps writing meanwhile.  The file may have been
                # closed in between: close() syncs itself.
                with contextlib.suppress(OSError):
                    os.fsync(fd)

    def _check_open(self) -> None:
        if self._closed:
            raise LogError(f"{self.path}: the log is closed")
        if self._error is not None:
            raise LogError(f"{self.path}: a background flush failed: {self._error}")

    # ------------------------------------------------------------------ messages

    def _register(self, topic: str) -> int:
        """Channel id of ``topic``, registering its schema and channel the first time (lock held)."""
        cid = self._channels.get(topic)
        if cid is not None:
            return cid
        name, data = self._schema_of(topic)
        sid = self._schemas.get((name, data))
        if sid is None:
            sid = self._writer.register_schema(name=name, encoding=self._encodings[1], data=data)
            self._schemas[(name, data)] = sid
        cid = self._writer.register_channel(topic=topic, message_encoding=self._encodings[0], schema_id=sid)
        self._channels[topic] = cid
        return cid

    def add(self, items: Iterable[tuple[str, bytes]], log_time_ns: int, publish_time_ns: int | None = None) -> None:
        """Write ``(topic, message bytes)`` pairs at one time stamp [ns], under one lock, in order."""
        t = int(log_time_ns)
        pt = t if publish_time_ns is None else int(publish_time_ns)
        with self._lock:
            if self._closed or self._error is not None:
                self._check_open()
            channels = self._channels
            batch = []
            for topic, data in items:
                cid = channels.get(topic)
                if cid is None:
                    cid = self._register(topic)
                batch.append((cid, data))
            try:
                self._writer.add_messages(batch, t, pt)
            except OSError as exc:
                raise LogError(f"{self.path}: write failed: {exc.strerror or exc}") from None
            self.message_count += len(batch)
            if self.end_time_ns is None or t > self.end_time_ns:
                self.end_time_ns = t
            if self.start_time_ns is None or t < self.start_time_ns:
                self.start_time_ns = t
            self._pending = True
            if time.monotonic() >= self._deadline:
                self._flush_locked()

    # ------------------------------------------------------------------ metadata, attachments

    def metadata(self, name: str, data: Mapping[str, Any]) -> None:
        """An MCAP metadata record ``name`` (keys and values are converted to str)."""
        with self._lock:
            self._check_open()
            try:
                self._writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})
            except OSError as exc:
                raise LogError(f"{self.path}: write failed: {exc.strerror or exc}") from None

    def attachment(self, name: str, media_type: str, data: bytes | str, *, log_time_ns: int | None = None) -> None:
        """An MCAP attachment (str is UTF-8 encoded); its log time is the last message's by default."""
        payload = data.encode() if isinstance(data, str) else bytes(data)
        with self._lock:
            self._check_open()
            t = log_time_ns if log_time_ns is not None else (self.end_time_ns or 0)
            try:
                self._writer.add_attachment(create_time=time.time_ns(), log_time=int(t), name=name,
                                            media_type=media_type, data=payload)
            except OSError as exc:
                raise LogError(f"{self.path}: write failed: {exc.strerror or exc}") from None
