"""MAVLink framing of the vehicle side: decode per peer, classify and count bad input, sign, encode.

Decoding uses pymavlink's generated ``ardupilotmega`` dialect with robust
parsing, one parser per peer (a TCP connection, a UDP sender, the serial
line).  Bytes that are not a valid frame for us never raise; they are
counted in :class:`LinkCounters`:

* ``garbage_bytes`` / ``bad_prefix``: bytes skipped while looking for a frame start;
* ``bad_crc``: frames whose checksum (with CRC extra) fails;
* ``malformed``: bad length, bad flags, unpack failures, a frame cut at the
  end of a UDP datagram (``truncated``), parser failures;
* ``unknown``: valid frames of message ids the dialect does not know;
* ``bad_signature`` / ``unsigned``: with a signing key, frames with a wrong
  signature (or stale timestamp) and unsigned frames (RADIO_STATUS excepted,
  as ArduPilot does for SiK radios).

Signing (MAVLink 2): with ``signing_key`` set, outgoing frames are signed
and every parser shares one :class:`MAVLinkSigning` state, so the outgoing
timestamp follows the newest valid incoming one (the ground station's clock;
there is no wall clock here), as ArduPilot does without GPS time.
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass
from typing import Hashable

from pymavlink.dialects.v20 import ardupilotmega as mavlink

__all__ = ["LinkCounters", "MavlinkEndpoint"]

log = logging.getLogger(__name__)

_RADIO_STATUS = mavlink.MAVLINK_MSG_ID_RADIO_STATUS
_MAX_PARSERS = 64


@dataclass
class LinkCounters:
    """What arrived and what was rejected (cumulative)."""

    bytes_in: int = 0
    frames_in: int = 0
    garbage_bytes: int = 0
    bad_prefix: int = 0
    bad_crc: int = 0
    malformed: int = 0
    truncated: int = 0
    unknown: int = 0
    bad_signature: int = 0
    unsigned: int = 0
    wrong_target: int = 0
    unhandled: int = 0
    handler_errors: int = 0
    frames_out: int = 0
    bytes_out: int = 0
    lost_in: int = 0
    lost_out: int = 0
    dropped_out: int = 0

    @property
    def rejected(self) -> int:
        """Everything that was not a valid frame for us."""
        return (self.bad_prefix + self.bad_crc + self.malformed + self.unknown + self.bad_signature
                + self.unsigned + self.wrong_target)

    def as_dict(self) -> dict[str, int]:
        """Plain dictionary (a snapshot)."""
        return asdict(self)


def _reset(parser: mavlink.MAVLink) -> None:
    parser.buf = bytearray()
    parser.buf_index = 0
    parser.expected_length = mavlink.HEADER_LEN_V1 + 2
    parser.have_prefix_error = False


class MavlinkEndpoint:
    """Encoder and per-peer decoders of the vehicle.

    Parameters
    ----------
    system_id, component_id : int
        Our MAVLink address (ArduPilot: 1, MAV_COMP_ID_AUTOPILOT1 = 1).
    signing_key : bytes or None
        32-byte MAVLink 2 secret key; None = no signing.
    counters : LinkCounters or None
    """

    def __init__(self, system_id: int = 1, component_id: int = 1, signing_key: bytes | None = None,
                 counters: LinkCounters | None = None) -> None:
        self.counters = counters or LinkCounters()
        self.mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self._signing = self.mav.signing
        if signing_key is not None:
            if len(signing_key) != 32:
                raise ValueError("signing key must be 32 bytes")
            self._signing.secret_key = bytes(signing_key)
            self._signing.sign_outgoing = True
            self._signing.link_id = 0
            self._signing.allow_unsigned_callback = lambda mav, msg_id: msg_id == _RADIO_STATUS
        self._parsers: dict[Hashable, mavlink.MAVLink] = {}

    @property
    def system_id(self) -> int:
        return self.mav.srcSystem

    @system_id.setter
    def system_id(self, value: int) -> None:
        self.mav.srcSystem = int(value)

    @property
    def signing(self) -> bool:
        """True when a signing key is configured."""
        return self._signing.secret_key is not None

    def _parser(self, peer: Hashable) -> mavlink.MAVLink:
        p = self._parsers.get(peer)
        if p is None:
            if len(self._parsers) >= _MAX_PARSERS:
                self._parsers.pop(next(iter(self._parsers)))
            p = mavlink.MAVLink(None, srcSystem=self.mav.srcSystem, srcComponent=self.mav.srcComponent)
            p.robust_parsing = True
            p.signing = self._signing
            self._parsers[peer] = p
        return p

    def forget(self, peer: Hashable) -> None:
        """Drop the parser of a peer that went away."""
        self._parsers.pop(peer, None)

    def decode(self, peer: Hashable, data: bytes, datagram: bool = False) -> list[mavlink.MAVLink_message]:
        """Valid messages in ``data`` received from ``peer``.

        Parameters
        ----------
        peer : hashable
            Who sent it (one parser state per peer).
        data : bytes
        datagram : bool
            ``data`` is a whole UDP datagram: a frame cut at its end is dropped
            (counted as truncated) instead of waiting for more bytes.
        """
        c = self.counters
        c.bytes_in += len(data)
        p = self._parser(peer)
        out: list[mavlink.MAVLink_message] = []
        chunk: bytes = data
        for _ in range(len(data) + 2):
            try:
                m = p.parse_char(chunk)
            except Exception as exc:  # noqa: BLE001 - pymavlink may raise anything on hostile input
                log.debug("parser failure from %s: %r", peer, exc)
                c.malformed += 1
                _reset(p)
                break
            chunk = b""
            if m is None:
                break
            self._classify(m, out)
            if not p.buf:  # pymavlink empties the buffer once everything is parsed
                break
        if datagram and p.buf_len() > 0:
            c.truncated += 1
            c.malformed += 1
            _reset(p)
        return out

    def _classify(self, m: mavlink.MAVLink_message, out: list) -> None:
        c = self.counters
        kind = m.get_type()
        if kind == "BAD_DATA":
            reason = getattr(m, "reason", "")
            data = bytes(getattr(m, "data", b""))
            if reason == "Bad prefix":
                c.bad_prefix += 1
                c.garbage_bytes += len(data)
            elif reason.startswith("invalid MAVLink CRC"):
                c.bad_crc += 1
            elif reason == "Invalid signature":
                if len(data) > 2 and data[0] == mavlink.PROTOCOL_MARKER_V2 and data[2] & mavlink.MAVLINK_IFLAG_SIGNED:
                    c.bad_signature += 1
                else:
                    c.unsigned += 1
            else:
                c.malformed += 1
            return
        if kind.startswith("UNKNOWN_"):
            c.unknown += 1
            return
        c.frames_in += 1
        out.append(m)

    def encode(self, msg: mavlink.MAVLink_message) -> bytes:
        """Frame ``msg`` (MAVLink 2, signed if configured) and advance the sequence number."""
        buf = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) & 0xFF
        self.counters.frames_out += 1
        self.counters.bytes_out += len(buf)
        return buf
