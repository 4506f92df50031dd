"""The sockets of ``gcs fly --out URL`` (:mod:`gcs.link.forward`): the URLs, and non-blocking I/O per endpoint.

``udpout:HOST:PORT`` (we send there; replies come back to our socket), ``udpin:HOST:PORT`` (we
listen and send to every address heard from), ``tcpin:HOST:PORT`` (we listen, several clients),
``tcp:HOST:PORT`` (we connect out, again every :data:`TCP_RETRY_S` while it fails).  Nothing here
blocks or raises into the flight: errors are counted and said once through the forwarder (``host``:
its ``counters``, ``say(kind, text, key)`` and ``clock()``).  Each UDP endpoint and each TCP
connection has its own pymavlink parser.
"""

from __future__ import annotations

import errno
import socket
from dataclasses import dataclass
from collections.abc import Callable

from pymavlink.dialects.v20 import ardupilotmega as mavlink

__all__ = ["BadOutUrl", "OutUrl", "parse_out_url", "Endpoint", "SCHEMES"]

SCHEMES = ("udpout", "udpin", "tcpin", "tcp")
UDP_DATAGRAMS_PER_POLL = 256
TCP_BYTES_PER_POLL = 65536
#: A TCP client that does not read: frames beyond this many buffered bytes are dropped (counted).
TCP_BUFFER_BYTES = 262144
TCP_RETRY_S = 2.0


class BadOutUrl(ValueError):
    """An ``--out`` URL that cannot be used (the message names ``--out``, the URL and the reason)."""

    def __init__(self, url: str, reason: str) -> None:
        self.url = url
        self.reason = reason
        super().__init__(f"--out {url!r}: {reason}")


@dataclass(frozen=True)
class OutUrl:
    scheme: str
    host: str
    port: int
    text: str


def parse_out_url(text: str) -> OutUrl:
    """``SCHEME:HOST:PORT`` (:data:`SCHEMES`); port 0 (any free port) only for the listening ``udpin``/``tcpin``.

    Raises
    ------
    BadOutUrl
    """
    parts = str(text).split(":")
    if len(parts) != 3:
        raise BadOutUrl(text, f"expected SCHEME:HOST:PORT with SCHEME one of {', '.join(SCHEMES)} "
                              "(e.g. udpout:127.0.0.1:14551)")
    scheme, host, port_text = parts
    if scheme not in SCHEMES:
        raise BadOutUrl(text, f"unknown scheme {scheme!r} (one of {', '.join(SCHEMES)})")
    if not host:
        raise BadOutUrl(text, "no host (e.g. 127.0.0.1, or 0.0.0.0 to listen on every interface)")
    try:
        port = int(port_text)
    except ValueError:
        raise BadOutUrl(text, f"port {port_text!r} is not a number") from None
    lo = 0 if scheme in ("udpin", "tcpin") else 1
    if not lo <= port <= 65535:
        raise BadOutUrl(text, f"port {port} is outside {lo}..65535")
    return OutUrl(scheme, host, port, str(text))


def new_parser() -> mavlink.MAVLink:
    mav = mavlink.MAVLink(None)
    mav.robust_parsing = True
    return mav


class _Conn:
    """One TCP connection: its parser, its send buffer."""

    def __init__(self, sock: socket.socket, name: str, connected: bool) -> None:
        sock.setblocking(False)
        self.sock = sock
        self.name = name
        self.mav = new_parser()
        self.out = bytearray()
        self.closed = False
        self.connected = connected
        self.overflowed = False


#: ``deliver(name, parser, data, datagram)``: bytes a client sent.
Deliver = Callable[[str, mavlink.MAVLink, bytes, bool], None]


class Endpoint:
    """One ``--out`` URL's sockets (opened now: OSError when it cannot be, e.g. a port in use)."""

    def __init__(self, url: OutUrl, host) -> None:
        self.url = url
        self.host = host
        self.name = url.text
        self.sock: socket.socket | None = None
        self.mav = new_parser()
        self.addrs: dict = {}          # udpin: addresses heard from
        self.conns: list[_Conn] = []   # tcpin, tcp
        self.dest = None
        self.next_try = 0.0
        s = url.scheme
        if s in ("udpout", "tcp"):  # the name resolved now, never in the flight's loop
            self.dest = (socket.gethostbyname(url.host), url.port)
        if s == "tcp":
            return  # connected in receive (never blocking)
        if s == "tcpin":
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        else:
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            if s == "udpout":
                self.sock.bind(("0.0.0.0", 0))  # the clients' replies come back here
            else:
                self.sock.bind((url.host, url.port))
                self.name = f"{s}:{url.host}:{self.sock.getsockname()[1]}"
                if s == "tcpin":
                    self.sock.listen(8)
            self.sock.setblocking(False)
        except OSError:
            self.sock.close()
            raise

    @property
    def port(self) -> int:
        """The local port (a listening endpoint's, when given as 0)."""
        return self.sock.getsockname()[1] if self.sock is not None else 0

    def close(self) -> None:
        for c in self.conns:
            c.sock.close()
        self.conns.clear()
        if self.sock is not None:
            self.sock.close()

    # ------------------------------------------------------------------ to the clients
    def send(self, buf: bytes) -> None:
        h = self.host
        s = self.url.scheme
        if s in ("udpout", "udpin"):
            for addr in ([self.dest] if s == "udpout" else list(self.addrs)):
                try:
                    self.sock.sendto(buf, addr)
                except (BlockingIOError, InterruptedError):
                    h.counters.overflow += 1
                except OSError as exc:
                    h.counters.send_errors += 1
                    if exc.errno != errno.ECONNREFUSED:
                        h.say("warning", f"--out {self.name}: cannot send to {addr[0]}:{addr[1]}: "
                                         f"{exc.strerror or exc} (counted from now on)", ("send", self.name, addr))
            return
        for c in list(self.conns):
            if len(c.out) + len(buf) > TCP_BUFFER_BYTES:
                h.counters.overflow += 1
                if not c.overflowed:
                    c.overflowed = True
                    h.say("warning", f"--out {c.name} does not keep up: frames dropped (counted)")
                continue
            c.out += buf
            self._flush(c)

    def _flush(self, c: _Conn) -> None:
        while c.out and not c.closed:
            try:
                n = c.sock.send(c.out)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                self._gone(c, exc.strerror or str(exc))
                return
            if not c.connected:
                c.connected = True
                self.host.say("forward", f"--out {c.name} connected")
            del c.out[:n]

    # ------------------------------------------------------------------ from the clients
    def receive(self, deliver: Deliver) -> None:
        """Everything the clients sent since the last call, to ``deliver`` (never blocks)."""
        s = self.url.scheme
        if s in ("udpout", "udpin"):
            self._receive_udp(deliver)
            return
        if s == "tcpin":
            self._accept()
        elif not self.conns:
            self._connect()
        for c in list(self.conns):
            self._read(c, deliver)

    def _receive_udp(self, deliver: Deliver) -> None:
        h = self.host
        for _ in range(UDP_DATAGRAMS_PER_POLL):
            try:
                data, addr = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                if exc.errno not in (errno.ECONNREFUSED, errno.EAGAIN):
                    h.counters.send_errors += 1
                    h.say("warning", f"--out {self.name}: {exc.strerror or exc}", ("recv", self.name))
                return
            if self.url.scheme == "udpout":
                h.say("forward", f"--out {self.name}: a client answers from {addr[0]}:{addr[1]}", ("heard", self.name))
                deliver(self.name, self.mav, data, True)
                continue
            if addr not in self.addrs:
                self.addrs[addr] = True
                h.say("forward", f"--out {self.name}: client {addr[0]}:{addr[1]} connected")
            deliver(f"{self.name} client {addr[0]}:{addr[1]}", self.mav, data, True)

    def _accept(self) -> None:
        while True:
            try:
                sock, addr = self.sock.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                self.host.say("warning", f"--out {self.name}: accept failed: {exc.strerror or exc}",
                              ("accept", self.name))
                return
            c = _Conn(sock, f"{self.name} client {addr[0]}:{addr[1]}", True)
            self.conns.append(c)
            self.host.say("forward", f"--out {c.name} connected")

    def _connect(self) -> None:
        now = self.host.clock()
        if now < self.next_try:
            return
        self.next_try = now + TCP_RETRY_S
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setblocking(False)
        code = sock.connect_ex(self.dest)
        if code not in (0, errno.EINPROGRESS, errno.EWOULDBLOCK):
            sock.close()
            self._cannot_connect(errno.errorcode.get(code, str(code)))
            return
        self.conns.append(_Conn(sock, self.name, False))

    def _cannot_connect(self, why: str) -> None:
        self.host.say("warning", f"--out {self.name}: cannot connect: {why} (trying again every {TCP_RETRY_S:g} s)",
                      ("connect", self.name))

    def _read(self, c: _Conn, deliver: Deliver) -> None:
        try:
            data = c.sock.recv(TCP_BYTES_PER_POLL)
        except (BlockingIOError, InterruptedError):
            self._flush(c)
            return
        except OSError as exc:
            self._gone(c, exc.strerror or str(exc))
            return
        if not data:
            self._gone(c, "closed by the client")
            return
        if not c.connected:
            c.connected = True
            self.host.say("forward", f"--out {c.name} connected")
        deliver(c.name, c.mav, data, False)
        self._flush(c)

    def _gone(self, c: _Conn, why: str) -> None:
        c.closed = True
        c.sock.close()
        if c in self.conns:
            self.conns.remove(c)
        if not c.connected:
            self._cannot_connect(why)
            return
        self.host.counters.clients_gone += 1
        self.host.say("warning", f"--out {c.name} went away ({why})")
