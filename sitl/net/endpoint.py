"""MAVLink framing of the vehicle side: decode per peer, classify and count bad input, sign, encode.

One parser per peer (robust parsing: bytes that are not a valid frame for us never raise) and one
outgoing sequence number per peer, as ArduPilot keeps them per channel, so a ground station that
sees only its own link's frames sees no gaps.  What :class:`LinkCounters` counts:

* ``garbage_bytes`` / ``bad_prefix``: bytes skipped while looking for a frame start;
* ``bad_crc``: frames whose checksum (with CRC extra) fails;
* ``malformed``: bad length, bad flags, unpack failures, a frame cut at the
  end of a UDP datagram (``truncated``), parser failures;
* ``unknown``: valid frames of message ids the dialect does not know;
* ``non_finite`` (counted by :mod:`sitl.copter.dispatch`): valid frames refused for a
  NaN or infinite value where a number is used;
* ``bad_signature`` / ``replayed`` / ``stale_timestamp`` / ``unsigned``: with a
  signing key, signed frames with a wrong signature, signed frames whose
  timestamp is not after their stream's last one, first frames of a new
  stream more than a minute behind our timestamp, and unsigned frames
  (RADIO_STATUS excepted, as ArduPilot does for SiK radios).

With a signing key every parser shares one signing state and one
:class:`~quadrotor.mavlink.signing.SignatureCheck`; with ``signing_state`` the timestamps are
loaded from that file here and saved by :meth:`MavlinkEndpoint.persist_signing`.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Hashable
from dataclasses import asdict, dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from quadrotor.mavlink.framing import parse_bytes
from quadrotor.mavlink.signing import (REJECT_REPLAYED, REJECT_STALE, SignatureCheck, SigningStateFile,
                                       install_signature_check, setup_signing)

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
    replayed: int = 0
    stale_timestamp: int = 0
    unsigned: int = 0
    wrong_target: int = 0
    non_finite: int = 0
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
        return (self.bad_prefix + self.bad_crc + self.malformed + self.unknown + self.signature_rejected
                + self.wrong_target)

    @property
    def signature_rejected(self) -> int:
        """Frames refused by signing: wrong signature, replayed, stale or unsigned."""
        return self.bad_signature + self.replayed + self.stale_timestamp + self.unsigned

    def as_dict(self) -> dict[str, int]:
        """Plain dictionary (a snapshot)."""
        return asdict(self)


class MavlinkEndpoint:
    """Encoder and per-peer decoders of the vehicle.

    Parameters
    ----------
    system_id, component_id : int
        Our MAVLink address (ArduPilot: 1, MAV_COMP_ID_AUTOPILOT1 = 1).
    signing_key : bytes or None
        32-byte MAVLink 2 secret key; None = no signing.
    counters : LinkCounters or None
    signing_state : str, PathLike or None
        With a key: the file that keeps the signing timestamps across restarts
        (loaded now); None = in memory only.
    """

    def __init__(self, system_id: int = 1, component_id: int = 1, signing_key: bytes | None = None,
                 counters: LinkCounters | None = None, signing_state: str | os.PathLike | None = None) -> None:
        self.counters = counters or LinkCounters()
        self.mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self._signing = self.mav.signing
        self._check: SignatureCheck | None = None
        self._state: SigningStateFile | None = None
        if signing_key is not None:
            if len(signing_key) != 32:
                raise ValueError("signing key must be 32 bytes")
            self._check = setup_signing(self.mav, bytes(signing_key), link_id=0,
                                        allow_unsigned_callback=lambda mav, msg_id: msg_id == _RADIO_STATUS)
            if signing_state is not None:
                self._state = SigningStateFile(signing_state)
                self._state.load(self._signing)
        self._parsers: dict[Hashable, mavlink.MAVLink] = {}
        self._encoders: dict[Hashable, mavlink.MAVLink] = {}
        # Why each signed frame of the chunk being decoded was refused, by id of its buffer (the
        # object pymavlink hands on as BAD_DATA.data): a chunk is parsed whole before its messages
        # are classified, so the check's ``last_rejection`` would only name the chunk's last refusal.
        self._rejections: dict[int, str] = {}

    @property
    def system_id(self) -> int:
        return self.mav.srcSystem

    @system_id.setter
    def system_id(self, value: int) -> None:
        self.mav.srcSystem = int(value)
        for enc in self._encoders.values():
            enc.srcSystem = int(value)

    @property
    def signing(self) -> bool:
        """True when a signing key is configured."""
        return self._signing.secret_key is not None

    @property
    def signature_check(self) -> SignatureCheck | None:
        """The shared signature check (None without a key)."""
        return self._check

    @property
    def signing_timestamp(self) -> int:
        """The local signing timestamp (what the next signed frame carries) [10 us since 2015]."""
        return int(self._signing.timestamp)

    def persist_signing(self, force: bool = False) -> bool:
        """Save the signing state file if due (at most once a second) or ``force``; True if written."""
        if self._state is None:
            return False
        return self._state.maybe_save(self._signing, force=force)

    def _parser(self, peer: Hashable) -> mavlink.MAVLink:
        p = self._parsers.get(peer)
        if p is None:
            if len(self._parsers) >= _MAX_PARSERS:
                self._parsers.pop(next(iter(self._parsers)))
            p = mavlink.MAVLink(None, srcSystem=self.mav.srcSystem, srcComponent=self.mav.srcComponent)
            p.robust_parsing = True
            p.signing = self._signing
            if self._check is not None:
                install_signature_check(p, self._check)
                p.check_signature = self._check_signature  # type: ignore[method-assign]
            self._parsers[peer] = p
        return p

    def _check_signature(self, msgbuf: bytearray, src_system: int, src_component: int) -> bool:
        check = self._check
        assert check is not None
        if check(msgbuf, src_system, src_component):
            return True
        self._rejections[id(msgbuf)] = check.last_rejection
        return False

    def forget(self, peer: Hashable) -> None:
        """Drop the parser and the sequence number of a peer that went away."""
        self._parsers.pop(peer, None)
        self._encoders.pop(peer, None)

    def decode(self, peer: Hashable, data: bytes, datagram: bool = False) -> list[mavlink.MAVLink_message]:
        """Valid messages in ``data`` received from ``peer`` (one parser state per peer).

        ``datagram``: ``data`` is a whole UDP datagram, so a frame cut at its end is dropped
        (counted as truncated) instead of waiting for more bytes.
        """
        c = self.counters
        c.bytes_in += len(data)
        self._rejections.clear()
        msgs, failed, truncated = parse_bytes(self._parser(peer), data, datagram=datagram)
        if failed:
            log.debug("parser failure on %d bytes from %s", len(data), peer)
            c.malformed += 1
        if truncated:
            c.truncated += 1
            c.malformed += 1
        out: list[mavlink.MAVLink_message] = []
        for m in msgs:
            self._classify(m, out)
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
                    why = self._rejections.get(id(m.data), "")
                    if why == REJECT_REPLAYED:
                        c.replayed += 1
                    elif why == REJECT_STALE:
                        c.stale_timestamp += 1
                    else:
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

    def _encoder(self, peer: Hashable | None) -> mavlink.MAVLink:
        if peer is None:
            return self.mav
        e = self._encoders.get(peer)
        if e is None:
            if len(self._encoders) >= _MAX_PARSERS:
                self._encoders.pop(next(iter(self._encoders)))
            e = mavlink.MAVLink(None, srcSystem=self.mav.srcSystem, srcComponent=self.mav.srcComponent)
            e.signing = self._signing
            self._encoders[peer] = e
        return e

    def encode(self, msg: mavlink.MAVLink_message, peer: Hashable | None = None) -> bytes:
        """Frame ``msg`` for ``peer`` (MAVLink 2, signed if configured) and advance that peer's sequence number.

        ``peer`` None uses a sequence shared by no peer (tools and tests).
        """
        enc = self._encoder(peer)
        buf = msg.pack(enc)
        enc.seq = (enc.seq + 1) & 0xFF
        self.counters.frames_out += 1
        self.counters.bytes_out += len(buf)
        return buf
