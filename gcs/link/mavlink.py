"""MAVLink link to one vehicle, on pymavlink: serial (telemetry radio), UDP or TCP.

:class:`MavlinkLink` wraps a ``pymavlink.mavutil`` connection and keeps to
ArduPilot Copter's conventions (``../shared/DESIGN.md``):

* only frames from ``target_system`` count; others are dropped and counted;
* garbled bytes (``BAD_DATA``) are counted and skipped, never raised;
* :meth:`drain` returns every pending message without blocking (the
  ``recv_match(blocking=False, timeout=0.0)`` trap of pymavlink is avoided by
  calling ``recv_msg`` until it returns None);
* commands wait for their COMMAND_ACK; parameters use PARAM_REQUEST_READ / PARAM_SET;
* optional MAVLink 2 signing.

The link knows nothing of the paper's frame; :mod:`gcs.flight.telemetry` converts.
"""

from __future__ import annotations

import errno
import os
import socket
import time
from dataclasses import dataclass, field
from typing import Callable, Iterable

# MAVLink 2 on the wire (signing, extensions): pymavlink picks its protocol module from this
# variable, so it is set before the dialect is loaded.
os.environ["MAVLINK20"] = "1"

from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

mavutil.set_dialect("ardupilotmega")

from gcs.errors import GcsError
from gcs.link.base import MessageWaiter

__all__ = ["LinkError", "MavlinkLink", "LinkCounters", "connection_url", "COPTER_MODES"]

#: ArduCopter custom modes used here.
COPTER_MODES = {"STABILIZE": 0, "GUIDED": 4, "LAND": 9, "GUIDED_NOGPS": 20}


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
    by_type: dict[str, int] = field(default_factory=dict)


def connection_url(port: str | None, connect: str | None) -> str:
    """The pymavlink URL from ``--port DEVICE`` or ``--connect URL`` (exactly one given)."""
    if (port is None) == (connect is None):
        raise ValueError("give exactly one of port and connect")
    if port is not None:
        return port
    return connect  # type: ignore[return-value]


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
                 on_frame: Callable[[str, object], None] | None = None) -> None:
        self.url = url
        self.target_system = target_system
        self.target_component = target_component
        self.counters = LinkCounters()
        self.on_frame = on_frame
        try:
            self.conn = mavutil.mavlink_connection(url, baud=baud, source_system=source_system,
                                                   source_component=source_component, autoreconnect=False,
                                                   robust_parsing=True, dialect="ardupilotmega")
        except (OSError, ValueError, OverflowError) as exc:
            raise LinkError(f"cannot open {url!r}: {exc}") from None
        self._pending: list = []
        #: Called while waiting for the heartbeat; raises if the peer cannot answer (a dead child).
        self.alive_check: Callable[[], None] | None = None
        if signing_key is not None:
            if len(signing_key) != 32:
                raise LinkError(f"signing key must be 32 bytes, got {len(signing_key)}")
            self.conn.setup_signing(signing_key, sign_outgoing=True, allow_unsigned_callback=self._allow_unsigned)
        self.mav = self.conn.mav
        self.last_heartbeat = None
        self._last_addr = None
        self.vehicle_addr = None
        if isinstance(self.conn, mavutil.mavudp) and self.conn.udp_server:
            self.conn.recv = self._udp_recv

    def _udp_recv(self, n=None) -> bytes:
        """pymavlink's udpin receive, but replies go to the vehicle only once it is known.

        pymavlink sends to every address that ever sent a datagram; any stray sender on the
        port would then get our commands.  Once the target's first frame arrives its address
        is the only destination.
        """
        conn = self.conn
        try:
            data, addr = conn.port.recvfrom(65535)
        except socket.error as exc:
            if exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK, errno.ECONNREFUSED):
                return b""
            raise
        self._last_addr = addr
        if self.vehicle_addr is None or addr == self.vehicle_addr:
            conn.clients.add(addr)
            conn.clients_last_alive[addr] = time.time()
        return data

    # ------------------------------------------------------------------ receive
    def _allow_unsigned(self, mav, msg_id: int) -> bool:
        if msg_id == mavlink.MAVLINK_MSG_ID_RADIO_STATUS:
            return True
        self.counters.unsigned_rejected += 1
        return False

    def _accept(self, msg) -> bool:
        c = self.counters
        t = msg.get_type()
        if t == "BAD_DATA":
            c.bad_data += 1
            if self.on_frame is not None:
                self.on_frame("in", msg, False)
            return False
        if msg.get_srcSystem() != self.target_system:
            c.other_system += 1
            if self.on_frame is not None:
                self.on_frame("in", msg, False)
            return False
        if self.vehicle_addr is None and self._last_addr is not None:
            self.vehicle_addr = self._last_addr
            self.conn.clients.intersection_update({self.vehicle_addr})
        c.received += 1
        c.by_type[t] = c.by_type.get(t, 0) + 1
        if t == "HEARTBEAT" and msg.get_srcComponent() == self.target_component:
            self.last_heartbeat = msg
        if self.on_frame is not None:
            self.on_frame("in", msg, True)
        return True

    def drain(self) -> list:
        """Every message waiting now from the target system (never blocks)."""
        out, self._pending = self._pending, []
        recv = self.conn.recv_msg
        while True:
            try:
                msg = recv()
            except (OSError, ValueError) as exc:
                raise LinkError(f"link {self.url!r} failed: {exc}") from None
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
                        f"on {self.url} within {timeout_s:g} s")

    # ------------------------------------------------------------------ send
    def send(self, msg) -> None:
        """Send a pymavlink message object."""
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
            ack = self.wait(lambda m: m.get_type() == "COMMAND_ACK" and m.command == command, timeout_s, on_message)
            if ack is not None:
                return int(ack.result)
        raise LinkError(f"no COMMAND_ACK for command {command} after {retries + 1} tries")

    def set_message_interval(self, message_id: int, rate_hz: float, on_message=None) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL (511): stream ``message_id`` at ``rate_hz``."""
        interval_us = -1 if rate_hz <= 0 else int(round(1e6 / rate_hz))
        return self.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, [message_id, interval_us], on_message=on_message)

    def set_mode(self, mode: str, on_message=None) -> int:
        """MAV_CMD_DO_SET_MODE with an ArduCopter custom mode name."""
        if mode not in COPTER_MODES:
            raise ValueError(f"unknown mode {mode!r}")
        return self.command_long(mavlink.MAV_CMD_DO_SET_MODE,
                                 [mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, COPTER_MODES[mode]], on_message=on_message)

    def arm(self, arm: bool = True, force: bool = False, on_message=None) -> int:
        """MAV_CMD_COMPONENT_ARM_DISARM (400); ``force`` uses the magic 21196."""
        return self.command_long(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, [1.0 if arm else 0.0, 21196.0 if force else 0.0],
                                 on_message=on_message)

    def param_get(self, name: str, timeout_s: float = 3.0, retries: int = 2, on_message=None) -> float:
        """PARAM_REQUEST_READ -> PARAM_VALUE."""
        for _ in range(retries + 1):
            self.send(self.mav.param_request_read_encode(self.target_system, self.target_component, name.encode(), -1))
            pv = self.wait(lambda m: m.get_type() == "PARAM_VALUE" and _param_id(m) == name, timeout_s, on_message)
            if pv is not None:
                return float(pv.param_value)
        raise LinkError(f"no PARAM_VALUE for {name} after {retries + 1} tries")

    def param_set(self, name: str, value: float, timeout_s: float = 3.0, retries: int = 2, on_message=None) -> float:
        """PARAM_SET, confirmed by the PARAM_VALUE echo; returns the value the vehicle holds."""
        for _ in range(retries + 1):
            self.send(self.mav.param_set_encode(self.target_system, self.target_component, name.encode(), float(value),
                                                mavlink.MAV_PARAM_TYPE_REAL32))
            pv = self.wait(lambda m: m.get_type() == "PARAM_VALUE" and _param_id(m) == name, timeout_s, on_message)
            if pv is not None:
                return float(pv.param_value)
        raise LinkError(f"no PARAM_VALUE echo for {name} after {retries + 1} tries")

    def close(self) -> None:
        try:
            self.conn.close()
        except OSError:
            pass


def _param_id(msg) -> str:
    pid = msg.param_id
    if isinstance(pid, bytes):
        pid = pid.decode(errors="replace")
    return pid.rstrip("\x00")


def read_signing_key(path: str) -> bytes:
    """A 32-byte key from a file: raw 32 bytes, or 64 hex characters, or a passphrase (SHA-256 of it)."""
    import hashlib

    try:
        data = open(path, "rb").read()
    except OSError as exc:
        raise LinkError(f"cannot read signing key {path!r}: {exc.strerror or exc}") from None
    if len(data) == 32:
        return data
    text = data.strip()
    try:
        if len(text) == 64:
            return bytes.fromhex(text.decode())
    except ValueError:
        pass
    if not text:
        raise LinkError(f"signing key file {path!r} is empty")
    return hashlib.sha256(text).digest()
