"""Serial link to the 4-DOF rig: XBee API-2 frames of :mod:`quadrotor.rig_protocol` over pyserial.

:class:`RigLink` opens the port (a device such as ``/dev/ttyUSB0``, or any pyserial URL),
feeds every byte read to an incremental :class:`~quadrotor.rig_protocol.RigDecoder` (garbled
bytes, bad checksums and lengths are counted and skipped, never raised) and encodes
outgoing messages.  ``on_bytes(direction, data)`` sees the bytes as on the wire both ways
(the flight log keeps them: replaying the received stream through a decoder gives back
every message).  The wire format is shared with the emulator (``sitl --rig 4dof``), which is
why it lives in :mod:`quadrotor.rig_protocol`.
"""

from __future__ import annotations

import select
import time
from collections.abc import Callable

import serial

from gcs.link.base import MessageWaiter
from gcs.link.guard import OutputGuard, UnsafeCommand
from gcs.link.mavlink import LinkError
from quadrotor import rig_protocol as rp

__all__ = ["RigLink", "rig_link_budget"]

#: Mean escaped sizes [bytes] measured on an emulated hover (docs/rig-protocol.md).
_TELEMETRY_B, _STATUS_B, _CONTROL_B, _HEARTBEAT_B = 43.4, 52.0, 24.2, 9.0


def rig_link_budget(baud: int, control_rate_hz: float = 100.0, telemetry_rate_hz: float = 200.0) -> dict:
    """Bytes per second each way of the rig exchange and their share of a ``baud`` 8N1 line.

    Returns
    -------
    dict
        ``down_b_s``, ``up_b_s``, ``capacity_b_s``, ``down_share``, ``up_share``.
    """
    if baud <= 0:
        raise ValueError(f"baud must be > 0, got {baud}")
    cap = baud / 10.0
    down = telemetry_rate_hz * _TELEMETRY_B + _STATUS_B
    up = control_rate_hz * _CONTROL_B + _HEARTBEAT_B
    return {"down_b_s": down, "up_b_s": up, "capacity_b_s": cap, "down_share": down / cap, "up_share": up / cap}


class RigLink(MessageWaiter):
    """The PC side of the rig's serial line.

    Parameters
    ----------
    port : str
        Serial device or pyserial URL.
    baud : int
        Baud rate (115200 for the paper's XBee link).
    on_bytes : callable (direction, bytes) or None
        Called with ``("in", data)`` for every chunk read and ``("out", frame)`` for every frame sent.

    Raises
    ------
    LinkError
        When the port cannot be opened.
    """

    def __init__(self, port: str, baud: int = 115200, on_bytes: Callable[[str, bytes], None] | None = None) -> None:
        self.url = port
        self.baud = baud
        self.on_bytes = on_bytes
        try:
            self.serial = serial.serial_for_url(port, baudrate=baud, timeout=0, write_timeout=1.0)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise LinkError(f"cannot open {port!r}: {exc}") from None
        self.decoder = rp.RigDecoder(rp.TO_PC)
        self.sent = 0
        self.received_bytes = 0
        self.sent_bytes = 0
        self._seq8 = 0
        self._pending: list[rp.Message] = []
        #: Checks every outgoing message (:class:`~gcs.link.guard.OutputGuard`); None = none.
        self.guard: OutputGuard | None = None

    @property
    def counters(self) -> rp.DecoderCounters:
        return self.decoder.counters

    def drain(self) -> list[rp.Message]:
        """Every message decoded from the bytes waiting now (never blocks)."""
        if self._pending:
            out, self._pending = self._pending, []
            return out + self.drain()
        try:
            n = self.serial.in_waiting
            data = self.serial.read(n) if n else b""
        except (serial.SerialException, OSError) as exc:
            raise LinkError(f"link {self.url!r} failed: {exc}") from None
        if not data:
            return []
        self.received_bytes += len(data)
        if self.on_bytes is not None:
            self.on_bytes("in", data)
        return self.decoder.feed(data)

    def wait_readable(self, timeout_s: float) -> None:
        """Block until bytes arrive or ``timeout_s`` passes."""
        try:
            select.select([self.serial.fileno()], [], [], max(0.0, timeout_s))
        except (OSError, ValueError, AttributeError):  # a URL transport without a file descriptor
            time.sleep(max(0.0, min(timeout_s, 0.001)))

    def send(self, msg: rp.Message) -> None:
        """Encode and write one message, unless the output guard blocks it.

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
                raise UnsafeCommand(reason)
        frame = rp.encode(msg)
        try:
            self.serial.write(frame)
        except (serial.SerialException, OSError) as exc:
            raise LinkError(f"link {self.url!r} failed: {exc}") from None
        self.sent += 1
        self.sent_bytes += len(frame)
        if self.on_bytes is not None:
            self.on_bytes("out", frame)

    def next_seq8(self) -> int:
        """Sequence number (1..255) for ARM / DISARM."""
        self._seq8 = self._seq8 % 255 + 1
        return self._seq8

    def close(self) -> None:
        try:
            self.serial.close()
        except (serial.SerialException, OSError):
            pass
