"""Other ground stations beside ``gcs fly`` (``--out URL``, as MAVProxy's ``--out``): the vehicle's frames to
them, theirs to the vehicle — but never their setpoints.

:class:`Forwarder` holds the endpoints (pymavlink-style URLs, :func:`parse_out_url`):

* ``udpout:HOST:PORT`` — we send there; the client's replies come back to our socket;
* ``udpin:HOST:PORT`` — we listen, and send to every address heard from;
* ``tcpin:HOST:PORT`` — we listen and accept several clients;
* ``tcp:HOST:PORT`` — we connect out (again every 2 s while it fails).

Vehicle to clients: the verbatim bytes of every frame the link accepted from the vehicle
(:meth:`Forwarder.from_vehicle`, the link's tap), its own sequence numbers and signature kept.
Clients to vehicle (:meth:`Forwarder.poll`, from the link's ``drain``): each client's frames as it
sent them (its ids, sequence and signature untouched), except the setpoints in :data:`SETPOINTS`,
which are dropped and counted while gcs flies the vehicle.  Stream requests are forwarded and then
``on_streams`` is called (the flight asks for its own rates again); commands and mode changes are
forwarded and said as events; the flight then sees a mode change as the pilot's.

Every socket is non-blocking; a client that goes away or an endpoint that fails is counted and said
once, never raised into the flight.  Each UDP endpoint and each TCP connection has its own parser:
garbled bytes are counted and skipped.
"""

from __future__ import annotations

import functools
import re
import time
from dataclasses import dataclass, field
from collections.abc import Callable, Collection, Iterable

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.link.endpoints import SCHEMES, BadOutUrl, Endpoint, OutUrl, parse_out_url
from gcs.link.param_encoding import param_id
from quadrotor.mavlink.framing import parse_bytes, restore_unknown_header

__all__ = ["Forwarder", "ForwardCounters", "OutUrl", "BadOutUrl", "parse_out_url", "SETPOINTS", "SCHEMES"]

#: Messages that fly the vehicle: a client's are dropped while gcs flies it.
SETPOINTS = frozenset({"SET_ATTITUDE_TARGET", "SET_POSITION_TARGET_LOCAL_NED", "SET_POSITION_TARGET_GLOBAL_INT",
                       "SET_ACTUATOR_CONTROL_TARGET", "MANUAL_CONTROL", "RC_CHANNELS_OVERRIDE"})
#: Commands said every time a client sends them (others: the first time per client and command).
CONTROL_COMMANDS = frozenset({mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_CMD_COMPONENT_ARM_DISARM,
                              mavlink.MAV_CMD_NAV_LAND, mavlink.MAV_CMD_NAV_TAKEOFF,
                              mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, mavlink.MAV_CMD_MISSION_START,
                              mavlink.MAV_CMD_DO_FLIGHTTERMINATION, mavlink.MAV_CMD_DO_MOTOR_TEST,
                              mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, mavlink.MAV_CMD_DO_REPOSITION})
#: A COMMAND_ACK not addressed to us exactly is a client's when a client sent that command this recently [s].
CLIENT_ACK_WINDOW_S = 3.0
MAX_EVENTS = 200
_SR_PARAM = re.compile(r"SR\d+_")


@dataclass
class ForwardCounters:
    """What the forwarder did (the summary's ``link.forward``)."""

    to_clients: int = 0          # vehicle frames sent on (once per frame, whatever the number of clients)
    from_clients: int = 0        # client frames parsed
    to_vehicle: int = 0          # client frames written to the vehicle
    garbled: int = 0             # client bytes pymavlink could not parse (BAD_DATA, cut datagrams)
    stream_requests: int = 0
    commands: int = 0
    send_errors: int = 0         # socket errors sending to a client or writing to the vehicle
    overflow: int = 0            # frames dropped for a TCP client that does not read
    clients_gone: int = 0
    internal_errors: int = 0
    dropped: dict[str, int] = field(default_factory=dict)


class Forwarder:
    """Endpoints for ``urls`` (opened now; :class:`BadOutUrl` or OSError before anything else opens).

    Parameters
    ----------
    urls : iterable of str
    own_ids : (system, component)
        gcs's own ids on the vehicle link (a client using them is warned about: its ACKs look like ours).
    on_event : callable (kind, text) or None
        Events said before it is set are kept and said when it is (:meth:`attach`).
    on_streams : callable () or None
        A client's stream request was forwarded: the flight asks for its own rates again.
    protected : callable () -> collection of str, or None
        The parameters gcs set for the flight (and restores after it): a client's PARAM_SET of one is
        dropped (it would change the flight under the controller, and be overwritten at the restore).
    """

    def __init__(self, urls: Iterable[str], *, own_ids: tuple[int, int] = (255, 190),
                 on_event: Callable[[str, str], None] | None = None, on_streams: Callable[[], None] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        parsed = [parse_out_url(u) for u in urls]
        self.own_ids = own_ids
        self.on_streams = on_streams
        self.protected: Callable[[], Collection[str]] | None = None
        self.clock = clock
        self.counters = ForwardCounters()
        self.endpoints: list[Endpoint] = []
        self._on_event = on_event
        self._queued: list[tuple[str, str]] = []
        self._said: set = set()
        self._events = 0
        self._client_commands: dict[int, float] = {}
        self._streams_asked = False
        self.closed = False
        try:
            for u in parsed:
                self.endpoints.append(Endpoint(u, self))
        except OSError as exc:
            self.close(quiet=True)
            raise OSError(f"--out {u.text!r}: cannot open: {exc.strerror or exc}") from None
        if self.endpoints:
            self.say("forward", "--out: forwarding on " + ", ".join(ep.name for ep in self.endpoints))

    # ------------------------------------------------------------------ events
    def attach(self, on_event: Callable[[str, str], None]) -> None:
        """Say events through ``on_event`` from now on (those kept so far first)."""
        self._on_event = on_event
        queued, self._queued = self._queued, []
        for kind, text in queued:
            on_event(kind, text)

    def say(self, kind: str, text: str, key=None) -> None:
        """An event; with ``key``, only the first time for that key."""
        if key is not None:
            if key in self._said:
                return
            self._said.add(key)
        self._events += 1
        if self._events > MAX_EVENTS:
            if self._events == MAX_EVENTS + 1:
                self._emit("warning", f"more than {MAX_EVENTS} forwarding events: the rest only counted")
            return
        self._emit(kind, text)

    def _emit(self, kind: str, text: str) -> None:
        if self._on_event is None:
            self._queued.append((kind, text))
        else:
            self._on_event(kind, text)

    # ------------------------------------------------------------------ vehicle -> clients
    def from_vehicle(self, msg) -> None:
        """Send a frame the link accepted from the vehicle to every client (never raises)."""
        if self.closed:
            return
        try:
            buf = bytes(msg.get_msgbuf())
            if not buf:
                return
            self.counters.to_clients += 1
            for ep in self.endpoints:
                ep.send(buf)
        except Exception as exc:  # noqa: BLE001 - forwarding never breaks the flight
            self._internal(exc)

    # ------------------------------------------------------------------ clients -> vehicle
    def poll(self, write: Callable[[bytes], object]) -> None:
        """Read every client (never blocks) and ``write`` their frames to the vehicle (never raises)."""
        if self.closed:
            return
        self._streams_asked = False
        try:
            deliver = functools.partial(self._frames, write=write)
            for ep in self.endpoints:
                ep.receive(deliver)
            if self._streams_asked and self.on_streams is not None:
                self.on_streams()
        except Exception as exc:  # noqa: BLE001 - forwarding never breaks the flight
            self._internal(exc)

    def _frames(self, name: str, mav, data: bytes, datagram: bool, write) -> None:
        c = self.counters
        msgs, failed, truncated = parse_bytes(mav, data, datagram=datagram)
        c.garbled += int(failed) + int(truncated)
        for msg in msgs:
            t = msg.get_type()
            if t == "BAD_DATA":
                c.garbled += 1
                continue
            restore_unknown_header(msg)
            c.from_clients += 1
            src = (msg.get_srcSystem(), msg.get_srcComponent())
            who = f"{name} ({src[0]}/{src[1]})"
            if src == tuple(self.own_ids):
                self.say("warning", f"--out {who} uses gcs's own ids {src[0]}/{src[1]}: the vehicle's answers to "
                                     "it cannot be told from those to gcs (give it another source system or "
                                     "component)", ("own_ids", name))
            if t == "PARAM_SET" and self.protected is not None and param_id(msg) in self.protected():
                pid = param_id(msg)
                c.dropped[t] = c.dropped.get(t, 0) + 1
                self.say("forward", f"dropped PARAM_SET {pid} = {msg.param_value:g} from {src[0]}/{src[1]} on --out "
                                     f"{name}: gcs set {pid} for this flight and restores it after", ("param", pid))
                continue
            if t in SETPOINTS:
                c.dropped[t] = c.dropped.get(t, 0) + 1
                self.say("forward", f"dropped {t} from {src[0]}/{src[1]} on --out {name} (gcs flies the vehicle; "
                                     "further ones counted)", ("drop", t))
                continue
            try:
                write(bytes(msg.get_msgbuf()))
            except OSError as exc:
                c.send_errors += 1
                self.say("warning", f"--out: cannot write a client's frame to the vehicle: {exc.strerror or exc}",
                          ("write",))
                continue
            c.to_vehicle += 1
            self._inspect(who, msg, t)

    def _inspect(self, who: str, msg, t: str) -> None:
        """Stream requests, commands and mode changes of a forwarded client frame."""
        c = self.counters
        if t == "REQUEST_DATA_STREAM":
            c.stream_requests += 1
            self._streams_asked = True
            self.say("forward", f"{who} asked for streams (REQUEST_DATA_STREAM {msg.req_stream_id} at "
                                 f"{msg.req_message_rate} Hz, {'start' if msg.start_stop else 'stop'}): forwarded, "
                                 "gcs's own rates asked for again", ("streams", who))
        elif t in ("COMMAND_LONG", "COMMAND_INT"):
            c.commands += 1
            cmd = int(msg.command)
            self._client_commands[cmd] = self.clock()
            if cmd == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
                c.stream_requests += 1
                self._streams_asked = True
            params = [msg.param1, msg.param2, msg.param3, msg.param4]
            while params and params[-1] == 0:
                params.pop()
            entry = mavlink.enums["MAV_CMD"].get(cmd)
            cname = entry.name.removeprefix("MAV_CMD_") if entry is not None else str(cmd)
            self.say("forward", f"{who} sent {cname} ({', '.join(f'{p:g}' for p in params)}): forwarded",
                      None if cmd in CONTROL_COMMANDS else ("cmd", who, cmd))
        elif t == "SET_MODE":
            c.commands += 1
            self.say("forward", f"{who} sent SET_MODE (base mode {msg.base_mode}, custom mode {msg.custom_mode}): "
                                 "forwarded")
        elif t == "PARAM_SET":
            pid = param_id(msg)
            if _SR_PARAM.match(pid):
                c.stream_requests += 1
                self._streams_asked = True
            self.say("forward", f"{who} sent PARAM_SET {pid} = {msg.param_value:g}: forwarded")

    def client_sent_recently(self, command: int) -> bool:
        """A client sent ``command`` within :data:`CLIENT_ACK_WINDOW_S` (an ACK not addressed to us is its)."""
        t = self._client_commands.get(int(command))
        return t is not None and self.clock() - t < CLIENT_ACK_WINDOW_S

    def _internal(self, exc: Exception) -> None:
        self.counters.internal_errors += 1
        self.say("warning", f"--out: forwarding error {type(exc).__name__}: {exc} (counted from now on)",
                  ("internal",))

    # ------------------------------------------------------------------ the end
    def summary(self) -> dict:
        c = self.counters
        return {"endpoints": [ep.name for ep in self.endpoints], "to_clients": c.to_clients,
                "from_clients": c.from_clients, "to_vehicle": c.to_vehicle, "garbled": c.garbled,
                "dropped": dict(c.dropped), "stream_requests": c.stream_requests, "commands": c.commands,
                "send_errors": c.send_errors, "overflow": c.overflow, "clients_gone": c.clients_gone,
                "internal_errors": c.internal_errors}

    def close(self, quiet: bool = False) -> dict:
        """Close every socket (idempotent); the summary, said once as an event."""
        if not self.closed:
            self.closed = True
            for ep in self.endpoints:
                ep.close()
            c = self.counters
            if not quiet:
                dropped = sum(c.dropped.values())
                self._emit("forward", f"--out: {c.to_clients} vehicle frames forwarded, {c.to_vehicle} client frames "
                                     f"to the vehicle, {dropped} setpoints dropped"
                                     + (f" ({', '.join(f'{k} {v}' for k, v in sorted(c.dropped.items()))})"
                                        if dropped else "") + f", {c.garbled} garbled")
        return self.summary()
