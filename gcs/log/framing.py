"""The one framing of the log pipeline: length-prefixed pickled lists of records.

A frame is an 8-byte little-endian length and a pickle of a list of records
(:mod:`gcs.log.records`), each in its *wire form*: a plain tuple ``(code, *fields)`` (a Tick's
:class:`~gcs.log.records.LoopTiming` as a plain tuple too), rebuilt as its record type on the
other side (:func:`from_wire`).  The C pickler takes plain tuples several times faster than
NamedTuples, and the control loop pays for the pickling: the flight recorder builds its
per-tick records in their wire form directly (:func:`code_of` gives the codes).  Both
directions of the writer process use frames: records to it, :class:`~gcs.log.records.LogDone`
/ :class:`~gcs.log.records.LogFailed` back.
"""

from __future__ import annotations

import pickle
import struct
from collections.abc import Iterable
from typing import Any, BinaryIO

from gcs.log.records import RECORDS, LoopTiming, Tick

__all__ = ["HEAD", "code_of", "from_wire", "pack", "pack_wire", "read_frame", "to_wire", "unpack", "write_frame"]

#: The length before each frame.
HEAD = struct.Struct("<Q")

_CODES = {cls: i for i, cls in enumerate(RECORDS)}
_TICK = _CODES[Tick]
_TIMING = 1 + Tick._fields.index("timing")  # in the wire form, after the code


def code_of(cls: type) -> int:
    """The wire code of a record type."""
    return _CODES[cls]


def to_wire(record: Any) -> tuple:
    """The wire form of a record.

    Raises
    ------
    TypeError
        For something that is not a record of :mod:`gcs.log.records`.
    """
    code = _CODES.get(type(record))
    if code is None:
        raise TypeError(f"not a log record: {record!r:.80}")
    if code == _TICK and record.timing is not None:
        return (code, *record[:_TIMING - 1], tuple(record.timing), *record[_TIMING:])
    return (code, *record)


def from_wire(wire: tuple) -> Any:
    """The record of a wire form (ValueError, TypeError or IndexError for one that is not)."""
    cls = RECORDS[wire[0]]
    rec = cls._make(wire[1:])
    if cls is Tick and rec.timing is not None:
        rec = rec._replace(timing=LoopTiming._make(rec.timing))
    return rec


def pack_wire(wire: Iterable[tuple]) -> bytes:
    """One frame of records in their wire form."""
    data = pickle.dumps(wire if isinstance(wire, list) else list(wire), protocol=pickle.HIGHEST_PROTOCOL)
    return HEAD.pack(len(data)) + data


def pack(records: Iterable[Any]) -> bytes:
    """One frame of records (TypeError for something that is not one)."""
    return pack_wire([to_wire(r) for r in records])


def unpack(payload: bytes) -> list:
    """The records of a frame's payload (the pickle after the length).

    Raises
    ------
    ValueError, TypeError, IndexError, pickle.UnpicklingError
        For a payload that is not a frame of records.
    """
    return [from_wire(w) for w in pickle.loads(payload)]


def write_frame(stream: BinaryIO, records: Iterable[Any]) -> None:
    """Write one frame and flush."""
    stream.write(pack(records))
    stream.flush()


def read_frame(stream: BinaryIO) -> list | None:
    """The records of the next frame, or None at the end of the stream (or of a frame cut short)."""
    head = stream.read(HEAD.size)
    if len(head) < HEAD.size:
        return None
    (n,) = HEAD.unpack(head)
    data = stream.read(n)
    if len(data) < n:
        return None
    return unpack(data)
