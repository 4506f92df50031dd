"""The proxy itself: three UDP sockets, the fault chain and a scheduler of delayed datagrams."""

from __future__ import annotations

import collections
import contextlib
import heapq
import random
import selectors
import socket
import threading
import time
import traceback
from collections.abc import Callable, Sequence

from .faults import Fault, Out
from .monitor import Monitor
from .wire import DOWN, UP, mavlink

__all__ = ["MitmProxy"]


def _udp() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.setblocking(False)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
    return s


class MitmProxy:
    """The proxy (a background thread).  See the package docstring.

    Parameters
    ----------
    faults : list of Fault
    seed : int
        Seed of the one ``random.Random`` every fault draws from.
    vehicle_sysid, vehicle_compid : int
    """

    def __init__(self, faults: Sequence[Fault] = (), seed: int = 0, vehicle_sysid: int = 1,
                 vehicle_compid: int = 1) -> None:
        self.faults = list(faults)
        self.rng = random.Random(seed)
        self.monitor = Monitor(vehicle_sysid, vehicle_compid)
        self.vsock = _udp()               # the sitl sends here (sitl --udp 127.0.0.1:<vehicle_port>)
        self.gsock = _udp()               # talks to the ground station
        self.asock = _udp()               # the alternate source address (injections)
        self.vehicle_port = self.vsock.getsockname()[1]
        self.vehicle_addr: tuple[str, int] | None = None   # the sitl's own socket, learned
        self.gcs_addr: tuple[str, int] | None = None
        self.forwarded = {DOWN: 0, UP: 0}
        self.forwarded_bytes = {DOWN: 0, UP: 0}
        self.send_errors = 0
        self.enabled = True               # False: forward untouched (faults off)
        self._heap: list = []
        self._injections: collections.deque = collections.deque()
        self._seq = 0
        self._stop = threading.Event()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._thread: threading.Thread | None = None
        self._encoders: dict = {}
        self.error: BaseException | None = None
        self.error_text = ""
        self.taps: list[Callable[[str, bytes], None]] = []

    # ------------------------------------------------------------------ encoding for faults
    def _encoder(self, sysid: int, compid: int) -> mavlink.MAVLink:
        key = (sysid, compid)
        e = self._encoders.get(key)
        if e is None:
            e = self._encoders[key] = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        return e

    def repack(self, msg, sysid: int, compid: int, seq: int, signed_like: bool = False) -> bytes:
        """``msg`` framed as MAVLink 2 from (sysid, compid) with ``seq``.  ``signed_like``: the link is
        signed, which the proxy cannot do: half unsigned, half signed with a wrong key (forged)."""
        if signed_like and self.rng.random() < 0.5:
            return self.forge(msg, sysid, compid, seq, 0, self.rng.randrange(1, 2 ** 40))
        e = self._encoder(sysid, compid)
        e.seq = seq & 0xFF
        e.signing.sign_outgoing = False
        return bytes(msg.pack(e, force_mavlink1=False))

    def forge(self, msg, sysid: int, compid: int, seq: int, link_id: int, timestamp: int) -> bytes:
        """``msg`` signed with a random (wrong) key, claiming stream (link_id, sysid, compid) at ``timestamp``."""
        e = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        e.seq = seq & 0xFF
        e.signing.secret_key = self.rng.randbytes(32)
        e.signing.sign_outgoing = True
        e.signing.link_id = link_id & 0xFF
        e.signing.timestamp = timestamp
        return bytes(msg.pack(e, force_mavlink1=False))

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> MitmProxy:
        self._thread = threading.Thread(target=self._main, name="mitm-proxy", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        with contextlib.suppress(OSError):
            self._wake_w.send(b"x")
        if self._thread is not None:
            self._thread.join(5.0)
        for s in (self.vsock, self.gsock, self.asock, self._wake_r, self._wake_w):
            s.close()

    def __enter__(self) -> MitmProxy:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # ------------------------------------------------------------------ counts
    def stats(self) -> dict:
        per: dict[str, dict] = {}
        for f in self.faults:
            d = per.setdefault(f.name, {"events": 0, "injected_bytes": 0, "mutated_bytes": 0,
                                        "injected_datagrams": 0, "dropped_datagrams": 0})
            for k in d:
                d[k] += getattr(f.stats, k)
        return {"faults": per,
                "injected_bytes": sum(v["injected_bytes"] for v in per.values()),
                "mutated_bytes": sum(v["mutated_bytes"] for v in per.values()),
                "forwarded": dict(self.forwarded), "forwarded_bytes": dict(self.forwarded_bytes),
                "send_errors": self.send_errors}

    # ------------------------------------------------------------------ the loop
    def inject(self, direction: str, data: bytes, alt: bool = False) -> None:
        """Send ``data`` now towards the gcs (DOWN) or the vehicle (UP), from outside the fault chain
        (thread-safe: goes through the scheduler)."""
        self._injections.append((direction, Out(data, 0.0, alt)))
        with contextlib.suppress(OSError):
            self._wake_w.send(b"i")

    def _push(self, now: float, direction: str, out: Out) -> None:
        self._seq += 1
        heapq.heappush(self._heap, (now + out.delay, self._seq, direction, out.data, out.alt))

    def _send(self, direction: str, data: bytes, alt: bool) -> None:
        if direction == DOWN:
            addr, sock = self.gcs_addr, (self.asock if alt else self.gsock)
        else:
            addr, sock = self.vehicle_addr, (self.asock if alt else self.vsock)
        if addr is None:
            return
        try:
            sock.sendto(data, addr)
        except OSError:
            self.send_errors += 1

    def _received(self, direction: str, data: bytes) -> None:
        self.forwarded[direction] += 1
        self.forwarded_bytes[direction] += len(data)
        if direction == DOWN:
            self.monitor.down(data)
        else:
            self.monitor.up(data)
        for tap in self.taps:
            tap(direction, data)
        items = [Out(data)]
        if self.enabled:
            for f in self.faults:
                try:
                    items = f.process(self, direction, items)
                except Exception as exc:  # noqa: BLE001 - a harness bug: reported, the datagram goes on
                    if self.error is None:
                        self.error = exc
                        self.error_text = f"in fault {f.name}: " + traceback.format_exc()
        now = time.monotonic()
        for it in items:
            self._push(now, direction, it)

    def _main(self) -> None:
        try:
            self._loop()
        except BaseException as exc:  # reported by the harness
            self.error = exc
            raise

    def _loop(self) -> None:
        sel = selectors.DefaultSelector()
        sel.register(self.vsock, selectors.EVENT_READ, DOWN)
        sel.register(self.gsock, selectors.EVENT_READ, UP)
        sel.register(self.asock, selectors.EVENT_READ, None)
        sel.register(self._wake_r, selectors.EVENT_READ, "wake")
        while not self._stop.is_set():
            now = time.monotonic()
            while self._injections:
                self._push(now, *self._injections.popleft())
            while self._heap and self._heap[0][0] <= now:
                _, _, direction, data, alt = heapq.heappop(self._heap)
                self._send(direction, data, alt)
            timeout = max(0.0, self._heap[0][0] - now) if self._heap else 0.2
            for key, _ in sel.select(min(timeout, 0.2)):
                self._read(key.fileobj, key.data)

    def _read(self, sock: socket.socket, what: str | None) -> None:
        """Up to 256 datagrams waiting on ``sock``; the vehicle's and the ground station's go through."""
        for _ in range(256):
            try:
                data, addr = sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # ICMP port unreachable from an earlier send (peer gone)
                continue
            if what == "wake" or what is None:
                continue
            if what == DOWN:
                if self.vehicle_addr is None:
                    self.vehicle_addr = addr
                elif addr != self.vehicle_addr:
                    continue  # not the vehicle: not ours to forward
            elif self.gcs_addr is not None and addr != self.gcs_addr:
                continue
            self._received(what, data)
