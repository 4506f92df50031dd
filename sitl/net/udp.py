"""The vehicle's UDP socket: the far end of a ground station's ``udpin:`` or ``udpout:``.

With ``remote`` the vehicle always sends there (ArduPilot's ``--out``; the ground station listens
with ``udpin:``); without, it answers whoever sent to its bound port (``udpout:``: the ground station
must send first).  Every sender address is a peer, at most 8: a new one evicts the one heard from
least recently, never ``remote``.  Every datagram is parsed on its own; output to a peer is packed
into datagrams of at most 1400 bytes, whole frames only.
"""

from __future__ import annotations

import errno
import logging
import socket
from collections.abc import Hashable

from sitl.errors import TransportError
from sitl.net.transport import Transport

__all__ = ["UdpTransport"]

log = logging.getLogger(__name__)

_UDP_PAYLOAD = 1400
_MAX_UDP_PEERS = 8


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
        super().__init__()
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
