"""A simulated ArduCopter behind a MAVLink endpoint: :class:`Simulation` and :class:`Dispatcher` on :class:`Links`.

Usage from Python (lockstep, UDP; the ground station connects with
``server.connection_string``, here ``udpout:127.0.0.1:<port>``)::

    from sitl.copter.server import SitlServer
    from sitl.net.udp import UdpTransport

    with SitlServer(UdpTransport(("127.0.0.1", 0)), lockstep=True, seed=1) as server:
        conn = mavutil.mavlink_connection(server.connection_string)
        conn.mav.heartbeat_send(6, 8, 0, 0, 0)        # udpout: say hello first
        conn.wait_heartbeat()
        ...

A lockstep step (one SET_ATTITUDE_TARGET or SET_ACTUATOR_CONTROL_TARGET addressed to this vehicle,
accepted or not: a target sent in a non-guided mode or with THROTTLE_IGNORE ticks the clock
without changing the target) is: apply the message, run the inner loop ``period / 2.5 ms`` times,
send every stream message that fell due (a stream at the control rate yields exactly one message
per step, stamped with the step's end), then the STATUSTEXTs.  A stream message goes to the links
whose schedule made it due, built once per tick however many links want it; replies go to the
link that asked; HEARTBEAT and STATUSTEXT go to every link, and every new peer gets a HEARTBEAT
once the input that revealed it has been handled.  What the dispatcher sends unasked (mission
re-requests and cancellations to the uploading link; HOME_POSITION, MISSION_CURRENT and
MISSION_ITEM_REACHED to every link) is drained after each message and each tick.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from quadrotor.clock import Clock, MonotonicClock
from quadrotor.wind import WindParams
from sitl.copter.dispatch import Dispatcher
from sitl.copter.simulation import InitialConditions, Simulation
from sitl.copter.streams import StreamScheduler
from sitl.copter.telemetry import TelemetryCounters, build, heartbeat
from sitl.copter.vehicle import VehicleParams
from sitl.copter.vehicle_file import load_vehicle
from sitl.errors import UsageError
from sitl.net.endpoint import LinkCounters, MavlinkEndpoint
from sitl.net.links import LinkKey, Links
from sitl.net.loop import LoopServer, ServerLoop, ticks_per_step
from sitl.net.radio import RadioParams
from sitl.net.transport import Transport

__all__ = ["SitlServer"]


class SitlServer(LoopServer):
    """A simulated ArduCopter on a transport.

    Parameters
    ----------
    transport : Transport or sequence of Transport
        :class:`~sitl.net.udp.UdpTransport`, :class:`~sitl.net.tcp.TcpTransport`
        or :class:`~sitl.net.pty.PtyTransport`, or several of them (each peer of
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
    emulate, ekf_ready_s
        Passed to :class:`~sitl.copter.simulation.Simulation` (``--emulate arducopter``).
    """

    def __init__(self, transport: Transport | Sequence[Transport], *, vehicle: VehicleParams | str | None = None,
                 model: str | None = None, lockstep: bool = False, control_period_s: float = 0.01, seed: int = 0,
                 wind: WindParams | None = None, initial: InitialConditions | None = None,
                 params: Mapping[str, float] | None = None, signing_key: bytes | None = None,
                 signing_state: str | os.PathLike | None = None, radio: RadioParams | None = None,
                 clock: Clock | None = None, loop_rate_hz: int = 400, prearm_delay_s: float = 0.0,
                 emulate: str | None = None, ekf_ready_s: float | None = None) -> None:
        transports = [transport] if isinstance(transport, Transport) else list(transport)
        try:
            if not transports:
                raise UsageError("no endpoint")
            v = vehicle if isinstance(vehicle, VehicleParams) else load_vehicle(vehicle)
            if model is not None:
                v = v.with_model(model)
            self._ticks_per_step = ticks_per_step(control_period_s, loop_rate_hz, "inner-loop")
            try:
                self.sim = Simulation(v, seed=seed, wind=wind, initial=initial, params=params,
                                      loop_rate_hz=loop_rate_hz, prearm_delay_s=prearm_delay_s, emulate=emulate,
                                      ekf_ready_s=ekf_ready_s)
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
        self.clock: Clock = clock or MonotonicClock()
        self.links = Links(transports, self.endpoint, self.counters, StreamScheduler, radio, seed)
        self._tcounters = TelemetryCounters()
        # the dispatcher's own scheduler is a fallback; every message comes with its link's
        self.dispatcher = Dispatcher(self.sim, StreamScheduler(), self.endpoint, self._tcounters, self.clock.now_ns)
        self.steps = 0
        self.loop = ServerLoop(self, self.links, self.clock, lockstep=lockstep, tick_ns=self.sim.tick_ns,
                               release=self._release, name="sitl server")

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

    @property
    def time_ns(self) -> int:
        """Simulated time [ns]."""
        return self.sim.time_ns

    def snapshot(self) -> dict[str, Any]:
        """A consistent copy of the vehicle's state (truth) and counters, for tests and tools."""
        with self.lock:
            ap = self.sim.autopilot
            return {
                "time_s": self.sim.time_s, "armed": ap.armed, "mode": ap.mode_name, "land_complete": ap.land_complete,
                "failsafe": ap.failsafe, "kinematics": self.sim.world.kinematics, "on_ground": self.sim.world.on_ground,
                "battery": self.sim.world.battery, "steps": self.steps, "overruns": self.loop.overruns,
                "targets_accepted": ap.targets_accepted, "targets_rejected": ap.targets_rejected,
                "counters": self.counters.as_dict(), "links": len(self.links),
            }

    def _release(self) -> None:
        self.endpoint.persist_signing(force=True)
        self.links.close()

    # ------------------------------------------------------------------ what the loop drives
    def announce(self) -> None:
        """Queue a HEARTBEAT for every link."""
        self.links.queue_all(heartbeat(self.sim))

    def take_input(self, now_ns: int) -> None:
        """Handle what the links received (stepping in lockstep), then greet the new peers."""
        self.handle_input(self.links.poll(now_ns))
        self.dispatcher.poll()
        self._queue_outbox()
        greet = self.links.take_greetings()
        if greet:
            hb = heartbeat(self.sim)
            for key in greet:
                self.links.queue(key, hb)

    def handle_input(self, items: list[tuple[LinkKey, bytes, bool]]) -> None:
        """Decode and handle ``(link key, data, is_datagram)`` items; in lockstep a target steps and flushes at once."""
        for key, data, datagram in items:
            msgs = self.endpoint.decode(key, data, datagram)
            if not msgs:
                continue
            streams = self.links.link(key).streams
            for msg in msgs:
                replies, step = self.dispatcher.handle(msg, streams, key)
                for r in replies:
                    self.links.queue(key, r)
                self._queue_outbox()
                self._queue_events()
                if step and self.lockstep:
                    self.step()
                    self.flush(self.clock.now_ns())

    def tick(self) -> None:
        """One inner-loop tick; queues the stream messages that fell due and the STATUSTEXTs."""
        sim = self.sim
        sim.tick()
        self.dispatcher.poll_vehicle()
        self._queue_outbox()
        built: dict[int, mavlink.MAVLink_message | None] = {}
        now = sim.time_ns
        for key, ln in self.links.links.items():
            for mid in ln.streams.due(now):
                if mid not in built:
                    if mid == mavlink.MAVLINK_MSG_ID_SYS_STATUS:
                        self.dispatcher.sync_counters()
                    built[mid] = build(mid, sim, self._tcounters)
                m = built[mid]
                if m is not None:
                    self.links.queue(key, m)
        self._queue_events()

    def step(self) -> None:
        """One lockstep control period."""
        for _ in range(self._ticks_per_step):
            self.tick()
        self.steps += 1

    def flush(self, now_ns: int) -> None:
        """Send what is queued; save the signing state when due."""
        self.links.flush(now_ns)
        self.endpoint.persist_signing()

    def _queue_outbox(self) -> None:
        """Queue the dispatcher's unasked messages (mission re-requests, HOME_POSITION, MISSION_CURRENT, ...)."""
        out = self.dispatcher.outbox
        if out:
            for key, m in out:
                if key is None:
                    self.links.queue_all(m)
                elif key in self.links.links:
                    self.links.queue(key, m)
            out.clear()

    def _queue_events(self) -> None:
        ev = self.sim.autopilot.events
        if ev:
            for severity, text in ev:
                self.links.queue_all(mavlink.MAVLink_statustext_message(severity, text.encode("ascii", "replace"),
                                                                         0, 0))
            ev.clear()
