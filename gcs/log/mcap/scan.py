"""The pieces of the robust MCAP reader: bounded reads, chunk checks and the message collector.

:class:`Collector` counts every message and keeps (or hands on) those of the wanted topics,
parsing the records of a decompressed chunk by hand (the hot path of every ``gcs log`` tool);
:func:`decompress_chunk` checks a chunk's sizes and CRC; :data:`BROKEN` is what reading a
damaged record can raise.
"""

from __future__ import annotations

import io
import json
import struct
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from operator import itemgetter
from pathlib import Path
from typing import Any

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.records import Channel, Chunk, Schema

from gcs.errors import LogError

__all__ = [
    "BROKEN",
    "MAGIC",
    "MAX_CHUNK_BYTES",
    "OP_ATTACHMENT",
    "OP_DATA_END",
    "RECORD_HEAD",
    "SKIPPED",
    "AttachmentInfo",
    "BoundedFile",
    "BrokenRecord",
    "ChannelInfo",
    "Collector",
    "McapLog",
    "decompress_chunk",
    "open_checked",
]

MAGIC = b"\x89MCAP0\r\n"

RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_FULL = struct.Struct("<BQHxxxxQ")  # opcode, length, channel id, (sequence), log time
_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE = 0x03, 0x04, 0x05
OP_ATTACHMENT, OP_DATA_END = 0x09, 0x0F
#: Message index, chunk index, attachment index, statistics, metadata index, summary offset.
SKIPPED = frozenset((0x07, 0x08, 0x0A, 0x0B, 0x0D, 0x0E))
#: Largest chunk this reader decompresses [bytes] (the writer's are about 1 MiB).
MAX_CHUNK_BYTES = 1 << 32

try:  # the zstandard error class, so that a corrupt chunk counts as a broken record
    from zstandard import ZstdError as _ZstdError
except ImportError:  # pragma: no cover - zstandard comes with mcap
    class _ZstdError(Exception):
        pass


class BrokenRecord(Exception):
    """A record that cannot be read: the data section ends before it."""


#: What reading a damaged record can raise (mcap, struct, decoding, decompression, absurd sizes).
BROKEN = (BrokenRecord, McapError, struct.error, ValueError, EOFError, IndexError, OverflowError, MemoryError,
          _ZstdError)


class BoundedFile:
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
    """What :func:`gcs.log.mcap.reader.read_log` read.

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


def decompress_chunk(chunk: Chunk) -> bytes:
    """The records of a chunk, checked (size, CRC); :class:`BrokenRecord` when they are damaged."""
    if not 0 <= chunk.uncompressed_size <= MAX_CHUNK_BYTES:
        raise BrokenRecord(f"chunk claims {chunk.uncompressed_size} bytes uncompressed")
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
            raise BrokenRecord(f"lz4: {exc}") from None
    else:
        raise BrokenRecord(f"unknown chunk compression {comp!r}")
    if len(data) != chunk.uncompressed_size:
        raise BrokenRecord(f"chunk decompresses to {len(data)} bytes, expected {chunk.uncompressed_size}")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise BrokenRecord("chunk CRC mismatch")
    return data


class Collector:
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
        head = RECORD_HEAD.unpack_from
        full = _MESSAGE_FULL.unpack_from
        kept_of, timed_of = self._kept, self._timed
        while off < n:
            if off + 31 <= n:
                op, length, cid, t = full(data, off)
            elif off + 9 <= n:
                op, length = head(data, off)
                cid = t = 0
            else:
                raise BrokenRecord("record header past the end of its chunk")
            end = off + 9 + length
            if end > n:
                raise BrokenRecord("record past the end of its chunk")
            if op == _OP_MESSAGE:
                if length < 22:
                    raise BrokenRecord("message record too short")
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


def open_checked(path: Path):
    """``path`` opened for reading, after checking it is an MCAP file (:class:`LogError` otherwise)."""
    if not path.exists():
        raise LogError(f"{path}: no such file")
    if path.is_dir():
        raise LogError(f"{path}: is a directory, not an MCAP log")
    try:
        f = open(path, "rb")  # noqa: SIM115 - handed to the caller, who closes it
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
