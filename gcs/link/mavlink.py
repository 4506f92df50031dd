"""MAVLink link to one vehicle, on pymavlink: serial (telemetry radio), UDP or TCP.

:class:`MavlinkLink` wraps a ``pymavlink.mavutil`` connection and keeps to
ArduPilot Copter's conventions (``../shared/DESIGN.md``):

* only frames from ``target_system`` count; others are dropped and counted;
* garbled bytes (``BAD_DATA``) are counted and skipped, never raised;
* UDP: every datagram is parsed on its own (a frame cut at a datagram's end is dropped,
  never joined to the next datagram), and once the vehicle's address is known datagrams
  from any other address are dropped and counted;
* every outgoing message passes the output guard (:mod:`gcs.link.guard`) first;
* :meth:`drain` returns every pending message without blocking (the
  ``recv_match(blocking=False, timeout=0.0)`` trap of pymavlink is avoided by
  calling ``recv_msg`` until it returns None);
* commands wait for their COMMAND_ACK; parameters use PARAM_REQUEST_READ / PARAM_SET;
* optional MAVLink 2 signing.

The link knows nothing of the paper's frame; :mod:`gcs.flight.telemetry` converts.
"""

from __future__ import annotations

import contextlib
import errno
import os
import socket
import time
from dataclasses import dataclass, field
from collections.abc import Callable, Iterable

# MAVLink 2 on the wire (signing, extensions): pymavlink picks its protocol module from this
# variable, so it is set before the dialect is loaded.
os.environ["MAVLINK20"] = "1"

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.errors import GcsError
from gcs.link.guard import OutputGuard, UnsafeCommand
from gcs.link.base import MessageWaiter, serial_errors
from gcs.link.param_encoding import ParamEncodingError, decode_param, encode_param, same_float32
from gcs.link.param_encoding import param_id as _param_id
from quadrotor.mavlink.framing import parse_bytes, reset_parser, restore_unknown_header
from quadrotor.mavlink.signing import SignatureCheck, setup_signing

mavutil.set_dialect("ardupilotmega")

__all__ = ["LinkError", "MavlinkLink", "LinkCounters"]

#: Receive buffer asked for a UDP link [B] (the kernel caps it at net.core.rmem_max): seconds of
#: a 100 Hz telemetry set, so that a stall of this process loses nothing the vehicle said.
UDP_RECEIVE_BUFFER_B = 4 * 1024 * 1024



class LinkError(GcsError):
    """The link failed: no heartbeat, no acknowledgement, refused command, closed port."""

    exit_code = 6


@dataclass
class LinkCounters:
    """What the link saw that was not for us or not readable."""

    received: int = 0
    sent: int = 0
    bad_data: int = 0
    other_system: int = 0
    unsigned_rejected: int = 0
    #: Signed frames whose signature or time stamp failed (another key, a forgery, a replay).
    bad_signature: int = 0
    #: UDP datagrams from an address other than the vehicle's, once it is known (dropped unread).
    other_address: int = 0
    #: UDP datagrams that ended inside a frame (the partial frame is dropped, not joined to the next).
    truncated: int = 0
    #: Frames the parser could not take apart (counted, skipped).
    malformed: int = 0
    #: Outgoing messages the output guard blocked (never sent).
    blocked: int = 0
    by_type: dict[str, int] = field(default_factory=dict)


class MavlinkLink(MessageWaiter):
    """A MAVLink connection to one vehicle.

    Parameters
    ----------
    url : str
        A serial device (``/dev/ttyUSB0``) or pymavlink URL (``udpin:0.0.0.0:14550``,
        ``udpout:127.0.0.1:14550``, ``tcp:127.0.0.1:5760``).
    baud : int
        Serial baud rate (ignored for UDP/TCP).
    target_system, target_component : int
        The vehicle.  Frames from other systems are ignored and counted.
    signing_key : bytes or None
        32-byte MAVLink 2 signing key; outgoing frames are signed and unsigned
        incoming frames rejected (except RADIO_STATUS, which SiK radios inject).
    on_frame : callable or None
        Called with ``(direction, msg, accepted)`` for every frame received ("in") and
        sent ("out"), e.g. for logging; ``accepted`` is False for frames that were
        dropped (garbled bytes as pymavlink's BAD_DATA, other systems).
    """

    def __init__(self, url: str, *, baud: int = 57600, target_system: int = 1, target_component: int = 1,
                 source_system: int = 255, source_component: int = 190, signing_key: bytes | None = None,
                 on_frame: Callable[[str, object], None] | None = None, guard: OutputGuard | None = None) -> None:
        self.url = url
        self.target_system = target_system
        self.target_component = target_component
        self.source_system = source_system
        self.source_component = source_component
        self.counters = LinkCounters()
        self.on_frame = on_frame
        #: Checks every outgoing message (:class:`~gcs.link.guard.OutputGuard`); None = none.
        self.guard = guard
        try:
            self.conn = mavutil.mavlink_connection(url, baud=baud, source_system=source_system,
                                                   source_component=source_component, autoreconnect=False,
                                                   robust_parsing=True, dialect="ardupilotmega")
        except (OSError, ValueError, OverflowError) as exc:
            raise LinkError(f"cannot open {url!r}: {exc}") from None
        self._pending: list = []
        #: Called while waiting for the heartbeat; raises if the peer cannot answer (a dead child).
        self.alive_check: Callable[[], None] | None = None
        self.mav = self.conn.mav
        self.signature_check: SignatureCheck | None = None
        if signing_key is not None:
            if len(signing_key) != 32:
                raise LinkError(f"signing key must be 32 bytes, got {len(signing_key)}")
            # The signature is checked before any time stamp is stored (pymavlink's own check stores
            # first: one forged frame would lock the link out); time stamps start at the wall clock.
            self.signature_check = setup_signing(self.mav, signing_key, allow_unsigned_callback=self._allow_unsigned)
        self.last_heartbeat = None
        self.vehicle_addr = None
        #: Integer parameters travel bytewise in PARAM_VALUE/PARAM_SET (PX4; the autopilot's
        #: MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE), else as C-cast floats (ArduPilot).
        self.param_bytewise = False
        #: name -> MAV_PARAM_TYPE, as the vehicle last reported it.
        self.param_types: dict[str, int] = {}
        self._udp = isinstance(self.conn, mavutil.mavudp)
        if self._udp:
            # A stalled ground station (a paused process, a swapping laptop) must find what the vehicle
            # said meanwhile, its mode changes above all: Linux's default 208 KiB holds < 1 s of telemetry.
            with contextlib.suppress(OSError):
                self.conn.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, UDP_RECEIVE_BUFFER_B)
        #: Other ground stations (:class:`gcs.link.forward.Forwarder`, ``gcs fly --out``); None = none.
        self.forwarder = None

    # ------------------------------------------------------------------ receive
    def _allow_unsigned(self, mav, msg_id: int) -> bool:
        """pymavlink asks this for unsigned frames and for signed frames that failed their check."""
        return msg_id == mavlink.MAVLINK_MSG_ID_RADIO_STATUS

    def _accept(self, msg, addr=None) -> bool:
        c = self.counters
        t = msg.get_type()
        restore_unknown_header(msg)
        if t == "BAD_DATA":
            if getattr(msg, "reason", "") == "Invalid signature":
                data = bytes(getattr(msg, "data", b"") or b"")
                if len(data) > 2 and data[0] == mavlink.PROTOCOL_MARKER_V2 and data[2] & mavlink.MAVLINK_IFLAG_SIGNED:
                    c.bad_signature += 1
                else:
                    c.unsigned_rejected += 1
            else:
                c.bad_data += 1
            if self.on_frame is not None:
                self.on_frame("in", msg, False)
            return False
        if msg.get_srcSystem() != self.target_system:
            c.other_system += 1
            if self.on_frame is not None:
                self.on_frame("in", msg, False)
            return False
        if self._udp and self.vehicle_addr is None and addr is not None:
            # The vehicle's address: from now on the only destination and the only source.
            self.vehicle_addr = addr
            if self.conn.udp_server:
                self.conn.clients.clear()
                self.conn.clients.add(addr)
                self.conn.clients_last_alive[addr] = time.time()
        if self.forwarder is not None:
            self.forwarder.from_vehicle(msg)
        c.received += 1
        c.by_type[t] = c.by_type.get(t, 0) + 1
        if t == "HEARTBEAT" and msg.get_srcComponent() == self.target_component:
            self.last_heartbeat = msg
        if self.on_frame is not None:
            self.on_frame("in", msg, True)
        return True


    def _drain_udp(self, out: list) -> list:
        port = self.conn.port
        while True:
            try:
                data, addr = port.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return out
            except OSError as exc:
                if exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK, errno.ECONNREFUSED):
                    return out
                raise LinkError(f"link {self.url!r} failed: {exc}") from None
            if self.vehicle_addr is not None and addr != self.vehicle_addr:
                self.counters.other_address += 1
                continue
            if self.conn.udp_server and self.vehicle_addr is None:
                # pymavlink's udpin answers every address that ever sent: until the vehicle is known.
                self.conn.clients.add(addr)
                self.conn.clients_last_alive[addr] = time.time()
            msgs, failed, truncated = parse_bytes(self.mav, data, datagram=True)
            self.counters.malformed += failed
            self.counters.truncated += truncated
            for msg in msgs:
                if self._accept(msg, addr):
                    out.append(msg)

    def drain(self) -> list:
        """Every message waiting now from the target system (never blocks)."""
        out, self._pending = self._pending, []
        if self.forwarder is not None:
            self.forwarder.poll(self.conn.write)  # the other ground stations' frames to the vehicle
        if self._udp:
            return self._drain_udp(out)
        recv = self.conn.recv_msg
        while True:
            try:
                msg = recv()
            except (OSError, serial_errors()) as exc:
                raise LinkError(f"link {self.url!r} failed: {exc}") from None
            except Exception:  # noqa: BLE001 - a parser failure on hostile bytes: counted, skipped
                self.counters.malformed += 1
                reset_parser(self.mav)
                continue
            if msg is None:
                return out
            if self._accept(msg):
                out.append(msg)

    def wait_readable(self, timeout_s: float) -> None:
        """Block until something arrives or ``timeout_s`` passes."""
        self.conn.select(timeout_s)

    def wait_heartbeat(self, timeout_s: float = 10.0, on_message=None):
        """The first HEARTBEAT of the target, sending ours meanwhile (so UDP-out peers learn our address)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.alive_check is not None:
                self.alive_check()
            self.send_heartbeat()
            hb = self.wait(lambda m: m.get_type() == "HEARTBEAT" and m.get_srcComponent() == self.target_component,
                           min(1.0, max(0.0, deadline - time.monotonic())), on_message)
            if hb is not None:
                return hb
        raise LinkError(f"no HEARTBEAT from system {self.target_system} component {self.target_component} "
                        f"on {self.url} within {timeout_s:g} s{self.signing_diagnosis()}")

    def signing_diagnosis(self) -> str:
        """Why signed traffic may have been refused (empty when it was not)."""
        c = self.counters
        chk = self.signature_check
        if chk is not None and chk.bad_signature:
            return (f"; {chk.bad_signature} signed frames failed the signature check: is --signing-key the "
                    "vehicle's key?")
        if chk is not None and (chk.replayed or chk.stale_timestamp):
            return (f"; {chk.replayed + chk.stale_timestamp} signed frames refused for old time stamps (replayed, "
                    "or the vehicle's clock is far behind)")
        if c.unsigned_rejected:
            return (f"; {c.unsigned_rejected} unsigned frames refused: the vehicle does not sign (is signing "
                    "set up on it with this key?)")
        return ""

    # ------------------------------------------------------------------ send
    def send(self, msg) -> None:
        """Send a pymavlink message object, unless the output guard blocks it.

        Raises
        ------
        UnsafeCommand
            The guard found a non-finite or out-of-limit field; nothing was sent.
        LinkError
            The port failed.
        """
        if self.guard is not None:
            reason = self.guard.check(msg)
            if reason is not None:
                self.counters.blocked += 1
                raise UnsafeCommand(reason)
        try:
            self.mav.send(msg)
        except (OSError, ValueError) as exc:
            raise LinkError(f"link {self.url!r} failed: {exc}") from None
        self.counters.sent += 1
        if self.on_frame is not None:
            self.on_frame("out", msg, True)

    def send_heartbeat(self) -> None:
        self.send(self.mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0))

    def send_timesync(self) -> int:
        """TIMESYNC request stamped with our monotonic clock [ns] (returned); the reply echoes it."""
        ts1 = time.monotonic_ns()
        self.send(self.mav.timesync_encode(0, ts1))
        return ts1

    def command_long(self, command: int, params: Iterable[float], timeout_s: float = 3.0, retries: int = 2,
                     on_message=None) -> int:
        """Send COMMAND_LONG and return the MAV_RESULT of its COMMAND_ACK (retries on silence)."""
        p = list(params) + [0.0] * (7 - len(list(params)))
        for attempt in range(retries + 1):
            self.send(self.mav.command_long_encode(self.target_system, self.target_component, command, attempt, *p[:7]))
            ack = self.wait(lambda m: self.is_our_ack(m, command), timeout_s, on_message)
            while ack is not None and ack.result == mavlink.MAV_RESULT_IN_PROGRESS:
                ack = self.wait(lambda m: self.is_our_ack(m, command) and m.result != mavlink.MAV_RESULT_IN_PROGRESS,
                                timeout_s, on_message)
            if ack is not None:
                return int(ack.result)
        raise LinkError(f"no COMMAND_ACK for command {command} after {retries + 1} tries")

    def is_our_ack(self, msg, command: int) -> bool:
        """A COMMAND_ACK of ``command`` from the autopilot, addressed to us (or to nobody in particular:
        autopilots before MAVLink 2's target fields send 0) — never another ground station's."""
        if msg.get_type() != "COMMAND_ACK" or msg.command != command:
            return False
        if msg.get_srcComponent() != self.target_component:
            return False
        ts = getattr(msg, "target_system", 0)
        tc = getattr(msg, "target_component", 0)
        if (ts, tc) != (self.source_system, self.source_component) and self.forwarder is not None \
                and self.forwarder.client_sent_recently(command):
            return False  # not addressed to us exactly, and a ground station behind --out sent that command
        return ts in (0, self.source_system) and tc in (0, self.source_component)

    def send_message_interval(self, message_id: int, rate_hz: float) -> None:
        """MAV_CMD_SET_MESSAGE_INTERVAL without waiting for its acknowledgement (the mission loop's re-request)."""
        self.send(self.mav.command_long_encode(self.target_system, self.target_component,
                                               mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0, message_id,
                                               _interval_us(rate_hz), 0, 0, 0, 0, 0))

    def set_message_interval(self, message_id: int, rate_hz: float, on_message=None) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL (511): stream ``message_id`` at ``rate_hz``."""
        return self.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, [message_id, _interval_us(rate_hz)],
                                 on_message=on_message)

    def arm(self, arm: bool = True, force: bool = False, on_message=None) -> int:
        """MAV_CMD_COMPONENT_ARM_DISARM (400); ``force`` uses the magic 21196."""
        return self.command_long(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, [1.0 if arm else 0.0, 21196.0 if force else 0.0],
                                 on_message=on_message)

    def param_get(self, name: str, timeout_s: float = 3.0, retries: int = 2, on_message=None) -> float:
        """PARAM_REQUEST_READ -> PARAM_VALUE (decoded per its type: :meth:`param_value`)."""
        for _ in range(retries + 1):
            self.send(self.mav.param_request_read_encode(self.target_system, self.target_component, name.encode(), -1))
            pv = self.wait(lambda m: m.get_type() == "PARAM_VALUE" and _param_id(m) == name, timeout_s, on_message)
            if pv is not None:
                return self.param_value(pv)
        raise LinkError(f"no PARAM_VALUE for {name} after {retries + 1} tries")

    def param_value(self, pv) -> float:
        """The value a PARAM_VALUE carries (its type remembered for :meth:`param_set`)."""
        ptype = int(pv.param_type)
        self.param_types[_param_id(pv)] = ptype
        return decode_param(float(pv.param_value), ptype, self.param_bytewise)

    def param_set(self, name: str, value: float, timeout_s: float = 3.0, retries: int = 2, on_message=None) -> float:
        """PARAM_SET, confirmed by a PARAM_VALUE that carries the value set; returns the value the vehicle holds.

        The value goes with the parameter's own type as the vehicle reported it (integers
        bytewise where the autopilot encodes them so: an autopilot such as PX4 ignores a REAL32
        PARAM_SET of an INT32 parameter); a parameter never read goes as REAL32.  A PARAM_VALUE
        with another value may be a stale or duplicated one sent before our PARAM_SET: it is
        not taken as the answer.  When only such values come back, the parameter is read once
        more and what the vehicle reports is returned (the caller decides whether that is a refusal).
        """
        # C-cast autopilots (ArduPilot) take every value as REAL32 and convert to their own type.
        ptype = self.param_types.get(name, mavlink.MAV_PARAM_TYPE_REAL32) if self.param_bytewise \
            else mavlink.MAV_PARAM_TYPE_REAL32
        try:
            wire = encode_param(value, ptype, self.param_bytewise)
        except ParamEncodingError as exc:
            raise LinkError(f"{name}: {exc}") from None
        want = decode_param(wire, ptype, self.param_bytewise)
        for _ in range(retries + 1):
            self.send(self.mav.param_set_encode(self.target_system, self.target_component, name.encode(), wire, ptype))
            pv = self.wait(lambda m: m.get_type() == "PARAM_VALUE" and _param_id(m) == name
                           and same_float32(self.param_value(m), want), timeout_s, on_message)
            if pv is not None:
                return self.param_value(pv)
        try:
            seen = self.param_get(name, timeout_s=timeout_s, retries=0, on_message=on_message)
        except LinkError:
            seen = None
        if seen is None:
            raise LinkError(f"no PARAM_VALUE echo for {name} after {retries + 1} tries")
        return seen

    def close(self) -> None:
        try:
            self.conn.close()
        except OSError:
            pass


def _interval_us(rate_hz: float) -> int:
    """SET_MESSAGE_INTERVAL's interval [us] for a rate [Hz] (<= 0: stop the stream)."""
    return -1 if not rate_hz > 0 else max(1, int(round(1e6 / rate_hz)))
