"""Read an MCAP file robustly, including one whose writer was killed (no summary, no footer).

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
import os
import struct
from collections.abc import Callable, Iterable
from pathlib import Path

from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Chunk, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from gcs.errors import LogError
from gcs.log.mcap.scan import (
    BROKEN,
    MAGIC,
    OP_ATTACHMENT,
    OP_DATA_END,
    RECORD_HEAD,
    SKIPPED,
    AttachmentInfo,
    BoundedFile,
    ChannelInfo,
    Collector,
    McapLog,
    decompress_chunk,
    open_checked,
)

__all__ = ["MAGIC", "AttachmentInfo", "ChannelInfo", "McapLog", "read_attachment", "read_log"]

_NO_FOOTER = "the file ends without a footer (the writer did not finish it: killed or crashed?)"


def _summary_count(f) -> int | None:
    """Message count from the summary of a finished file (None without a readable summary)."""
    try:
        summary = make_reader(f).get_summary()
    except (*BROKEN, OSError):
        return None
    finally:
        f.seek(0)
    if summary is None or summary.statistics is None:
        return None
    return int(summary.statistics.message_count)


def _keep_function(topics: Iterable[str] | Callable[[str], bool] | str | None) -> Callable[[str], bool]:
    if topics is None:
        return lambda topic: False
    if topics == "all":
        return lambda topic: True
    if callable(topics):
        return topics
    wanted = set(topics)
    prefixes = tuple(t[:-1] for t in wanted if t.endswith("*"))
    return lambda topic: topic in wanted or (bool(prefixes) and topic.startswith(prefixes))


def _describe(exc: BaseException, pos: int, what: str) -> str:
    from mcap.exceptions import EndOfFile
    if isinstance(exc, (EndOfFile, EOFError)) or (isinstance(exc, struct.error) and "unpack requires" in str(exc)):
        reason = "the file ends in the middle of a record"
    else:
        reason = str(exc) or type(exc).__name__
    rec = f"{what} record" if what else "record"
    return f"broken {rec} at byte {pos}: {reason}; nothing after it was read"


def _dispatch(rec, log: McapLog, col: Collector) -> bool:
    """Take one record of the data section; True for the footer."""
    if isinstance(rec, Chunk):
        col.chunk_records(decompress_chunk(rec))
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
        return True
    return False


def _cut_short(f, pos: int, size: int) -> tuple[bool, str]:
    """Look at the record header at ``pos``: (skip it, "") for an index record, (False, problem)
    when its length runs past the end of the file, (False, "") otherwise.  Leaves ``f`` where
    the stream reader must go on."""
    if pos >= len(MAGIC):
        # A damaged length would make the stream reader swallow the rest of the file: check it.
        head = f.read(9)
        if len(head) == 9:
            opcode, length = RECORD_HEAD.unpack(head)
            if pos + 9 + length > size:
                return False, (f"broken record at byte {pos}: it claims {length} bytes but the file ends "
                               f"{size - pos - 9} bytes later (cut short, or damaged); nothing after it was read")
            if opcode in SKIPPED:
                f.seek(pos + 9 + length)  # indexes and statistics: not needed, slow to parse
                return True, ""
        f.seek(pos)
    return False, ""


def _read_records(f, size: int, log: McapLog, col: Collector) -> bool:
    """Read the data section into ``col``; True when the footer was reached (sets ``log.truncated``)."""
    reader = StreamReader(BoundedFile(f, size), skip_magic=False, emit_chunks=True, validate_crcs=False,
                          record_size_limit=1 << 34)
    records = reader.records
    footer = False
    while True:
        pos = f.tell()
        skip, problem = _cut_short(f, pos, size)
        if problem:
            log.truncated, log.problem = True, problem
            return footer
        if skip:
            continue
        try:
            rec = next(records)
        except StopIteration:
            return footer
        except BROKEN as exc:
            log.truncated = True
            log.problem = _NO_FOOTER if pos >= size else _describe(exc, max(pos, len(MAGIC)), "")
            return footer
        try:
            footer = _dispatch(rec, log, col) or footer
        except BROKEN as exc:
            log.truncated, log.problem = True, _describe(exc, pos, type(rec).__name__)
            return footer


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
    f = open_checked(p)
    log = McapLog(p)
    col = Collector(log, _keep_function(topics), sink)
    size = os.fstat(f.fileno()).st_size
    try:
        log.summary_message_count = _summary_count(f)
        footer = _read_records(f, size, log, col)
    except OSError as exc:
        raise LogError(f"{p}: cannot read: {exc.strerror or exc}") from None
    finally:
        f.close()
    col.finish()
    if not log.truncated and not footer:
        log.truncated = True
        log.problem = _NO_FOOTER
    return log


def _indexed_attachment(f, size: int, name: str) -> tuple[bool, Attachment | None]:
    """(summary read, the last attachment ``name``) through a finished file's attachment index."""
    try:
        summary = make_reader(f).get_summary()
    except BROKEN:
        summary = None
    if summary is None:
        return False, None
    found = None
    try:
        for idx in summary.attachment_indexes:
            if idx.name == name:
                f.seek(idx.offset)
                rec = next(StreamReader(BoundedFile(f, size), skip_magic=True).records)
                if isinstance(rec, Attachment):
                    found = rec
    except (*BROKEN, StopIteration):
        return False, None
    return True, found


def _scanned_attachment(f, size: int, name: str) -> Attachment | None:
    """The last attachment ``name``, scanning the records from the start and stepping over the chunks."""
    found = None
    pos = len(MAGIC)
    while pos + 9 <= size:
        f.seek(pos)
        op, length = RECORD_HEAD.unpack(f.read(9))
        if pos + 9 + length > size or op == OP_DATA_END:
            break
        if op == OP_ATTACHMENT:
            try:
                rec = Attachment.read(ReadDataStream(io.BytesIO(f.read(length))))
            except BROKEN:
                break
            if rec.name == name:
                found = rec
        pos += 9 + length
    return found


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
    f = open_checked(p)
    size = os.fstat(f.fileno()).st_size
    try:
        indexed, found = _indexed_attachment(f, size, name)
        if not indexed:
            found = _scanned_attachment(f, size, name)
    except OSError as exc:
        raise LogError(f"{p}: cannot read: {exc.strerror or exc}") from None
    finally:
        f.close()
    if found is None:
        return None
    return AttachmentInfo(found.name, found.media_type, found.log_time, found.create_time, bytes(found.data))
