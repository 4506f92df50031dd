"""The rig protocol's framing: API-mode-2 escaping, encoding, and the incremental decoder.

Frame: 0x7E, 16-bit big-endian length of the frame data, frame data (type byte + payload),
checksum = 0xFF - (sum of the frame data & 0xFF); 0x7E, 0x7D, 0x11, 0x13 after the start are
sent as 0x7D, byte ^ 0x20.  :class:`RigDecoder` never raises: garbled bytes, bad checksums and
lengths, unknown types and invalid values are counted in :class:`DecoderCounters` and skipped.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass, fields
from collections.abc import Iterable

from quadrotor.errors import ProtocolError
from quadrotor.rig_protocol.messages import (ESCAPE, MAX_FRAME_DATA, MESSAGE_TYPES, SPECIAL_BYTES, START, XOR,
                                             Message, MessageBase)

_SPECIAL_RE = re.compile(b"[\x7e\x7d\x11\x13]")
_ESCAPED = {b: bytes((ESCAPE, b ^ XOR)) for b in SPECIAL_BYTES}


def escape(data: bytes) -> bytes:
    """API-mode-2 escaping of the bytes after the start delimiter."""
    if _SPECIAL_RE.search(data) is None:
        return data
    return _SPECIAL_RE.sub(lambda m: _ESCAPED[m.group()[0]], data)


def encode(msg: Message) -> bytes:
    """The escaped frame of a message.

    Raises
    ------
    ProtocolError
        A field does not fit its wire type (e.g. PWM above 1023, seq above 65535,
        a float beyond float32 range).
    """
    try:
        payload = msg.pack()
    except (struct.error, OverflowError) as exc:
        raise ProtocolError(f"{type(msg).__name__}: {exc}") from None
    data = bytes((msg.TYPE,)) + payload
    n = len(data)
    checksum = 0xFF - (sum(data) & 0xFF)
    return bytes((START,)) + escape(bytes((n >> 8, n & 0xFF)) + data + bytes((checksum,)))


@dataclass
class DecoderCounters:
    """What a :class:`RigDecoder` accepted and dropped.

    Attributes
    ----------
    frames : int
        Valid messages returned.
    checksum_errors : int
        Complete frames whose checksum did not match.
    length_errors : int
        Length field 0 or above :data:`MAX_FRAME_DATA`, or a payload too long / too
        short for its type (checksum good).
    unknown_types : int
        Good frames of a type this decoder does not accept.
    invalid_values : int
        Good frames with an impossible field (PWM above 1023, unknown state or result).
    truncated_frames : int
        Frames cut short by a new start delimiter.
    discarded_bytes : int
        Bytes skipped while hunting for a start delimiter.
    """

    frames: int = 0
    checksum_errors: int = 0
    length_errors: int = 0
    unknown_types: int = 0
    invalid_values: int = 0
    truncated_frames: int = 0
    discarded_bytes: int = 0

    @property
    def errors(self) -> int:
        """Frames dropped for any reason."""
        return (self.checksum_errors + self.length_errors + self.unknown_types + self.invalid_values
                + self.truncated_frames)

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


_HUNT, _FRAME = 0, 1


class RigDecoder:
    """Incremental decoder of the byte stream; never raises on any bytes.

    Parameters
    ----------
    accept : iterable of message classes or None
        Types to return (e.g. :data:`TO_PC` on the ground station); other types,
        known or not, count as ``unknown_types``.  None: all.
    max_frame_data : int
        Largest accepted length field [bytes].

    Notes
    -----
    Escapes split across :meth:`feed` calls are handled.  A checksum, length or
    value error drops the frame and the decoder hunts for the next unescaped
    0x7E; an unescaped 0x7E inside a frame aborts it (``truncated_frames``) and
    starts a new one, so the frame after any garbage is decoded.
    """

    def __init__(self, accept: Iterable[type[MessageBase]] | None = None, max_frame_data: int = MAX_FRAME_DATA) -> None:
        classes = MESSAGE_TYPES.values() if accept is None else accept
        self._types: dict[int, type[MessageBase]] = {c.TYPE: c for c in classes}
        self._max = int(max_frame_data)
        self.counters = DecoderCounters()
        self._state = _HUNT
        self._esc = False
        self._buf = bytearray()
        self._need = 2

    def reset(self) -> None:
        """Forget a partial frame (counters are kept)."""
        self._state = _HUNT
        self._esc = False
        self._buf.clear()

    def _start(self) -> None:
        self._state = _FRAME
        self._esc = False
        self._buf.clear()
        self._need = 2  # the length field first

    def feed(self, data: bytes | bytearray | memoryview) -> list[Message]:
        """Messages completed by ``data`` (in order)."""
        out: list[Message] = []
        data = bytes(data)
        n = len(data)
        i = 0
        buf = self._buf
        c = self.counters
        while i < n:
            if self._state == _HUNT:
                j = data.find(START, i)
                if j < 0:
                    c.discarded_bytes += n - i
                    break
                c.discarded_bytes += j - i
                i = j + 1
                self._start()
                continue
            b = data[i]
            if b == START:
                c.truncated_frames += 1
                i += 1
                self._start()
                continue
            if self._esc:
                self._esc = False
                buf.append(b ^ XOR)
                i += 1
            elif b == ESCAPE:
                self._esc = True
                i += 1
                continue
            else:
                # Copy the run of plain bytes up to what the frame still needs.
                end = min(n, i + self._need - len(buf))
                k = data.find(START, i, end)
                if k >= 0:
                    end = k
                k = data.find(ESCAPE, i, end)
                if k >= 0:
                    end = k
                buf += data[i:end]
                i = end
            if len(buf) < self._need:
                continue
            if self._need == 2:
                length = (buf[0] << 8) | buf[1]
                if length == 0 or length > self._max:
                    c.length_errors += 1
                    self._state = _HUNT
                    continue
                self._need = 3 + length
                continue
            msg = self._finish(buf)
            self._state = _HUNT
            if msg is not None:
                out.append(msg)
        return out

    def _finish(self, buf: bytearray) -> Message | None:
        c = self.counters
        if sum(buf[2:]) & 0xFF != 0xFF:
            c.checksum_errors += 1
            return None
        cls = self._types.get(buf[2])
        if cls is None:
            c.unknown_types += 1
            return None
        if len(buf) - 4 != cls.STRUCT.size:
            c.length_errors += 1
            return None
        try:
            msg = cls.unpack(bytes(buf[3:-1]))
        except ValueError:
            c.invalid_values += 1
            return None
        c.frames += 1
        return msg  # type: ignore[return-value]
