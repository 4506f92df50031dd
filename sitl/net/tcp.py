"""The vehicle's TCP server (``tcp:HOST:PORT`` for the ground station): every connection is a peer.

A peer is ``("tcp", n)`` with ``n`` counting connections, so a client that reconnects (and may get
the same descriptor) is a new peer with fresh stream rates.  A client whose output backs up beyond
256 KiB loses frames; one whose socket fails is dropped.
"""

from __future__ import annotations

import logging
import socket
from collections.abc import Hashable

from sitl.errors import TransportError
from sitl.net.transport import PendingOutput, Transport

__all__ = ["TcpTransport"]

log = logging.getLogger(__name__)


class TcpTransport(Transport):
    """TCP server of the vehicle.

    Parameters
    ----------
    bind : (host, port)
        Listening address; port 0 = ephemeral (see :attr:`address`).
    """

    def __init__(self, bind: tuple[str, int] = ("127.0.0.1", 0)) -> None:
        super().__init__()
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
        self._clients: dict[tuple[str, int], tuple[socket.socket, PendingOutput]] = {}
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
            self._clients[peer] = (sock, PendingOutput(sock.fileno(), sock.send))
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
