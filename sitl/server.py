"""The networked SITL: a simulated vehicle behind a MAVLink endpoint, in real time or lockstep.

Usage from Python (lockstep, UDP; the ground station connects with
``server.connection_string``, here ``udpout:127.0.0.1:<port>``)::

    from sitl.server import SitlServer
    from sitl.transport import UdpTransport

    with SitlServer(UdpTransport(("127.0.0.1", 0)), lockstep=True, seed=1) as server:
        conn = mavutil.mavlink_connection(server.connection_string)
        conn.mav.heartbeat_send(6, 8, 0, 0, 0)        # udpout: say hello first
        conn.wait_heartbeat()
        ...

Time
----
* **Real time**: simulated time follows the injected monotonic clock; the
  400 Hz inner loop catches up in bursts if the process was late (more than
  one second behind: it skips ahead and counts an overrun).
* **Lockstep**: simulated time advances by one control period (10 ms by
  default) per SET_ATTITUDE_TARGET or SET_ACTUATOR_CONTROL_TARGET addressed to
  this vehicle (accepted or not: a target sent in a non-guided mode, or with
  THROTTLE_IGNORE, ticks the clock without changing the target).  Each step
  is: apply the message, run the inner loop ``period / 2.5 ms`` times, send
  every stream message that fell due (so a stream at the control rate
  yields exactly one message per step, stamped with the step's end), then
  STATUSTEXTs.  Other messages (commands, parameters) are answered at once
  without moving time.  While no step arrives, a HEARTBEAT goes out every
  wall-clock second so ``wait_heartbeat`` works.  Same seed + same commands
  = same trajectory, however fast the client runs.

Links
-----
The server may serve several endpoints at once (e.g. UDP and TCP); every
peer of every endpoint -- a UDP sender address (or the fixed ``udpin:``
destination), a TCP connection, the serial line -- is its own link
(:mod:`sitl.links`) with its own stream rates, as ArduPilot keeps them per
channel.  A stream message goes to the links whose schedule made it due;
replies go to the link that asked; HEARTBEAT (each link's 1 Hz, and the
lockstep wall-clock one) and STATUSTEXT go to every link.  Every new peer
(UDP sender, TCP client, first bytes on the serial line) gets a HEARTBEAT at
once.

Signing
-------
With ``signing_key``, frames are verified by :mod:`quadrotor.mavlink.signing` (signature
first, then timestamps); with ``signing_state`` the timestamps survive a
restart (file written at most once a second and when the server closes), so a
frame captured before the restart is refused.
"""

from __future__ import annotations

import logging
import math
import os
import select
import socket
import threading
from typing import Any, Mapping, Sequence

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from quadrotor.clock import Clock, MonotonicClock
from sitl.dispatch import Dispatcher
from sitl.endpoint import LinkCounters, MavlinkEndpoint
from sitl.errors import SitlError, UsageError
from sitl.links import LinkKey, Links
from sitl.radio import RadioParams
from sitl.simulation import InitialConditions, Simulation
from sitl.streams import StreamScheduler
from sitl.telemetry import TelemetryCounters, build, heartbeat
from sitl.transport import Transport
from sitl.vehicle_params import VehicleParams, load_vehicle
from quadrotor.wind import WindParams

__all__ = ["SitlServer"]

log = logging.getLogger(__name__)

_MAX_CATCHUP_S = 1.0


class SitlServer:
    """A simulated ArduCopter on a transport.

    Parameters
    ----------
    transport : Transport or sequence of Transport
        :class:`~sitl.transport.UdpTransport`, :class:`~sitl.transport.TcpTransport`
        or :class:`~sitl.transport.PtyTransport`, or several of them (each peer of
        each is a link).  The server closes them.
    vehicle : VehicleParams, str or None
        Parameters, a bundled vehicle name or a TOML path (default ``quad-1kg``).
    model : {"rigid_body", "reduced"} or None
        Override the vehicle file's plant.
    lockstep : bool
        Advance time by commands (see the module docstring) instead of the clock.
    control_period_s : float
        Lockstep step; a multiple of the inner-loop period (2.5 ms).
    seed : int
    wind : WindParams or None
    initial : InitialConditions or None
    params : mapping
        ArduPilot parameter overrides, e.g. ``{"GUID_OPTIONS": 8}``.
    signing_key : bytes or None
        32-byte MAVLink 2 signing key.
    signing_state : str, PathLike or None
        With a key: the file keeping the signing timestamps across restarts
        (:class:`~quadrotor.mavlink.signing.SigningStateFile`); None = in memory only.
    radio : RadioParams or None
        Baud limit / loss / latency applied to both directions of every link.
    clock : Clock or None
        Monotonic clock (default: :class:`~quadrotor.clock.MonotonicClock`).
    loop_rate_hz : int
        Inner-loop rate.
    prearm_delay_s : float
        Refuse arming for this long after boot (simulated time), like an
        autopilot whose estimator is settling.
    """

    def __init__(self, transport: Transport | Sequence[Transport], *, vehicle: VehicleParams | str | None = None,
                 model: str | None = None, lockstep: bool = False, control_period_s: float = 0.01, seed: int = 0,
                 wind: WindParams | None = None, initial: InitialConditions | None = None,
                 params: Mapping[str, float] | None = None, signing_key: bytes | None = None,
                 signing_state: str | os.PathLike | None = None, radio: RadioParams | None = None,
                 clock: Clock | None = None, loop_rate_hz: int = 400, prearm_delay_s: float = 0.0) -> None:
        transports = [transport] if isinstance(transport, Transport) else list(transport)
        try:
            if not transports:
                raise UsageError("no endpoint")
            v = vehicle if isinstance(vehicle, VehicleParams) else load_vehicle(vehicle)
            if model is not None:
                v = v.with_model(model)
            ticks = control_period_s * loop_rate_hz
            if not 0 < control_period_s < math.inf or abs(ticks - round(ticks)) > 1e-6 or round(ticks) < 1:
                raise UsageError(f"control period {control_period_s!r} s is not a multiple of the "
                                 f"{1000 / loop_rate_hz:g} ms inner-loop period")
            try:
                self.sim = Simulation(v, seed=seed, wind=wind, initial=initial, params=params,
                                      loop_rate_hz=loop_rate_hz, prearm_delay_s=prearm_delay_s)
            except ValueError as exc:
                raise UsageError(str(exc)) from None
            self.counters = LinkCounters()
            self.endpoint = MavlinkEndpoint(int(self.sim.params["SYSID_THISMAV"]), 1, signing_key, self.counters,
                                            signing_state)
        except BaseException:
            for t in transports:
                t.close()
            raise
        self.transport = transports[0]
        self.vehicle = v
        self.lockstep = lockstep
        self.control_period_s = control_period_s
        self._ticks_per_step = int(round(ticks))
        self.clock: Clock = clock or MonotonicClock()
        self.links = Links(transports, self.endpoint, self.counters, radio, seed)
        self._tcounters = TelemetryCounters()
        # the dispatcher's own scheduler is a fallback; every message comes with its link's
        self.dispatcher = Dispatcher(self.sim, StreamScheduler(), self.endpoint, self._tcounters)
        self.steps = 0
        self.overruns = 0
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self._closed = False
        self.running = False

    # ------------------------------------------------------------------ public API
    @property
    def transports(self) -> list[Transport]:
        """The endpoints, in order."""
        return self.links.transports

    @property
    def connection_string(self) -> str:
        """What the ground station passes to ``mavutil.mavlink_connection`` (the first endpoint's)."""
        return self.transport.connection_string

    @property
    def connection_strings(self) -> list[str]:
        """One connection string per endpoint."""
        return [t.connection_string for t in self.links.transports]

    @property
    def time_s(self) -> float:
        """Simulated time [s]."""
        return self.sim.time_s

    def snapshot(self) -> dict[str, Any]:
        """A consistent copy of the vehicle's state (truth) and counters, for tests and tools."""
        with self._lock:
            ap = self.sim.autopilot
            return {
                "time_s": self.sim.time_s, "armed": ap.armed, "mode": ap.mode_name, "land_complete": ap.land_complete,
                "failsafe": ap.failsafe, "kinematics": self.sim.world.kinematics, "on_ground": self.sim.world.on_ground,
                "battery": self.sim.world.battery, "steps": self.steps, "overruns": self.overruns,
                "targets_accepted": ap.targets_accepted, "targets_rejected": ap.targets_rejected,
                "counters": self.counters.as_dict(), "links": len(self.links),
            }

    def start(self) -> "SitlServer":
        """Run :meth:`run` in a background thread; returns self."""
        if self._thread is not None:
            raise SitlError("server already started")
        self._thread = threading.Thread(target=self._thread_main, name="sitl-server", daemon=True)
        self._thread.start()
        return self

    def _thread_main(self) -> None:
        try:
            self.run()
        except BaseException as exc:  # noqa: BLE001 - re-raised by stop()
            log.exception("sitl server failed")
            self._error = exc

    def request_stop(self) -> None:
        """Ask :meth:`run` to return (thread- and signal-handler-safe)."""
        self._stop.set()
        try:
            self._wake_w.send(b"x")
        except OSError:
            pass

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the background thread, close everything; re-raises a failure of the loop."""
        self.request_stop()
        if self._thread is not None:
            self._thread.join(timeout)
            if self._thread.is_alive():
                raise SitlError("sitl server thread did not stop")
            self._thread = None
        self.close()
        if self._error is not None:
            err, self._error = self._error, None
            raise err

    def close(self) -> None:
        """Save the signing state, release the transports and wake-up sockets (idempotent; stop the loop first)."""
        if not self._closed:
            self._closed = True
            self.endpoint.persist_signing(force=True)
            self.links.close()
            self._wake_r.close()
            self._wake_w.close()

    def __enter__(self) -> "SitlServer":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def run(self) -> None:
        """Serve until :meth:`request_stop` (blocking)."""
        self.running = True
        try:
            with self._lock:
                self.links.queue_all(heartbeat(self.sim))
                self._flush(self.clock.now_ns())
            if self.lockstep:
                self._run_lockstep()
            else:
                self._run_realtime()
        finally:
            self.running = False

    # ------------------------------------------------------------------ loops
    def _run_realtime(self) -> None:
        tick_ns = self.sim.tick_ns
        wall0 = self.clock.now_ns()
        sim0 = self.sim.time_ns
        while not self._stop.is_set():
            now = self.clock.now_ns()
            with self._lock:
                self._process(self._poll_input(now))
                self._greet_new_peers()
                target = sim0 + (now - wall0)
                n = 0
                while self.sim.time_ns + tick_ns <= target:
                    self._tick()
                    n += 1
                    if n * tick_ns > _MAX_CATCHUP_S * 1e9:
                        self.overruns += 1
                        wall0 = now - (self.sim.time_ns - sim0)
                        break
                self._flush(now)
            next_tick = wall0 + (self.sim.time_ns + tick_ns - sim0)
            self._wait(next_tick)

    def _run_lockstep(self) -> None:
        last_hb = self.clock.now_ns()
        steps_seen = self.steps
        while not self._stop.is_set():
            now = self.clock.now_ns()
            with self._lock:
                self._process(self._poll_input(now))
                self._greet_new_peers()
                if self.steps != steps_seen:
                    steps_seen = self.steps
                    last_hb = now
                elif now - last_hb >= 1_000_000_000:
                    self.links.queue_all(heartbeat(self.sim))
                    last_hb = now
                self._flush(now)
            self._wait(last_hb + 1_000_000_000)

    def _wait(self, until_ns: int) -> None:
        t = self.links.next_event_ns()
        if t is not None and t < until_ns:
            until_ns = t
        timeout = max(0.0, (until_ns - self.clock.now_ns()) * 1e-9)
        rlist = [*self.links.filenos(), self._wake_r.fileno()]
        wlist = self.links.write_filenos()
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
            self.links.flush_transports()

    # ------------------------------------------------------------------ I/O
    def _poll_input(self, now_ns: int) -> list[tuple[LinkKey, bytes, bool]]:
        return self.links.poll(now_ns)

    def _process(self, items: list[tuple[LinkKey, bytes, bool]]) -> None:
        """Decode and handle input: ``(link key, data, is_datagram)`` items."""
        for key, data, datagram in items:
            msgs = self.endpoint.decode(key, data, datagram)
            if not msgs:
                continue
            streams = self.links.link(key).streams
            for msg in msgs:
                replies, step = self.dispatcher.handle(msg, streams)
                for r in replies:
                    self.links.queue(key, r)
                self._drain_events()
                if step and self.lockstep:
                    self._step()
                    self._flush(self.clock.now_ns())

    def _greet_new_peers(self) -> None:
        # after the input that revealed them was handled
        greet = self.links.take_greetings()
        if greet:
            hb = heartbeat(self.sim)
            for key in greet:
                self.links.queue(key, hb)

    def _flush(self, now_ns: int) -> None:
        self.links.flush(now_ns)
        self.endpoint.persist_signing()

    def _drain_events(self) -> None:
        ev = self.sim.autopilot.events
        if ev:
            for severity, text in ev:
                self.links.queue_all(mavlink.MAVLink_statustext_message(severity, text.encode("ascii", "replace"),
                                                                         0, 0))
            ev.clear()

    # ------------------------------------------------------------------ simulation
    def _tick(self) -> None:
        sim = self.sim
        sim.tick()
        built: dict[int, mavlink.MAVLink_message | None] = {}
        now = sim.time_ns
        for key, ln in self.links.links.items():
            due = ln.streams.due(now)
            for mid in due:
                if mid not in built:
                    if mid == mavlink.MAVLINK_MSG_ID_SYS_STATUS:
                        self.dispatcher.sync_counters()
                    built[mid] = build(mid, sim, self._tcounters)
                m = built[mid]
                if m is not None:
                    self.links.queue(key, m)
        self._drain_events()

    def _step(self) -> None:
        for _ in range(self._ticks_per_step):
            self._tick()
        self.steps += 1
