"""A second client: a MAVProxy-like ground station that keeps asking the vehicle for low stream rates."""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from typing import TYPE_CHECKING

from .wire import UP, mavlink

if TYPE_CHECKING:
    from .proxy import MitmProxy

__all__ = ["StreamClobberer"]


class StreamClobberer:
    """A MAVProxy-like second ground station talking to the vehicle directly (its own address, or
    ``target``: an endpoint of its own; or ``shared_link``: on the ground station's own link, as when
    both sit behind one MAVProxy):
    HEARTBEAT once a second and REQUEST_DATA_STREAM(target 1/1, MAV_DATA_STREAM_ALL, ``rate_hz``,
    start) at connect and every ``period_s`` of vehicle time (or of wall time, whichever comes
    first), as MAVProxy's ``set streamrate`` keeps doing.  Everything it receives is read and dropped.
    """

    def __init__(self, proxy: MitmProxy, rate_hz: int = 4, period_s: float = 2.0, sysid: int = 255,
                 compid: int = 0, target: tuple[str, int] | None = None, shared_link: bool = False) -> None:
        self.proxy = proxy
        self.target = target  # None: the vehicle's socket as the proxy learned it
        self.shared_link = shared_link  # True: injected into the ground station's own link (same address)
        self.rate_hz, self.period_s = rate_hz, period_s
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self.requests = 0
        self.received_bytes = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _send(self, msg) -> None:
        data = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) & 0xFF
        if self.shared_link:
            self.proxy.inject(UP, bytes(data))
            return
        addr = self.target or self.proxy.vehicle_addr
        if addr is None:
            return
        with contextlib.suppress(OSError):
            self.sock.sendto(data, addr)

    def request(self) -> None:
        self._send(self.mav.request_data_stream_encode(1, 1, mavlink.MAV_DATA_STREAM_ALL, self.rate_hz, 1))
        self.requests += 1

    def _drain(self) -> None:
        with contextlib.suppress(OSError):
            while True:
                self.received_bytes += len(self.sock.recv(65535))

    def _run(self) -> None:
        last_wall = last_hb = -1e9
        last_vt = None
        while not self._stop.wait(0.01):
            self._drain()
            if self.proxy.vehicle_addr is None:  # the SITL is not up yet
                continue
            now = time.monotonic()
            vt = self.proxy.monitor.vehicle_time_ms
            if now - last_hb >= 1.0:
                last_hb = now
                self._send(self.mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0))
            if last_vt is None or vt - last_vt >= self.period_s * 1000 or now - last_wall >= self.period_s:
                last_vt, last_wall = vt, now
                self.request()

    def start(self) -> StreamClobberer:
        self._thread = threading.Thread(target=self._run, name="stream-clobberer", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
        self.sock.close()
