"""Read an MCAP log robustly, including one whose writer was killed (no summary, no footer).

:func:`read_log` first asks mcap's :func:`mcap.reader.make_reader` for the summary
(present only in a finished file), then reads the data section record by record
with :class:`mcap.stream_reader.StreamReader` (chunks handed over whole), checks
each chunk (decompression, CRC) and parses the messages inside it.  It stops
cleanly at the first broken or incomplete record and reports the log as
``truncated`` with the reason; everything before that point is kept.

Input that is not an MCAP file (missing, empty, a directory, wrong magic bytes)
raises :class:`gcs.errors.LogError` with a one-line reason.
"""

from __future__ import annotations

import io
import json
import os
import struct
import zlib
from dataclasses import dataclass, field
from operator import itemgetter
from pathlib import Path
from typing import Any, Callable, Iterable

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Chunk, DataEnd, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from gcs.errors import LogError

__all__ = ["ChannelInfo", "AttachmentInfo", "McapLog", "read_log", "read_attachment", "MAGIC"]

MAGIC = b"\x89MCAP0\r\n"

_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_FULL = struct.Struct("<BQHxxxxQ")  # opcode, length, channel id, (sequence), log time
_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_ATTACHMENT, _OP_DATA_END = 0x03, 0x04, 0x05, 0x09, 0x0F
#: Message index, chunk index, attachment index, statistics, metadata index, summary offset.
_SKIPPED = frozenset((0x07, 0x08, 0x0A, 0x0B, 0x0D, 0x0E))

try:  # the zstandard error class, so that a corrupt chunk counts as a broken record
    from zstandard import ZstdError as _ZstdError
except ImportError:  # pragma: no cover - zstandard comes with mcap
    class _ZstdError(Exception):
        pass


class _Broken(Exception):
    """A record that cannot be read: the data section ends before it."""


#: What reading a damaged record can raise (mcap, struct, decoding, decompression, absurd sizes).
_BROKEN = (_Broken, McapError, struct.error, ValueError, EOFError, IndexError, OverflowError, MemoryError, _ZstdError)

#: Largest chunk this reader decompresses [bytes] (the writer's are about 1 MiB).
MAX_CHUNK_BYTES = 1 << 32


class _Bounded:
    """A read-only view of a file that never reads past its size, so that a damaged length
    field inside a record cannot make the stream reader allocate gigabytes."""

    def __init__(self, f, size: int) -> None:
        self._f, self._size = f, size

    def read(self, n: int = -1) -> bytes:
        left = self._size - self._f.tell()
        if n < 0 or n > left:
            n = max(left, 0)
        return self._f.read(n)

    def tell(self) -> int:
        return self._f.tell()

    def seek(self, pos: int, whence: int = 0) -> int:
        return self._f.seek(pos, whence)


@dataclass(frozen=True)
class ChannelInfo:
    """One channel: id, topic, message encoding, its schema's name and encoding, metadata."""

    id: int
    topic: str
    message_encoding: str
    schema_name: str = ""
    schema_encoding: str = ""
    metadata: dict = field(default_factory=dict)


@dataclass(frozen=True)
class AttachmentInfo:
    """One attachment (name, media type, times [ns], data)."""

    name: str
    media_type: str
    log_time_ns: int
    create_time_ns: int
    data: bytes


@dataclass
class McapLog:
    """What :func:`read_log` read.

    Attributes
    ----------
    path : Path
    truncated : bool
        The file does not end with a valid footer, or a record in it is broken: the
        data after the first broken record are ignored.
    problem : str
        Why it is truncated ("" when it is not).
    profile, library : str
        From the MCAP header.
    channels : dict of int to ChannelInfo
    metadata : list of (name, dict)
    attachments : list of AttachmentInfo
    counts : dict of str to int
        Messages per topic (every topic, kept or not).
    first_ns, last_ns : dict of str to int
        First and last log time per topic [ns].
    messages : dict of str to list of (log_time_ns, bytes)
        The kept topics' messages in log-time order (raw JSON).
    summary_message_count : int or None
        The message count in the file's summary (a finished file only).
    """

    path: Path
    truncated: bool = False
    problem: str = ""
    profile: str = ""
    library: str = ""
    channels: dict[int, ChannelInfo] = field(default_factory=dict)
    metadata: list[tuple[str, dict]] = field(default_factory=list)
    attachments: list[AttachmentInfo] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)
    first_ns: dict[str, int] = field(default_factory=dict)
    last_ns: dict[str, int] = field(default_factory=dict)
    messages: dict[str, list[tuple[int, bytes]]] = field(default_factory=dict)
    summary_message_count: int | None = None

    @property
    def message_count(self) -> int:
        return sum(self.counts.values())

    @property
    def start_ns(self) -> int | None:
        return min(self.first_ns.values()) if self.first_ns else None

    @property
    def end_ns(self) -> int | None:
        return max(self.last_ns.values()) if self.last_ns else None

    @property
    def topics(self) -> list[str]:
        """Topics with messages, sorted."""
        return sorted(self.counts)

    def decoded(self, topic: str) -> list[tuple[int, Any]]:
        """``(log_time_ns, decoded JSON)`` of a kept topic (empty when it has no messages).

        Raises
        ------
        LogError
            For a topic that was not kept, or a message that is not JSON.
        """
        if topic not in self.messages:
            if topic not in self.counts:
                return []
            raise LogError(f"{self.path}: topic {topic} was not read")
        out = []
        loads = json.loads
        for t, data in self.messages[topic]:
            try:
                out.append((t, loads(data.decode())))  # str: json.loads skips its encoding detection
            except ValueError:
                raise LogError(f"{self.path}: a {topic} message at {t} ns is not JSON") from None
        return out

    def metadata_dict(self, name: str) -> dict | None:
        """The last metadata record called ``name`` (None if there is none)."""
        found = [d for n, d in self.metadata if n == name]
        return found[-1] if found else None

    def attachment(self, name: str) -> AttachmentInfo | None:
        """The last attachment called ``name`` (None if there is none)."""
        found = [a for a in self.attachments if a.name == name]
        return found[-1] if found else None


def _open_checked(path: Path):
    if not path.exists():
        raise LogError(f"{path}: no such file")
    if path.is_dir():
        raise LogError(f"{path}: is a directory, not an MCAP log")
    try:
        f = open(path, "rb")
    except OSError as exc:
        raise LogError(f"{path}: cannot read: {exc.strerror or exc}") from None
    head = f.read(len(MAGIC))
    if not head:
        f.close()
        raise LogError(f"{path}: empty file, not an MCAP log")
    if head != MAGIC:
        f.close()
        raise LogError(f"{path}: not an MCAP log (it does not start with the MCAP magic bytes)")
    f.seek(0)
    return f


def _summary_count(f) -> int | None:
    """Message count from the summary of a finished file (None without a readable summary)."""
    try:
        summary = make_reader(f).get_summary()
    except _BROKEN + (OSError,):
        return None
    finally:
        f.seek(0)
    if summary is None or summary.statistics is None:
        return None
    return int(summary.statistics.message_count)


def _decompress(chunk: Chunk) -> bytes:
    if not 0 <= chunk.uncompressed_size <= MAX_CHUNK_BYTES:
        raise _Broken(f"chunk claims {chunk.uncompressed_size} bytes uncompressed")
    comp = chunk.compression
    if comp == "":
        data = chunk.data
    elif comp == "zstd":
        import zstandard
        data = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
    elif comp == "lz4":
        try:
            import lz4.frame
        except ImportError:
            raise LogError("this log has lz4-compressed chunks: install the lz4 package to read it") from None
        try:
            data = lz4.frame.decompress(chunk.data)
        except RuntimeError as exc:
            raise _Broken(f"lz4: {exc}") from None
    else:
        raise _Broken(f"unknown chunk compression {comp!r}")
    if len(data) != chunk.uncompressed_size:
        raise _Broken(f"chunk decompresses to {len(data)} bytes, expected {chunk.uncompressed_size}")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise _Broken("chunk CRC mismatch")
    return data


class _Collector:
    """Counts every message and keeps (or hands to ``sink``) those of the wanted topics.

    Per channel, a kept topic's ``(t, data)`` is appended to its list (or passed to the
    sink); other topics only update a ``[count, first, last]`` record.
    """

    def __init__(self, log: McapLog, keep: Callable[[str], bool],
                 sink: Callable[[str, int, bytes], None] | None = None) -> None:
        self.log = log
        self.keep = keep
        self.sink = sink
        self.schemas: dict[int, Schema] = {}
        self._topic: dict[int, str] = {}
        self._kept: dict[int, Any] = {}   # channel id -> append((t, data)) of a kept topic
        self._timed: dict[int, Any] = {}  # channel id -> count(t) of a topic only counted (or sunk)
        self._stats: dict[int, list[int]] = {}

    def schema(self, s: Schema) -> None:
        self.schemas[s.id] = s

    def channel(self, c: Channel) -> None:
        sch = self.schemas.get(c.schema_id)
        self.log.channels[c.id] = ChannelInfo(c.id, c.topic, c.message_encoding, sch.name if sch else "",
                                              sch.encoding if sch else "", dict(c.metadata))
        self._bind(c.id, c.topic)

    def _counter(self, cid: int) -> Callable[[int], None]:
        st = self._stats.setdefault(cid, [0, 1 << 63, -(1 << 63)])

        def count(t: int) -> None:
            st[0] += 1
            if t < st[1]:
                st[1] = t
            if t > st[2]:
                st[2] = t
        return count

    def _bind(self, cid: int, topic: str) -> None:
        if cid in self._topic:
            if self._topic[cid] == topic:
                return  # the same channel again (e.g. repeated in the summary)
            self._kept.pop(cid, None)
            self._timed.pop(cid, None)
        self._topic[cid] = topic
        keep = self.keep(topic)
        if keep and self.sink is None:
            self._kept[cid] = self.log.messages.setdefault(topic, []).append
            return
        count = self._counter(cid)
        if keep:
            sink = self.sink

            def deliver(item: tuple[int, bytes]) -> None:
                count(item[0])
                sink(topic, item[0], item[1])  # type: ignore[misc]
            self._kept[cid] = deliver
        else:
            self._timed[cid] = count

    def message(self, cid: int, t: int, data: bytes | memoryview) -> None:
        if cid not in self._topic:
            self._bind(cid, f"<channel {cid}>")
        kept = self._kept.get(cid)
        if kept is not None:
            kept((t, bytes(data)))
        else:
            self._timed[cid](t)

    def chunk_records(self, data: bytes) -> None:
        """Parse the records of a decompressed chunk (messages by hand: the hot path)."""
        n = len(data)
        off = 0
        head = _RECORD_HEAD.unpack_from
        full = _MESSAGE_FULL.unpack_from
        kept_of, timed_of = self._kept, self._timed
        while off < n:
            if off + 31 <= n:
                op, length, cid, t = full(data, off)
            elif off + 9 <= n:
                op, length = head(data, off)
                cid = t = 0
            else:
                raise _Broken("record header past the end of its chunk")
            end = off + 9 + length
            if end > n:
                raise _Broken("record past the end of its chunk")
            if op == _OP_MESSAGE:
                if length < 22:
                    raise _Broken("message record too short")
                kept = kept_of.get(cid)
                if kept is not None:
                    kept((t, data[off + 31:end]))
                else:
                    timed = timed_of.get(cid)
                    if timed is not None:
                        timed(t)
                    else:
                        self.message(cid, t, data[off + 31:end])
            elif op == _OP_SCHEMA:
                self.schema(Schema.read(ReadDataStream(io.BytesIO(data[off + 9:end]))))
            elif op == _OP_CHANNEL:
                self.channel(Channel.read(ReadDataStream(io.BytesIO(data[off + 9:end]))))
            off = end

    def finish(self) -> None:
        log = self.log
        key = itemgetter(0)
        for topic, lst in log.messages.items():
            lst.sort(key=key)  # stable: equal times keep the file's order; linear when already sorted
            if lst:
                log.counts[topic] = len(lst)
                log.first_ns[topic] = lst[0][0]
                log.last_ns[topic] = lst[-1][0]
        for cid, (n, lo, hi) in self._stats.items():
            if not n:
                continue
            topic = self._topic[cid]
            log.counts[topic] = log.counts.get(topic, 0) + n
            log.first_ns[topic] = min(lo, log.first_ns.get(topic, lo))
            log.last_ns[topic] = max(hi, log.last_ns.get(topic, hi))
        for topic in [t for t, lst in log.messages.items() if not lst]:
            del log.messages[topic]


def _keep_function(topics: Iterable[str] | Callable[[str], bool] | None | str) -> Callable[[str], bool]:
    if topics is None:
        return lambda topic: False
    if topics == "all":
        return lambda topic: True
    if callable(topics):
        return topics
    wanted = set(topics)
    prefixes = tuple(t[:-1] for t in wanted if t.endswith("*"))
    return lambda topic: topic in wanted or (bool(prefixes) and topic.startswith(prefixes))


def read_log(path: str | Path, topics: Iterable[str] | Callable[[str], bool] | str | None = "all", *,
             sink: Callable[[str, int, bytes], None] | None = None) -> McapLog:
    """Read an MCAP log, keeping the messages of ``topics``.

    Parameters
    ----------
    path : path-like
    topics : "all", None, iterable of str or callable
        Topics whose messages to keep (``"/mavlink/in/*"`` keeps a prefix); None keeps
        none (counts, metadata and attachments only).  Every message is counted.
    sink : callable (topic, log_time_ns, data) or None
        Hand the kept topics' messages to this, in file order, instead of keeping them
        (``McapLog.messages`` stays empty for them): for logs too big to hold.

    Returns
    -------
    McapLog

    Raises
    ------
    LogError
        Missing file, a directory, an empty file or not an MCAP file.
    """
    p = Path(path)
    f = _open_checked(p)
    log = McapLog(p)
    col = _Collector(log, _keep_function(topics), sink)
    footer = False
    size = os.fstat(f.fileno()).st_size
    try:
        log.summary_message_count = _summary_count(f)
        reader = StreamReader(_Bounded(f, size), skip_magic=False, emit_chunks=True, validate_crcs=False,
                              record_size_limit=1 << 34)
        records = reader.records
        while True:
            pos = f.tell()
            if pos >= len(MAGIC):
                # A damaged length would make the stream reader swallow the rest of the file: check it.
                head = f.read(9)
                if len(head) == 9:
                    opcode, length = _RECORD_HEAD.unpack(head)
                    if pos + 9 + length > size:
                        log.truncated = True
                        log.problem = (f"broken record at byte {pos}: it claims {length} bytes but the file ends "
                                       f"{size - pos - 9} bytes later (cut short, or damaged); nothing after it "
                                       "was read")
                        break
                    if opcode in _SKIPPED:
                        f.seek(pos + 9 + length)  # indexes and statistics: not needed, slow to parse
                        continue
                f.seek(pos)
            try:
                rec = next(records)
            except StopIteration:
                break
            except _BROKEN as exc:
                log.truncated = True
                if pos >= size:
                    log.problem = _NO_FOOTER
                else:
                    log.problem = _describe(exc, max(pos, len(MAGIC)), "")
                break
            try:
                if isinstance(rec, Chunk):
                    col.chunk_records(_decompress(rec))
                elif isinstance(rec, Message):
                    col.message(rec.channel_id, rec.log_time, rec.data)
                elif isinstance(rec, Schema):
                    col.schema(rec)
                elif isinstance(rec, Channel):
                    col.channel(rec)
                elif isinstance(rec, Header):
                    log.profile, log.library = rec.profile, rec.library
                elif isinstance(rec, Metadata):
                    log.metadata.append((rec.name, dict(rec.metadata)))
                elif isinstance(rec, Attachment):
                    log.attachments.append(AttachmentInfo(rec.name, rec.media_type, rec.log_time, rec.create_time,
                                                          bytes(rec.data)))
                elif isinstance(rec, Footer):
                    footer = True
                elif isinstance(rec, DataEnd):
                    pass
            except _BROKEN as exc:
                log.truncated = True
                log.problem = _describe(exc, pos, type(rec).__name__)
                break
    except OSError as exc:
        raise LogError(f"{p}: cannot read: {exc.strerror or exc}") from None
    finally:
        f.close()
    col.finish()
    if not log.truncated and not footer:
        log.truncated = True
        log.problem = _NO_FOOTER
    return log


_NO_FOOTER = "the file ends without a footer (the writer did not finish it: killed or crashed?)"


def _describe(exc: BaseException, pos: int, what: str) -> str:
    from mcap.exceptions import EndOfFile
    if isinstance(exc, (EndOfFile, EOFError)) or (isinstance(exc, struct.error) and "unpack requires" in str(exc)):
        reason = "the file ends in the middle of a record"
    else:
        reason = str(exc) or type(exc).__name__
    rec = f"{what} record" if what else "record"
    return f"broken {rec} at byte {pos}: {reason}; nothing after it was read"


def read_attachment(path: str | Path, name: str) -> AttachmentInfo | None:
    """The last attachment called ``name``, found without reading the messages (None if there is none).

    A finished file is looked up in its summary's attachment index; a truncated one is scanned
    record by record from the start, stepping over the chunks.

    Raises
    ------
    LogError
        As :func:`read_log` for input that is not an MCAP log.
    """
    p = Path(path)
    f = _open_checked(p)
    size = os.fstat(f.fileno()).st_size
    found: Attachment | None = None
    try:
        try:
            summary = make_reader(f).get_summary()
        except _BROKEN:
            summary = None
        if summary is not None:
            try:
                for idx in summary.attachment_indexes:
                    if idx.name == name:
                        f.seek(idx.offset)
                        rec = next(StreamReader(_Bounded(f, size), skip_magic=True).records)
                        if isinstance(rec, Attachment):
                            found = rec
            except _BROKEN + (StopIteration,):
                found, summary = None, None
        if summary is None:
            pos = len(MAGIC)
            while pos + 9 <= size:
                f.seek(pos)
                op, length = _RECORD_HEAD.unpack(f.read(9))
                if pos + 9 + length > size or op == _OP_DATA_END:
                    break
                if op == _OP_ATTACHMENT:
                    try:
                        rec = Attachment.read(ReadDataStream(io.BytesIO(f.read(length))))
                    except _BROKEN:
                        break
                    if rec.name == name:
                        found = rec
                pos += 9 + length
    except OSError as exc:
        raise LogError(f"{p}: cannot read: {exc.strerror or exc}") from None
    finally:
        f.close()
    if found is None:
        return None
    return AttachmentInfo(found.name, found.media_type, found.log_time, found.create_time, bytes(found.data))
