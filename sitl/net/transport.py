"""The byte transports' interface: non-blocking, polled with ``select``, one peer per remote end.

A transport only moves bytes; framing is :mod:`sitl.net.endpoint`'s (or the rig protocol's) and
link emulation :mod:`sitl.net.radio`'s.  A peer is the hashable :meth:`Transport.receive` reports
with the data and :meth:`Transport.send_to` takes; the server keeps one link (parser, stream rates,
sequence numbers, radio) per peer and greets the peers :meth:`Transport.take_new_peers` reports.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Hashable

__all__ = ["Transport", "PendingOutput", "parse_host_port"]

_MAX_PENDING = 256 * 1024


def parse_host_port(text: str, default_host: str = "127.0.0.1") -> tuple[str, int]:
    """``"HOST:PORT"`` or ``"PORT"`` to ``(host, port)``; ValueError if malformed."""
    host, sep, port = text.rpartition(":")
    if not sep:
        host, port = default_host, text
    try:
        p = int(port)
    except ValueError:
        raise ValueError(f"bad port in {text!r}") from None
    if not 0 <= p <= 65535:
        raise ValueError(f"port out of range in {text!r}")
    return (host or default_host), p


class Transport(ABC):
    """Interface of the byte transports."""

    def __init__(self) -> None:
        self._new_peers: list[Hashable] = []
        self._gone_peers: list[Hashable] = []

    @abstractmethod
    def filenos(self) -> list[int]:
        """File descriptors to wait on for input."""

    def write_filenos(self) -> list[int]:
        """File descriptors with output waiting for the kernel."""
        return []

    @abstractmethod
    def receive(self) -> list[tuple[Hashable, bytes, bool]]:
        """Everything readable now: ``(peer, data, is_datagram)``; never blocks."""

    @abstractmethod
    def peers(self) -> list[Hashable]:
        """The peers output can be sent to now."""

    @abstractmethod
    def send_to(self, peer: Hashable, frames: list[bytes]) -> int:
        """Send frames to one peer; returns the number of frames dropped (all of them for an unknown peer)."""

    def send(self, frames: list[bytes]) -> int:
        """Send the same frames to every peer; returns the number of frames dropped."""
        return sum(self.send_to(peer, frames) for peer in self.peers())

    def flush(self) -> None:  # noqa: B027 - a transport without an output buffer has nothing to retry
        """Retry output that did not fit into the kernel buffers."""

    @abstractmethod
    def close(self) -> None:
        """Release the resources (idempotent)."""

    @property
    @abstractmethod
    def connection_string(self) -> str:
        """What a ground station passes to ``mavutil.mavlink_connection``."""

    def take_new_peers(self) -> list[Hashable]:
        """Peers that appeared since the last call."""
        out, self._new_peers = self._new_peers, []
        return out

    def take_gone_peers(self) -> list[Hashable]:
        """Peers that went away since the last call."""
        out, self._gone_peers = self._gone_peers, []
        return out


class PendingOutput:
    """Output of one stream socket or descriptor that the kernel did not take yet (at most 256 KiB)."""

    __slots__ = ("fd", "pending", "write")

    def __init__(self, fd: int, write: Callable[[bytes], int]) -> None:
        self.fd = fd
        self.pending = bytearray()
        self.write = write

    def push(self, data: bytes) -> bool:
        """Queue ``data``; False (nothing queued) if it would overflow."""
        if len(self.pending) + len(data) > _MAX_PENDING:
            return False
        self.pending += data
        return True

    def flush(self) -> bool:
        """Write what the kernel takes; False if the peer is gone."""
        while self.pending:
            try:
                n = self.write(bytes(self.pending[:65536]))
            except (BlockingIOError, InterruptedError):
                return True
            except OSError:
                return False
            if n <= 0:
                return True
            del self.pending[:n]
        return True
