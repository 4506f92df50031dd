"""What the emulated autopilot does with each incoming MAVLink message.

:meth:`Dispatcher.handle` takes one decoded message and returns the replies
to send and whether the message ticks the lockstep clock.  Handled:

=============================  ==============================================================
SET_ATTITUDE_TARGET            guided target (:meth:`Autopilot.set_attitude_target`); lockstep tick
SET_ACTUATOR_CONTROL_TARGET    group 0: normalised torques + thrust; lockstep tick
COMMAND_LONG / COMMAND_INT     :mod:`sitl.copter.dispatch_commands` (modes, arming, message
                               intervals and requests, home, mission current, the navigation
                               commands of :mod:`sitl.copter.dispatch_nav`); COMMAND_ACK always
SET_MODE                       custom mode; COMMAND_ACK with command = 11 (as ArduPilot)
REQUEST_DATA_STREAM            stream groups (``SR0_*`` parameters)
PARAM_REQUEST_READ/LIST        PARAM_VALUE
PARAM_SET                      as ArduPilot 4.8: the value is set even outside the documented
                               range and echoed with ``param_index`` 65535 (-1); an unknown name
                               or a non-finite value: PARAM_ERROR only; a read-only one:
                               "Param write denied (NAME)" + PARAM_ERROR + the unchanged value
MISSION_*                      the mission protocol (:mod:`sitl.copter.mission`)
FILE_TRANSFER_PROTOCOL         MAVFTP (:mod:`sitl.copter.ftp`)
SET_HOME_POSITION              home moved (and locked), HOME_POSITION to every link
navigation messages            ``dispatch_nav.NAV_MESSAGES`` (position targets) -> ``nav_message``
TIMESYNC                       request (tc1 = 0) answered with tc1 = the vehicle clock [ns] (Simulation.boot_ns)
=============================  ==============================================================

Besides the replies, :attr:`Dispatcher.outbox` collects what goes out unasked, as
``(link, message)`` (link None = every link): the mission protocol's repeated requests and
cancellations (:meth:`Dispatcher.poll`, server clock), HOME_POSITION when home moves,
MISSION_CURRENT when the current item changes and MISSION_ITEM_REACHED for every item AUTO
reached (:meth:`Dispatcher.poll_vehicle`, every tick).  The server drains it.

Messages whose ``target_system`` is neither 0 nor ours (or whose
``target_component`` is neither 0 nor ours) are ignored and counted;
anything else is ignored (counted as unhandled, except HEARTBEAT).

Stream rates are per link: :meth:`Dispatcher.handle` takes the requesting
link's :class:`~sitl.copter.streams.StreamScheduler`, and SET_MESSAGE_INTERVAL,
GET_MESSAGE_INTERVAL, REQUEST_DATA_STREAM and a PARAM_SET of an ``SR0_*``
rate act on that one only (the ``SR0_*`` values show the last request of any
link).

Non-finite values (NaN, inf) where a number is used -- a SET_ATTITUDE_TARGET
quaternion, rate or thrust that is not ignored by ``type_mask``, actuator
controls, the parameters of the commands above, a PARAM_SET value -- refuse
the message (targets: not applied; commands: MAV_RESULT_DENIED; parameters:
unchanged, PARAM_ERROR VALUE_OUT_OF_RANGE) and count it in ``LinkCounters.non_finite``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Hashable

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sitl.copter.autopilot import SEVERITY_WARNING
from sitl.copter.dispatch_commands import NAV_MESSAGES, CommandsMixin, dispatch_nav
from sitl.copter.ftp import FtpServer, ftp_message
from sitl.copter.mission import MISSION_MESSAGES, MissionProtocol, mission_current
from sitl.copter.params import STREAM_PARAMS
from sitl.copter.simulation import Simulation
from sitl.copter.streams import StreamScheduler
from sitl.copter.telemetry import TelemetryCounters
from sitl.copter.telemetry_nav import HomeTracker, home_position, set_home
from sitl.net.endpoint import LinkCounters, MavlinkEndpoint

__all__ = ["Dispatcher", "STEPPING_MESSAGES"]

M = mavlink
STEPPING_MESSAGES = frozenset({"SET_ATTITUDE_TARGET", "SET_ACTUATOR_CONTROL_TARGET"})
# ATTITUDE_TARGET_TYPEMASK bits: body roll/pitch/yaw rate ignore 1/2/4, throttle 64, attitude 128
_THROTTLE_IGNORE = 64
_ATTITUDE_IGNORE = 128
_PARAM_INDEX_NONE = 65535  # ArduPilot's -1: a PARAM_VALUE that is not an answer to a read by index


def _text(value) -> str:
    if isinstance(value, (bytes, bytearray)):
        return bytes(value).split(b"\x00", 1)[0].decode("ascii", errors="replace")
    return str(value)


class Dispatcher(CommandsMixin):
    """Message handlers of one vehicle.

    Parameters
    ----------
    sim : Simulation
    streams : StreamScheduler
        Rates acted on when :meth:`handle` is given none (the server gives each message its link's).
    endpoint : MavlinkEndpoint
    telemetry_counters : TelemetryCounters
        Updated from the link counters for SYS_STATUS.
    clock : callable or None
        Monotonic time [ns] of the mission protocol's timeouts (default ``time.monotonic_ns``;
        the server gives its clock).
    """

    def __init__(self, sim: Simulation, streams: StreamScheduler, endpoint: MavlinkEndpoint,
                 telemetry_counters: TelemetryCounters, clock: Callable[[], int] | None = None) -> None:
        self.sim = sim
        self.streams = streams
        self.endpoint = endpoint
        self.tcounters = telemetry_counters
        self.counters: LinkCounters = endpoint.counters
        self._link: StreamScheduler | None = None
        self._key: Hashable | None = None
        self._clock = clock or time.monotonic_ns
        self.mission = MissionProtocol(sim, lambda: self.endpoint.system_id)
        self.ftp = FtpServer(sim.params)
        self.home = HomeTracker(sim)
        #: Unasked messages ``(link or None for all, message)``; drained by the server.
        self.outbox: list[tuple[Hashable | None, mavlink.MAVLink_message]] = []
        self._current_sent = self._current_key()
        self._commands = self._command_table()
        self._handlers = {
            "SET_ATTITUDE_TARGET": self._set_attitude_target,
            "SET_ACTUATOR_CONTROL_TARGET": self._set_actuator_control_target,
            "COMMAND_LONG": self._command_long,
            "COMMAND_INT": self._command_int,
            "SET_MODE": self._set_mode,
            "REQUEST_DATA_STREAM": self._request_data_stream,
            "PARAM_REQUEST_READ": self._param_request_read,
            "PARAM_REQUEST_LIST": self._param_request_list,
            "PARAM_SET": self._param_set,
            "TIMESYNC": self._timesync,
            "FILE_TRANSFER_PROTOCOL": self._ftp,
            "SET_HOME_POSITION": self._set_home_position,
        }
        for name in MISSION_MESSAGES:
            self._handlers[name] = self._mission
        for name in NAV_MESSAGES:
            self._handlers[name] = self._nav_message
        sim.params.add_listener(self._param_changed)

    # ------------------------------------------------------------------ entry
    def handle(self, msg: mavlink.MAVLink_message, streams: StreamScheduler | None = None,
               link: Hashable | None = None) -> tuple[list[mavlink.MAVLink_message], bool]:
        """Act on ``msg`` received on ``link`` whose stream rates are ``streams`` (default: the constructor's).

        Returns
        -------
        (replies, tick)
            Messages to send now, and True when ``msg`` ticks the lockstep clock.
        """
        kind = msg.get_type()
        handler = self._handlers.get(kind)
        if handler is None:
            if kind != "HEARTBEAT":
                self.counters.unhandled += 1
            return [], False
        if not self._for_us(msg):
            return [], False
        replies: list[mavlink.MAVLink_message] = []
        self._link = streams if streams is not None else self.streams
        self._key = link
        try:
            handler(msg, replies)
        except Exception:  # noqa: BLE001 - a hostile field value must never stop the vehicle
            self.counters.handler_errors += 1
        finally:
            self._link = None
            self._key = None
        return replies, kind in STEPPING_MESSAGES

    def poll(self) -> None:
        """Mission-protocol timeouts (server clock) into :attr:`outbox`."""
        self.mission.poll(self._clock())
        if self.mission.outbox:
            self.outbox.extend(self.mission.outbox)
            self.mission.outbox.clear()

    def poll_vehicle(self) -> None:
        """HOME_POSITION, MISSION_CURRENT and MISSION_ITEM_REACHED when due, into :attr:`outbox` (every link)."""
        sim = self.sim
        if self.home.poll():
            hp = home_position(sim)
            if hp is not None:
                self.outbox.append((None, hp))
        store = sim.missions
        if store.reached:
            for seq in store.reached:
                self.outbox.append((None, M.MAVLink_mission_item_reached_message(seq & 0xFFFF)))
            store.reached.clear()
        key = self._current_key()
        if key != self._current_sent:
            self.outbox.append((None, mission_current(sim)))
            self._current_sent = key

    def _current_key(self) -> tuple[int, int, int, bool]:
        """What MISSION_CURRENT shows: current item, mission length, mode, armed."""
        store, ap = self.sim.missions, self.sim.autopilot
        return store.current_seq, store.count(0), int(ap.mode), ap.armed

    def sync_counters(self) -> None:
        """Copy link counters into the SYS_STATUS counters."""
        c, t = self.counters, self.tcounters
        t.frames_in = c.frames_in
        t.errors = c.bad_prefix + c.bad_crc + c.malformed + c.signature_rejected
        t.unknown = c.unknown
        t.bad_signature = c.signature_rejected
        t.wrong_target = c.wrong_target

    def _non_finite(self, *values: float) -> bool:
        """True (and counted) if any of ``values`` is NaN or infinite."""
        if all(math.isfinite(v) for v in values):
            return False
        self.counters.non_finite += 1
        return True

    def _for_us(self, msg) -> bool:
        ts = getattr(msg, "target_system", None)
        if ts is not None and ts not in (0, self.endpoint.system_id):
            self.counters.wrong_target += 1
            return False
        tc = getattr(msg, "target_component", None)
        if tc is not None and tc not in (0, self.endpoint.mav.srcComponent):
            self.counters.wrong_target += 1
            return False
        return True

    @property
    def _now(self) -> int:
        return self.sim.time_ns

    # ------------------------------------------------------------------ targets
    def _set_attitude_target(self, msg, replies) -> None:
        mask = int(msg.type_mask)
        rates = (float(msg.body_roll_rate), float(msg.body_pitch_rate), float(msg.body_yaw_rate))
        used = [float(msg.thrust)] if not mask & _THROTTLE_IGNORE else []
        if not mask & _ATTITUDE_IGNORE:
            used += [float(v) for v in msg.q]
        used += [r for bit, r in zip((1, 2, 4), rates, strict=True) if not mask & bit]
        if self._non_finite(*used):
            self.sim.autopilot.targets_rejected += 1
            return
        self.sim.autopilot.set_attitude_target(mask, list(msg.q), rates, float(msg.thrust), self._now)

    def _set_actuator_control_target(self, msg, replies) -> None:
        if int(msg.group_mlx) != 0 or self._non_finite(*(float(v) for v in msg.controls[:4])):
            self.sim.autopilot.targets_rejected += 1
            return
        self.sim.autopilot.set_actuator_controls(list(msg.controls), self._now)

    # ------------------------------------------------------------------ modes, streams
    def _set_mode(self, msg, replies) -> None:
        ok = False
        if int(msg.base_mode) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            ok = self.sim.autopilot.set_mode(int(msg.custom_mode), self._now)[0]
        replies.append(M.MAVLink_command_ack_message(M.MAVLINK_MSG_ID_SET_MODE,
                                                     M.MAV_RESULT_ACCEPTED if ok else M.MAV_RESULT_FAILED, 0, 0,
                                                     msg.get_srcSystem(), msg.get_srcComponent()))

    def _request_data_stream(self, msg, replies) -> None:
        rate = int(msg.req_message_rate) if int(msg.start_stop) else 0
        sid = int(msg.req_stream_id)
        names = list(STREAM_PARAMS.values()) if sid == M.MAV_DATA_STREAM_ALL else (
            [STREAM_PARAMS[sid]] if sid in STREAM_PARAMS else [])
        for name in names:
            self.sim.params.set(name, min(rate, 400))

    # ------------------------------------------------------------------ parameters
    def _param_changed(self, name: str, value: float) -> None:
        if name == "SYSID_THISMAV" and 1 <= value <= 255:
            self.endpoint.system_id = int(value)
        if self._link is None:  # not changed by a link (start-up overrides): no link's rates change
            return
        for sid, pname in STREAM_PARAMS.items():
            if pname == name:
                self._link.set_group_rate(sid, value, self._now)

    def _param_value(self, name: str, index: int | None = None) -> mavlink.MAVLink_message:
        ps = self.sim.params
        return M.MAVLink_param_value_message(name.encode("ascii"), ps[name], ps.spec(name).ptype, len(ps),
                                             ps.index(name) if index is None else index)

    def _param_request_read(self, msg, replies) -> None:
        ps = self.sim.params
        idx = int(msg.param_index)
        name = ps.name_at(idx) if idx >= 0 else _text(msg.param_id)
        if name is None or name not in ps:
            self.counters.unhandled += 1
            return
        replies.append(self._param_value(name))

    def _param_request_list(self, msg, replies) -> None:
        replies.extend(self._param_value(name) for name in self.sim.params)

    def _param_error(self, msg, name: str, error: int, replies) -> None:
        replies.append(M.MAVLink_param_error_message(msg.get_srcSystem(), msg.get_srcComponent(),
                                                     name.encode("ascii", "replace")[:16], -1, error))

    def _param_set(self, msg, replies) -> None:
        ps = self.sim.params
        name = _text(msg.param_id)
        if name not in ps:
            self.counters.unhandled += 1
            self._param_error(msg, name, M.MAV_PARAM_ERROR_DOES_NOT_EXIST, replies)
            return
        if self._non_finite(float(msg.param_value)):
            self._param_error(msg, name, M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE, replies)
            return
        ok, _reason = ps.set(name, msg.param_value, check_range=False)
        if not ok:  # read-only
            self.sim.autopilot.events.append((SEVERITY_WARNING, f"Param write denied ({name})"))
            self._param_error(msg, name, M.MAV_PARAM_ERROR_PERMISSION_DENIED, replies)
        replies.append(self._param_value(name, _PARAM_INDEX_NONE))

    # ------------------------------------------------------------------ misc
    def _timesync(self, msg, replies) -> None:
        if int(msg.tc1) == 0:
            replies.append(M.MAVLink_timesync_message(self.sim.boot_ns, int(msg.ts1)))

    # ------------------------------------------------------------------ mission, FTP, home, navigation
    def _mission(self, msg, replies) -> None:
        self.mission.handle(msg, self._key, self._clock(), replies)

    def _ftp(self, msg, replies) -> None:
        if int(msg.target_network) != 0:
            return
        for payload in self.ftp.handle(msg.payload):
            replies.append(ftp_message(payload, msg.get_srcSystem(), msg.get_srcComponent()))

    def _set_home_position(self, msg, replies) -> None:
        lat, lon, alt = int(msg.latitude) * 1e-7, int(msg.longitude) * 1e-7, int(msg.altitude) * 1e-3
        if self.sim.autopilot.position_ready(self._now) and set_home(self.sim, lat, lon, alt, lock=True):
            self.poll_vehicle()

    def _nav_message(self, msg, replies) -> None:
        dispatch_nav.nav_message(self.sim, msg, self._now)
