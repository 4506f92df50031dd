"""The one server skeleton: a simulated vehicle served over its links, in real time or lockstep.

:class:`ServerLoop` owns what every server repeats -- the background thread, the lock, the
wake-up socket pair, ``select`` on the links' descriptors (woken early for the radio's next
delivery), the two run loops and the stop / close sequence -- and drives a :class:`Served`
vehicle, which only knows how to take input, tick and send.

* **Real time**: vehicle time follows the injected monotonic clock; the ticks catch up in bursts
  when the process was late, and more than a second behind it skips ahead and counts an overrun.
* **Lockstep**: the loop never ticks; the vehicle steps itself while it takes input (one control
  period per control message) and counts :attr:`Served.steps`.  While no step arrives,
  :meth:`Served.announce` runs every wall-clock second (a HEARTBEAT, or the rig's STATUS), so a
  client waiting for the first message gets it.

Input is taken and ticks run under :attr:`ServerLoop.lock`; a snapshot taken under it is
consistent.
"""

from __future__ import annotations

import contextlib
import logging
import math
import select
import socket
import threading
from collections.abc import Callable
from typing import Protocol, Self

from quadrotor.clock import Clock
from sitl.errors import SitlError, UsageError

__all__ = ["ServerLoop", "LoopServer", "Served", "Descriptors", "ticks_per_step", "THREAD_NAME"]

log = logging.getLogger(__name__)

#: Name of the background thread of every server.
THREAD_NAME = "sitl-server"
_MAX_CATCHUP_NS = 1_000_000_000
_IDLE_ANNOUNCE_NS = 1_000_000_000


def ticks_per_step(control_period_s: float, ticks_per_s: float, loop: str) -> int:
    """Onboard ticks in one lockstep control period; UsageError unless a whole number of at least one."""
    ticks = control_period_s * ticks_per_s
    if not 0 < control_period_s < math.inf or abs(ticks - round(ticks)) > 1e-6 or round(ticks) < 1:
        raise UsageError(f"control period {control_period_s!r} s is not a multiple of the "
                         f"{1000 / ticks_per_s:g} ms {loop} period")
    return round(ticks)


class Served(Protocol):
    """The vehicle side of a server, as :class:`ServerLoop` drives it (every call under the lock)."""

    #: Lockstep steps taken so far.
    steps: int

    @property
    def time_ns(self) -> int:
        """Vehicle time [ns]."""

    def announce(self) -> None:
        """Queue the message every peer gets at start and, in lockstep, every idle second."""

    def take_input(self, now_ns: int) -> None:
        """Receive and handle everything that arrived (in lockstep: stepping), greet new peers."""

    def tick(self) -> None:
        """Advance one onboard loop period and queue what it sends."""

    def flush(self, now_ns: int) -> None:
        """Send what is queued."""


class Descriptors(Protocol):
    """The links' side of the wait: what to ``select`` on and when the radio delivers next."""

    def filenos(self) -> list[int]: ...

    def write_filenos(self) -> list[int]: ...

    def flush_transports(self) -> None: ...

    def next_event_ns(self) -> int | None: ...


class ServerLoop:
    """Thread, lock, wake-up and run loops of one server.

    Parameters
    ----------
    vehicle : Served
    io : Descriptors
    clock : Clock
    lockstep : bool
    tick_ns : int
        The vehicle's onboard loop period (real time).
    release : callable
        Releases the server's own resources (transports, state files); called once by :meth:`close`.
    name : str
        What the errors call the server ("sitl server", "rig server").
    """

    def __init__(self, vehicle: Served, io: Descriptors, clock: Clock, *, lockstep: bool, tick_ns: int,
                 release: Callable[[], None], name: str) -> None:
        self.vehicle = vehicle
        self.io = io
        self.clock = clock
        self.lockstep = lockstep
        self.tick_ns = tick_ns
        self.name = name
        self.lock = threading.RLock()
        self.overruns = 0
        self.running = False
        self._release = release
        self._stop = threading.Event()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self._closed = False

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        """Run :meth:`run` in a background thread."""
        if self._thread is not None:
            raise SitlError(f"{self.name} already started")
        self._thread = threading.Thread(target=self._thread_main, name=THREAD_NAME, daemon=True)
        self._thread.start()

    def _thread_main(self) -> None:
        try:
            self.run()
        except BaseException as exc:  # logged here, re-raised by stop()
            log.exception("%s failed", self.name)
            self._error = exc

    def request_stop(self) -> None:
        """Ask :meth:`run` to return (thread- and signal-handler-safe)."""
        self._stop.set()
        with contextlib.suppress(OSError):  # closed already, or the buffer is full of wake-ups
            self._wake_w.send(b"x")

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the background thread, close everything; re-raises a failure of the loop."""
        self.request_stop()
        if self._thread is not None:
            self._thread.join(timeout)
            if self._thread.is_alive():
                raise SitlError(f"{self.name} thread did not stop")
            self._thread = None
        self.close()
        if self._error is not None:
            err, self._error = self._error, None
            raise err

    def close(self) -> None:
        """Release the server's resources and the wake-up sockets (idempotent; stop the loop first)."""
        if not self._closed:
            self._closed = True
            self._release()
            self._wake_r.close()
            self._wake_w.close()

    def run(self) -> None:
        """Serve until :meth:`request_stop` (blocking)."""
        self.running = True
        try:
            with self.lock:
                self.vehicle.announce()
                self.vehicle.flush(self.clock.now_ns())
            if self.lockstep:
                self._run_lockstep()
            else:
                self._run_realtime()
        finally:
            self.running = False

    # ------------------------------------------------------------------ loops
    def _run_realtime(self) -> None:
        v, clock, tick_ns = self.vehicle, self.clock, self.tick_ns
        wall0 = clock.now_ns()
        sim0 = v.time_ns
        while not self._stop.is_set():
            now = clock.now_ns()
            with self.lock:
                v.take_input(now)
                target = sim0 + (now - wall0)
                n = 0
                while v.time_ns + tick_ns <= target:
                    v.tick()
                    n += 1
                    if n * tick_ns > _MAX_CATCHUP_NS:
                        self.overruns += 1
                        wall0 = now - (v.time_ns - sim0)
                        break
                v.flush(now)
            self._wait(wall0 + (v.time_ns + tick_ns - sim0))

    def _run_lockstep(self) -> None:
        v, clock = self.vehicle, self.clock
        last_sent = clock.now_ns()
        steps_seen = v.steps
        while not self._stop.is_set():
            now = clock.now_ns()
            with self.lock:
                v.take_input(now)
                if v.steps != steps_seen:
                    steps_seen = v.steps
                    last_sent = now
                elif now - last_sent >= _IDLE_ANNOUNCE_NS:
                    v.announce()
                    last_sent = now
                v.flush(now)
            self._wait(last_sent + _IDLE_ANNOUNCE_NS)

    def _wait(self, until_ns: int) -> None:
        """Until input, ``until_ns``, the radio's next delivery or a wake-up; retries blocked output."""
        t = self.io.next_event_ns()
        if t is not None and t < until_ns:
            until_ns = t
        timeout = max(0.0, (until_ns - self.clock.now_ns()) * 1e-9)
        rlist = [*self.io.filenos(), self._wake_r.fileno()]
        wlist = self.io.write_filenos()
        try:
            r, w, _ = select.select(rlist, wlist, [], timeout)
        except (OSError, ValueError) as exc:  # a descriptor closed under us: retry next loop
            log.debug("select: %s", exc)
            return
        if self._wake_r.fileno() in r:
            try:
                while self._wake_r.recv(4096):
                    pass
            except (BlockingIOError, InterruptedError):
                pass
        if w:
            self.io.flush_transports()


class LoopServer:
    """The public lifecycle of a server whose work its :class:`ServerLoop` (``self.loop``) does."""

    loop: ServerLoop

    @property
    def lock(self) -> threading.RLock:
        """Held while the loop takes input or ticks: take it to read a consistent state."""
        return self.loop.lock


    @property
    def running(self) -> bool:
        """True while :meth:`run` serves."""
        return self.loop.running

    def start(self) -> Self:
        """Serve in a background thread; returns self."""
        self.loop.start()
        return self

    def run(self) -> None:
        """Serve until :meth:`request_stop` (blocking)."""
        self.loop.run()

    def request_stop(self) -> None:
        """Ask :meth:`run` to return (thread- and signal-handler-safe)."""
        self.loop.request_stop()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the background thread, close everything; re-raises a failure of the loop."""
        self.loop.stop(timeout)

    def close(self) -> None:
        """Release the transports and the server's state (idempotent; stop the loop first)."""
        self.loop.close()

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
