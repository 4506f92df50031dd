"""``FlightLog``: the MCAP writer of every ``gcs fly`` / ``gcs sim`` run.

Built on :class:`mcap.writer.Writer`: JSON messages with ``jsonschema`` schemas
(Foxglove Studio reads them), chunked and compressed (zstd when ``zstandard``
imports, else lz4 when ``lz4`` imports, else none), each topic registered once,
lazily, with the schema of :mod:`gcs.log.topics`.

Nothing is lost when the process dies: completed chunks reach the operating
system at least every ``flush_interval_s`` of wall time (0.5 s by default; a
background thread does it even when nothing is being written, and the write
path does it too should that thread be starved), and on :meth:`FlightLog.flush`.
A process killed with SIGKILL therefore leaves a file that
:func:`gcs.log.reader.read_log` opens, marked truncated, with everything up to
about the last ``flush_interval_s``.  With ``fsync=True`` the background thread
also ``fsync``s what it flushed (power loss), outside the control loop's path.

The per-message path is cheap: cached channel ids, one lock, and for the
fixed-field topics (state, reference, error, command, cost, truth) a
pre-compiled ``%.17g`` template instead of building a dict (17 significant
digits read back as the same double; non-finite values fall back to
``json.dumps``, which writes ``NaN``/``Infinity`` as Python's json reads them).
"""

from __future__ import annotations

import base64
import importlib.util
import itertools
import json
import math
import os
import shutil
import struct
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from mcap.opcode import Opcode
from mcap.records import MessageIndex
from mcap.writer import CompressionType, IndexType, Writer

from gcs import __version__
from gcs.errors import LogError
from gcs.log import topics as T

__all__ = ["FlightLog", "check_writable", "best_compression", "MIN_FREE_BYTES", "PROFILE"]

#: Free space that must remain on the disk besides the expected log size [bytes].
MIN_FREE_BYTES = 64 * 1024 * 1024
#: MCAP header profile of these logs.
PROFILE = "gcs"

_TWO_PI = 2.0 * math.pi


def best_compression() -> str:
    """``"zstd"`` if ``zstandard`` imports, else ``"lz4"`` if ``lz4`` imports, else ``"none"``."""
    if importlib.util.find_spec("zstandard") is not None:
        return "zstd"
    if importlib.util.find_spec("lz4") is not None:
        return "lz4"
    return "none"


_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}


def _size(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if abs(n) < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000.0
    return f"{n:.1f} TB"  # pragma: no cover


def check_writable(path: str | os.PathLike, expected_bytes: int = 0, *, min_free_bytes: int = MIN_FREE_BYTES) -> Path:
    """Pre-flight check that a log can be written at ``path``.

    Creates the directory if needed, writes and removes a probe file in it, and
    checks the free space.

    Parameters
    ----------
    path : path-like
        The log file to be written.
    expected_bytes : int
        Expected size of the log [bytes].
    min_free_bytes : int
        Space that must remain free besides it [bytes].

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


def _json_default(obj: Any) -> Any:
    if isinstance(obj, (bytes, bytearray, memoryview)):
        return base64.b64encode(bytes(obj)).decode("ascii")
    tolist = getattr(obj, "tolist", None)  # numpy scalars and arrays
    if tolist is not None:
        return tolist()
    if isinstance(obj, (set, frozenset, tuple)):
        return list(obj)
    return str(obj)


_dumps = json.JSONEncoder(separators=(",", ":"), default=_json_default).encode


class _Template:
    """``%.17g`` template of a fixed-field JSON object (17 digits read back as the same double).

    Formats straight to bytes (faster than a str and its encoding)."""

    __slots__ = ("fields", "fmt", "n_count", "size")

    def __init__(self, fields: Sequence[str]) -> None:
        self.fields = tuple(fields)
        self.size = len(self.fields)
        self.fmt = ("{" + ",".join(f'"{f}":%.17g' for f in self.fields) + "}").encode()
        # 'n' occurs in 'nan' and 'inf': a count above the template's own means a non-finite value.
        self.n_count = (self.fmt % ((0.0,) * self.size)).count(b"n")

    def encode(self, values: Any) -> bytes:
        try:
            s = self.fmt % values
        except TypeError:
            return self._slow(values)
        if s.count(b"n") != self.n_count:
            return _dumps(dict(zip(self.fields, values))).encode()
        return s

    def _slow(self, values: Any) -> bytes:
        vals = tuple(values)
        if len(vals) != self.size:
            raise ValueError(f"expected {self.size} values ({', '.join(self.fields)}), got {len(vals)}")
        try:
            s = self.fmt % vals
        except TypeError:  # None or other non-numbers: let json say what they are
            return _dumps(dict(zip(self.fields, vals))).encode()
        if s.count(b"n") != self.n_count:
            return _dumps(dict(zip(self.fields, vals))).encode()
        return s


_TEMPLATES = {topic: _Template(fields) for topic, fields in T.FIXED_FIELDS.items()}

_MESSAGE_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel id, sequence, log time, publish time


class _FastMessageIndex(MessageIndex):
    """A MessageIndex that serialises its entries with one ``struct.pack`` (same bytes as the base class)."""

    def write(self, stream) -> None:
        n = len(self.records)
        stream.start_record(Opcode.MESSAGE_INDEX)
        stream.write(struct.pack(f"<HI{2 * n}Q", self.channel_id, 16 * n, *itertools.chain.from_iterable(self.records)))
        stream.finish_record()


class _Writer(Writer):
    """:class:`mcap.writer.Writer` with a faster ``add_message`` for chunked files.

    mcap-python's ``add_message`` builds a record object and writes it field by field
    (about 3 us a message); this one packs the record header with one ``struct.pack``
    into the same chunk buffer and keeps the same statistics and message indexes, so
    the file is byte-for-byte what the base class writes (tested).  It relies on the
    base class's private attributes: if they are not there (another mcap version), it
    falls back to the base class's method.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        cb = getattr(self, "_Writer__chunk_builder", None)
        buf = getattr(getattr(cb, "record_writer", None), "_buffer", None)
        self._fast = (cb is not None and hasattr(buf, "write") and hasattr(buf, "tell")
                      and all(hasattr(cb, a) for a in ("message_indices", "num_messages", "message_start_time",
                                                       "message_end_time"))
                      and hasattr(self, "_Writer__statistics") and hasattr(self, "_Writer__chunk_size")
                      and hasattr(self, "_Writer__maybe_finalize_chunk"))
        if self._fast:
            self._stats = getattr(self, "_Writer__statistics")
            self._chunk_size = getattr(self, "_Writer__chunk_size")
            self._maybe_finalize = getattr(self, "_Writer__maybe_finalize_chunk")
            self._cb = cb

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0) -> None:
        if not self._fast:
            return super().add_message(channel_id, log_time, data, publish_time, sequence)
        st = self._stats
        if st.message_count == 0:
            st.message_start_time = log_time
        elif log_time < st.message_start_time:
            st.message_start_time = log_time
        if log_time > st.message_end_time:
            st.message_end_time = log_time
        st.channel_message_counts[channel_id] += 1
        st.message_count += 1
        cb = self._cb
        if cb.num_messages == 0:
            cb.message_start_time = log_time
        elif log_time < cb.message_start_time:
            cb.message_start_time = log_time
        if log_time > cb.message_end_time:
            cb.message_end_time = log_time
        index = cb.message_indices.get(channel_id)
        if not index:
            index = cb.message_indices[channel_id] = _FastMessageIndex(channel_id=channel_id, records=[])
        buf = cb.record_writer._buffer  # replaced by a new BytesIO after each chunk
        index.records.append((log_time, buf.tell()))
        cb.num_messages += 1
        buf.write(_MESSAGE_HEAD.pack(Opcode.MESSAGE, 22 + len(data), channel_id, sequence, log_time, publish_time))
        buf.write(data)
        if buf.tell() > self._chunk_size:
            self._maybe_finalize()
        return None

    def add_messages(self, messages: Sequence[tuple[int, bytes]], log_time: int, publish_time: int) -> None:
        """``add_message`` of several ``(channel id, data)`` with one time stamp (same bytes, less overhead)."""
        if not self._fast:
            for cid, data in messages:
                super().add_message(cid, log_time, data, publish_time, 0)
            return
        st = self._stats
        if st.message_count == 0:
            st.message_start_time = log_time
        elif log_time < st.message_start_time:
            st.message_start_time = log_time
        if log_time > st.message_end_time:
            st.message_end_time = log_time
        st.message_count += len(messages)
        counts = st.channel_message_counts
        cb = self._cb
        if cb.num_messages == 0:
            cb.message_start_time = log_time
        elif log_time < cb.message_start_time:
            cb.message_start_time = log_time
        if log_time > cb.message_end_time:
            cb.message_end_time = log_time
        indices = cb.message_indices
        buf = cb.record_writer._buffer
        write, tell, pack = buf.write, buf.tell, _MESSAGE_HEAD.pack
        for cid, data in messages:
            counts[cid] += 1
            index = indices.get(cid)
            if not index:
                index = indices[cid] = _FastMessageIndex(channel_id=cid, records=[])
            index.records.append((log_time, tell()))
            write(pack(5, 22 + len(data), cid, 0, log_time, publish_time))
            write(data)
        cb.num_messages += len(messages)
        if tell() > self._chunk_size:
            self._maybe_finalize()


class FlightLog:
    """An MCAP flight log being written.  Use as a context manager (the file is always finished).

    Parameters
    ----------
    path : path-like
        File to write (its directory is created).
    compression : {"auto", "zstd", "lz4", "none"}
        ``"auto"`` = :func:`best_compression`.
    chunk_size_bytes : int
        A chunk is closed when its uncompressed size passes this.
    flush_interval_s : float
        Wall time between flushes of the chunk in progress to the OS (<= 1 s keeps
        a killed process's loss under a second).
    fsync : bool
        Also ``os.fsync`` after the periodic flushes (in the background thread).
    background_flush : bool
        Run the flushing thread (else only the write path flushes, when it runs).
    check : bool
        Run :func:`check_writable` first.
    expected_bytes : int
        Expected log size for the free-space check.

    Examples
    --------
    A flight loop::

        with FlightLog("logs/x.mcap") as log:
            log.metadata("flight", {...}); log.attachment("config.json", "application/json", text)
            log.flight_start(t0_ns, controller="loc", experiment="outdoor-altitude", ts_s=0.01)
            for k ...:
                log.control_tick(t_ns, k=k, state=est, reference=ref, command=cmd,
                                 command_limited=sent, steps_to_go=j, mode="horizon")
                log.event(t_ns, "mode", "GUIDED_NOGPS")
    """

    def __init__(self, path: str | os.PathLike, *, compression: str = "auto", chunk_size_bytes: int = 1 << 20,
                 flush_interval_s: float = 0.5, fsync: bool = True, background_flush: bool = True,
                 check: bool = True, expected_bytes: int = 0) -> None:
        self.path = Path(path)
        if compression == "auto":
            compression = best_compression()
        if compression not in _COMPRESSION:
            raise ValueError(f"compression must be one of auto, {', '.join(_COMPRESSION)}; got {compression!r}")
        if not flush_interval_s > 0:
            raise ValueError(f"flush_interval_s must be > 0, got {flush_interval_s!r}")
        if check:
            check_writable(self.path, expected_bytes)
        self.compression = compression
        self.flush_interval_s = float(flush_interval_s)
        try:
            self._file = open(self.path, "wb")
        except OSError as exc:
            raise LogError(f"{self.path}: cannot open for writing: {exc.strerror or exc}") from None
        self._writer = _Writer(self._file, chunk_size=chunk_size_bytes, compression=_COMPRESSION[compression],
                              index_types=IndexType.ALL)
        self._lock = threading.Lock()
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self._modes: dict[str, bytes] = {}
        self._last_ref: tuple | None = None
        self._last_ref_text = b""
        self._closed = False
        self._error: BaseException | None = None
        self._pending = False
        self._unsynced = False
        self._fsync = fsync
        self.message_count = 0
        self.flight_count = 0
        self.start_time_ns: int | None = None
        self.end_time_ns: int | None = None
        now = time.monotonic()
        self._last_flush = now
        # The write path flushes too, a little later than the thread would, in case it is starved.
        self._deadline = now + 1.5 * self.flush_interval_s
        try:
            self._writer.start(profile=PROFILE, library=f"gcs/{__version__} mcap-python")
            self._file.flush()
        except OSError as exc:
            try:
                self._file.close()
            except OSError:
                pass  # closing flushes again into the same full disk
            raise LogError(f"{self.path}: cannot write: {exc.strerror or exc}") from None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        if background_flush:
            self._thread = threading.Thread(target=self._flusher, name=f"gcs-log-flush:{self.path.name}", daemon=True)
            self._thread.start()

    # ------------------------------------------------------------------ life cycle

    def __enter__(self) -> "FlightLog":
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
                try:
                    self._file.close()
                except OSError:
                    pass
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
                try:
                    os.fsync(fd)  # outside the lock: the control loop keeps writing meanwhile
                except OSError:
                    pass  # the file may have been closed in between; close() syncs itself

    def _check_open(self) -> None:
        if self._closed:
            raise LogError(f"{self.path}: the log is closed")
        if self._error is not None:
            raise LogError(f"{self.path}: a background flush failed: {self._error}")

    # ------------------------------------------------------------------ channels

    def _register(self, topic: str) -> int:
        """Channel id of ``topic``, registering its schema and channel the first time (lock held)."""
        cid = self._channels.get(topic)
        if cid is not None:
            return cid
        name, data = T.schema_json(topic)
        key = name + "\0" + data.decode()
        sid = self._schemas.get(key)
        if sid is None:
            sid = self._writer.register_schema(name=name, encoding="jsonschema", data=data)
            self._schemas[key] = sid
        cid = self._writer.register_channel(topic=topic, message_encoding="json", schema_id=sid)
        self._channels[topic] = cid
        return cid

    def _add(self, items: Iterable[tuple[str, bytes]], log_time_ns: int, publish_time_ns: int | None) -> None:
        """Write ``(topic, JSON as bytes)`` pairs at one time stamp, under one lock."""
        t = int(log_time_ns)
        pt = t if publish_time_ns is None else int(publish_time_ns)
        with self._lock:
            if self._closed or self._error is not None:
                self._check_open()
            channels = self._channels
            batch = []
            for topic, text in items:
                cid = channels.get(topic)
                if cid is None:
                    cid = self._register(topic)
                batch.append((cid, text))
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

    # ------------------------------------------------------------------ messages

    def write(self, topic: str, log_time_ns: int, obj: Mapping[str, Any], *, publish_time_ns: int | None = None) -> None:
        """Write one message: ``obj`` (a JSON-able mapping) on ``topic`` at ``log_time_ns`` [ns].

        bytes become base64 strings, numpy values plain numbers.
        """
        self._add(((topic, _dumps(obj).encode()),), log_time_ns, publish_time_ns)

    def write_json(self, topic: str, log_time_ns: int, text: str | bytes, *,
                   publish_time_ns: int | None = None) -> None:
        """Write an already serialised JSON object."""
        self._add(((topic, text.encode() if isinstance(text, str) else bytes(text)),), log_time_ns, publish_time_ns)

    def write_values(self, topic: str, log_time_ns: int, values: Sequence[float], *,
                     publish_time_ns: int | None = None) -> None:
        """Fast path for the fixed-field topics (:data:`gcs.log.topics.FIXED_FIELDS`): the values in field order.

        ``values`` may be a :class:`gcs.model.State` / :class:`gcs.model.Command` (any tuple), a list or an array.
        """
        tmpl = _TEMPLATES.get(topic)
        if tmpl is None:
            raise ValueError(f"{topic} has no fixed fields; use write()")
        self._add(((topic, tmpl.encode(values)),), log_time_ns, publish_time_ns)

    def control_tick(self, log_time_ns: int, *, state: Sequence[float], reference: Sequence[float],
                     command: Sequence[float], command_limited: Sequence[float] | None = None,
                     k: int | None = None, steps_to_go: int = 0, mode: str = "horizon",
                     cost: Sequence[float] | None = None, truth: Sequence[float] | None = None,
                     error: bool = True) -> None:
        """Everything of one control tick, under one lock.

        Writes ``/control/state``, ``/control/reference``, ``/control/error`` (reference - state,
        yaw wrapped; unless ``error=False``), ``/control/command``, and when given
        ``/control/command_limited``, ``/control/horizon`` (``k`` given), ``/control/cost``
        (state_cost, input_cost, stage_cost) and ``/sim/truth``.
        """
        if isinstance(reference, tuple) and reference == self._last_ref:
            ref_text = self._last_ref_text  # references hold still most of a flight: format them once
        else:
            ref_text = _TEMPLATES[T.REFERENCE].encode(reference)
            if isinstance(reference, tuple):
                self._last_ref, self._last_ref_text = reference, ref_text
        items = [(T.STATE, _TEMPLATES[T.STATE].encode(state)), (T.REFERENCE, ref_text)]
        if error:
            e = [r - s for r, s in zip(reference, state)]
            if len(e) == 12:
                e[8] = (e[8] + math.pi) % _TWO_PI - math.pi
            items.append((T.ERROR, _TEMPLATES[T.ERROR].encode(e)))
        items.append((T.COMMAND, _TEMPLATES[T.COMMAND].encode(command)))
        if command_limited is not None:
            items.append((T.COMMAND_LIMITED, _TEMPLATES[T.COMMAND_LIMITED].encode(command_limited)))
        if k is not None:
            items.append((T.HORIZON, self.horizon_json(k, steps_to_go, mode)))
        if cost is not None:
            items.append((T.COST, _TEMPLATES[T.COST].encode(cost)))
        if truth is not None:
            items.append((T.TRUTH, _TEMPLATES[T.TRUTH].encode(truth)))
        self._add(items, log_time_ns, None)

    def horizon_json(self, k: int, steps_to_go: int, mode: str) -> bytes:
        """The ``/control/horizon`` message."""
        m = self._modes.get(mode)
        if m is None:
            m = self._modes[mode] = json.dumps(str(mode)).encode()
        return b'{"k":%d,"steps_to_go":%d,"mode":%s}' % (k, steps_to_go, m)

    def event(self, log_time_ns: int, kind: str, text: str, **fields: Any) -> None:
        """An ``/events`` message: ``{"kind", "text", **fields}`` (mode change, arming, failsafe, warning, phase)."""
        obj = {"kind": kind, "text": text}
        obj.update(fields)
        self._add(((T.EVENTS, _dumps(obj).encode()),), log_time_ns, None)

    def flight_start(self, log_time_ns: int, *, controller: str, flight: int | None = None, experiment: str = "",
                     run: int = 0, seed: int | None = None, ts_s: float | None = None, steps: int | None = None,
                     source: str = "flight", **fields: Any) -> int:
        """A ``/flight`` message: every later message up to the next one belongs to this flight.

        Returns the flight index (by default the number of flights started before).
        """
        if flight is None:
            flight = self.flight_count
        obj = {"flight": flight, "controller": controller, "experiment": experiment, "run": run, "seed": seed,
               "ts_s": ts_s, "steps": steps, "source": source}
        obj.update(fields)
        self._add(((T.FLIGHT, _dumps(obj).encode()),), log_time_ns, None)
        self.flight_count += 1
        return flight

    def loop_timing(self, log_time_ns: int, **fields: Any) -> None:
        """A ``/loop/timing`` message (``k``, ``jitter_s``, ``tick_s``, ``deadline_missed``, per-stage ``*_s``)."""
        self._add(((T.TIMING, _dumps(fields).encode()),), log_time_ns, None)

    def mavlink(self, log_time_ns: int, direction: str, msg: Any, *, raw: bool = True) -> None:
        """A pymavlink message: decoded fields on ``/mavlink/<direction>/<TYPE>`` and its frame on ``/mavlink/raw``.

        Parameters
        ----------
        direction : {"in", "out"}
        msg : pymavlink ``MAVLink_message``
            Needs ``get_type()``, ``to_dict()`` and, for ``raw``, ``get_msgbuf()``.
        """
        mtype = msg.get_type()
        fields = msg.to_dict()
        fields.pop("mavpackettype", None)
        items = [(T.mavlink_topic(direction, mtype), _dumps(fields).encode())]
        if raw:
            buf = msg.get_msgbuf()
            if buf:
                items.append((T.MAVLINK_RAW, _dumps({"dir": direction, "type": mtype,
                                                     "data_b64": base64.b64encode(bytes(buf)).decode("ascii")}).encode()))
        self._add(items, log_time_ns, None)

    def mavlink_raw(self, log_time_ns: int, direction: str, frame: bytes, msg_type: str = "") -> None:
        """A raw frame on ``/mavlink/raw`` (e.g. one that did not decode)."""
        if direction not in ("in", "out"):
            raise ValueError(f"direction must be 'in' or 'out', got {direction!r}")
        self._add(((T.MAVLINK_RAW, _dumps({"dir": direction, "type": msg_type,
                                           "data_b64": base64.b64encode(bytes(frame)).decode("ascii")}).encode()),),
                  log_time_ns, None)

    # ------------------------------------------------------------------ metadata, attachments

    def metadata(self, name: str, data: Mapping[str, Any]) -> None:
        """An MCAP metadata record ``name`` (values are converted to str)."""
        with self._lock:
            self._check_open()
            try:
                self._writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})
            except OSError as exc:
                raise LogError(f"{self.path}: write failed: {exc.strerror or exc}") from None

    def attachment(self, name: str, media_type: str, data: bytes | str, *, log_time_ns: int | None = None) -> None:
        """An MCAP attachment (e.g. ``config.json``, ``gains.json``); str is UTF-8 encoded."""
        payload = data.encode() if isinstance(data, str) else bytes(data)
        with self._lock:
            self._check_open()
            t = log_time_ns if log_time_ns is not None else (self.end_time_ns or 0)
            try:
                self._writer.add_attachment(create_time=time.time_ns(), log_time=int(t), name=name,
                                            media_type=media_type, data=payload)
            except OSError as exc:
                raise LogError(f"{self.path}: write failed: {exc.strerror or exc}") from None
