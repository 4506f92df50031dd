"""Byte transports of the vehicle: UDP, TCP server, serial port on a pseudo-terminal.

All are non-blocking and polled by :class:`sitl.server.SitlServer` with
``select``.  A transport only moves bytes: framing is :mod:`sitl.endpoint`'s,
link emulation (baud, loss, latency) :mod:`sitl.radio`'s.

* :class:`UdpTransport`: the vehicle side of a ground station's ``udpin:`` (give
  ``remote``: the vehicle sends there, like ArduPilot's ``--out``) or
  ``udpout:`` (no remote: the vehicle answers whoever sent to its bound port;
  the ground station must send first).  Every datagram is parsed on its own.
  Each sender address is a peer (at most 8; the one heard from least
  recently, never ``remote``, makes room).
* :class:`TcpTransport`: a TCP server (``tcp:HOST:PORT`` for the ground
  station); several clients may connect, each connection is a peer.
* :class:`PtyTransport`: a pseudo-terminal in raw mode; the ground station
  opens :attr:`PtyTransport.device` (like ``/dev/ttyUSB0``) at any baud.
  Until the ground station has sent something (or after it has been silent
  for 5 s) unread output is discarded before each write, so a late opener
  does not read seconds of stale telemetry.  The line is one peer, ``"serial"``.

A peer is what :meth:`Transport.receive` reports with the data and what
:meth:`Transport.send_to` takes: the server keeps one link (parser, stream
rates, sequence numbers) per peer.
"""

from __future__ import annotations

import errno
import logging
import os
import socket
import termios
import tty
from abc import ABC, abstractmethod
from typing import Callable, Hashable

from sitl.errors import TransportError

__all__ = ["Transport", "UdpTransport", "TcpTransport", "PtyTransport", "parse_host_port"]

log = logging.getLogger(__name__)

_UDP_PAYLOAD = 1400
_MAX_PENDING = 256 * 1024
_MAX_UDP_PEERS = 8
_PTY_STALE_NS = 5_000_000_000


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

    #: Peers that appeared since the last :meth:`take_new_peers` (the server greets them).
    _new_peers: list[Hashable]
    _gone_peers: list[Hashable]

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

    def flush(self) -> None:
        """Retry output that did not fit into the kernel buffers."""

    @abstractmethod
    def close(self) -> None:
        """Release the resources (idempotent)."""

    @property
    @abstractmethod
    def connection_string(self) -> str:
        """What a ground station passes to ``mavutil.mavlink_connection``."""

    def take_new_peers(self) -> list[Hashable]:
        out, self._new_peers = self._new_peers, []
        return out

    def take_gone_peers(self) -> list[Hashable]:
        out, self._gone_peers = self._gone_peers, []
        return out


class UdpTransport(Transport):
    """UDP socket of the vehicle.

    Parameters
    ----------
    bind : (host, port)
        Local address; port 0 = ephemeral (see :attr:`address`).
    remote : (host, port) or None
        Ground station listening with ``udpin:`` (always sent to); None: answer
        the senders (ground station using ``udpout:``).
    """

    def __init__(self, bind: tuple[str, int] = ("127.0.0.1", 0), remote: tuple[str, int] | None = None) -> None:
        self._new_peers, self._gone_peers = [], []
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind(bind)
        except OSError as exc:
            self._sock.close()
            raise TransportError(f"cannot bind udp {bind[0]}:{bind[1]}: {exc.strerror or exc}") from None
        self._sock.setblocking(False)
        self.remote = remote
        self._peers: dict[tuple[str, int], bool] = {}
        if remote is not None:
            try:
                remote = (socket.gethostbyname(remote[0]), remote[1])
            except OSError as exc:
                self._sock.close()
                raise TransportError(f"cannot resolve udp host {remote[0]!r}: {exc}") from None
            self.remote = remote
            self._peers[remote] = True
        self.address: tuple[str, int] = self._sock.getsockname()

    def filenos(self) -> list[int]:
        return [self._sock.fileno()]

    def receive(self) -> list[tuple[Hashable, bytes, bool]]:
        out: list[tuple[Hashable, bytes, bool]] = []
        for _ in range(10000):
            try:
                data, addr = self._sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                break
            except ConnectionRefusedError:  # ICMP port unreachable from an earlier send
                continue
            except OSError as exc:
                if exc.errno in (errno.EBADF, errno.ENOTSOCK):
                    break
                log.debug("udp recv: %s", exc)
                continue
            fixed = self._peers.pop(addr, None)
            if fixed is None:  # a new sender: the one heard from least recently (not remote) makes room
                fixed = False
                if len(self._peers) >= _MAX_UDP_PEERS:
                    old = next((a for a, f in self._peers.items() if not f), None)
                    if old is not None:
                        del self._peers[old]
                        self._gone_peers.append(old)
                self._new_peers.append(addr)
            self._peers[addr] = fixed  # (re)inserted last: the dict is in order of the last datagram
            out.append((addr, data, True))
        return out

    def peers(self) -> list[Hashable]:
        return list(self._peers)

    def send_to(self, peer: Hashable, frames: list[bytes]) -> int:
        if not frames:
            return 0
        if peer not in self._peers:
            return len(frames)
        datagrams: list[bytearray] = [bytearray()]
        for f in frames:
            if datagrams[-1] and len(datagrams[-1]) + len(f) > _UDP_PAYLOAD:
                datagrams.append(bytearray())
            datagrams[-1] += f
        dropped = 0
        for d in datagrams:
            try:
                self._sock.sendto(d, peer)
            except ConnectionRefusedError:
                continue
            except OSError as exc:  # buffer full or unreachable: the datagram is lost
                log.debug("udp send to %s: %s", peer, exc)
                dropped += 1
        return dropped

    def close(self) -> None:
        self._sock.close()

    @property
    def connection_string(self) -> str:
        if self.remote is not None:
            return f"udpin:{self.remote[0]}:{self.remote[1]}"
        return f"udpout:{self.address[0]}:{self.address[1]}"


class _Stream:
    """Pending output of one stream socket/fd."""

    __slots__ = ("fd", "pending", "write")

    def __init__(self, fd: int, write: Callable[[bytes], int]) -> None:
        self.fd = fd
        self.pending = bytearray()
        self.write = write

    def push(self, data: bytes) -> bool:
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


class TcpTransport(Transport):
    """TCP server of the vehicle.

    Parameters
    ----------
    bind : (host, port)
        Listening address; port 0 = ephemeral (see :attr:`address`).
    """

    def __init__(self, bind: tuple[str, int] = ("127.0.0.1", 0)) -> None:
        self._new_peers, self._gone_peers = [], []
        self._srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._srv.bind(bind)
            self._srv.listen(8)
        except OSError as exc:
            self._srv.close()
            raise TransportError(f"cannot listen on tcp {bind[0]}:{bind[1]}: {exc.strerror or exc}") from None
        self._srv.setblocking(False)
        self.address: tuple[str, int] = self._srv.getsockname()
        # peer ("tcp", n): n counts connections, so a reused descriptor is a new peer
        self._clients: dict[tuple[str, int], tuple[socket.socket, _Stream]] = {}
        self._accepted = 0

    def filenos(self) -> list[int]:
        return [self._srv.fileno(), *(st.fd for _, st in self._clients.values())]

    def write_filenos(self) -> list[int]:
        return [st.fd for _, st in self._clients.values() if st.pending]

    def _drop(self, peer: tuple[str, int]) -> None:
        sock, _ = self._clients.pop(peer)
        sock.close()
        self._gone_peers.append(peer)

    def receive(self) -> list[tuple[Hashable, bytes, bool]]:
        while True:
            try:
                sock, _ = self._srv.accept()
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:
                log.debug("tcp accept: %s", exc)
                break
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._accepted += 1
            peer = ("tcp", self._accepted)
            self._clients[peer] = (sock, _Stream(sock.fileno(), sock.send))
            self._new_peers.append(peer)
        out: list[tuple[Hashable, bytes, bool]] = []
        for peer, (sock, _) in list(self._clients.items()):
            while True:
                try:
                    data = sock.recv(65536)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError:
                    data = b""
                if not data:
                    self._drop(peer)
                    break
                out.append((peer, data, False))
        return out

    def peers(self) -> list[Hashable]:
        return list(self._clients)

    def send_to(self, peer: Hashable, frames: list[bytes]) -> int:
        if not frames:
            return 0
        client = self._clients.get(peer)  # type: ignore[call-overload]
        if client is None:
            return len(frames)
        st = client[1]
        dropped = 0 if st.push(b"".join(frames)) else len(frames)
        if not st.flush():
            self._drop(peer)  # type: ignore[arg-type]
        return dropped

    def flush(self) -> None:
        for peer, (_, st) in list(self._clients.items()):
            if st.pending and not st.flush():
                self._drop(peer)

    def close(self) -> None:
        for peer in list(self._clients):
            self._clients.pop(peer)[0].close()
        self._srv.close()

    @property
    def connection_string(self) -> str:
        return f"tcp:{self.address[0]}:{self.address[1]}"


class PtyTransport(Transport):
    """Serial port of the vehicle on a pseudo-terminal (raw mode).

    Parameters
    ----------
    clock_ns : callable
        Monotonic time source [ns] (for the stale-output rule).
    """

    def __init__(self, clock_ns: Callable[[], int]) -> None:
        self._new_peers, self._gone_peers = [], []
        try:
            self._master, self._slave = os.openpty()
        except OSError as exc:
            raise TransportError(f"cannot open a pseudo-terminal: {exc.strerror or exc}") from None
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.device = os.ttyname(self._slave)
        self._out = _Stream(self._master, lambda b: os.write(self._master, b))
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
