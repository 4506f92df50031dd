"""The vehicle's serial port on a pseudo-terminal (raw mode), opened by the ground station like ``/dev/ttyUSB0``.

The line is one peer, ``"serial"``.  Until the ground station has sent something, or after it has
been silent for 5 s, unread output is discarded before each write, so a late opener does not read
seconds of stale telemetry.  The baud rate the ground station sets means nothing to a
pseudo-terminal; :mod:`sitl.net.radio` emulates it.
"""

from __future__ import annotations

import logging
import os
import termios
import tty
from collections.abc import Callable, Hashable

from sitl.errors import TransportError
from sitl.net.transport import PendingOutput, Transport

__all__ = ["PtyTransport"]

log = logging.getLogger(__name__)

_PTY_STALE_NS = 5_000_000_000


class PtyTransport(Transport):
    """Serial port of the vehicle on a pseudo-terminal (raw mode).

    Parameters
    ----------
    clock_ns : callable
        Monotonic time source [ns] (for the stale-output rule).
    """

    def __init__(self, clock_ns: Callable[[], int]) -> None:
        super().__init__()
        try:
            self._master, self._slave = os.openpty()
        except OSError as exc:
            raise TransportError(f"cannot open a pseudo-terminal: {exc.strerror or exc}") from None
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.device = os.ttyname(self._slave)
        self._out = PendingOutput(self._master, lambda b: os.write(self._master, b))
        self._clock_ns = clock_ns
        self._last_rx_ns: int | None = None
        self._closed = False

    def filenos(self) -> list[int]:
        return [self._master]

    def write_filenos(self) -> list[int]:
        return [self._master] if self._out.pending else []

    def receive(self) -> list[tuple[Hashable, bytes, bool]]:
        out: list[tuple[Hashable, bytes, bool]] = []
        while True:
            try:
                data = os.read(self._master, 65536)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:  # EIO when no one holds the slave (never here: we keep it open)
                log.debug("pty read: %s", exc)
                break
            if not data:
                break
            out.append(("serial", data, False))
        if out:
            if self._last_rx_ns is None:
                self._new_peers.append("serial")
            self._last_rx_ns = self._clock_ns()
        return out

    def peers(self) -> list[Hashable]:
        return ["serial"]

    def send_to(self, peer: Hashable, frames: list[bytes]) -> int:
        if not frames:
            return 0
        if peer != "serial":
            return len(frames)
        now = self._clock_ns()
        if self._last_rx_ns is None or now - self._last_rx_ns > _PTY_STALE_NS:
            try:
                termios.tcflush(self._slave, termios.TCIFLUSH)
            except termios.error as exc:
                log.debug("pty flush: %s", exc)
            self._out.pending.clear()
        dropped = 0 if self._out.push(b"".join(frames)) else len(frames)
        self._out.flush()
        return dropped

    def flush(self) -> None:
        if self._out.pending:
            self._out.flush()

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            os.close(self._master)
            os.close(self._slave)

    @property
    def connection_string(self) -> str:
        return self.device
