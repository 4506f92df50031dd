"""What the emulated autopilot does with each incoming MAVLink message.

:meth:`Dispatcher.handle` takes one decoded message and returns the replies
to send and whether the message ticks the lockstep clock.  Handled:

=============================  ==============================================================
SET_ATTITUDE_TARGET            guided target (:meth:`Autopilot.set_attitude_target`); lockstep tick
SET_ACTUATOR_CONTROL_TARGET    group 0: normalised torques + thrust; lockstep tick
COMMAND_LONG / COMMAND_INT     DO_SET_MODE (176), COMPONENT_ARM_DISARM (400), NAV_LAND (21),
                               SET_MESSAGE_INTERVAL (511), GET_MESSAGE_INTERVAL (510),
                               REQUEST_MESSAGE (512), REQUEST_AUTOPILOT_CAPABILITIES (520);
                               COMMAND_ACK always, MAV_RESULT_UNSUPPORTED for anything else
SET_MODE                       custom mode; COMMAND_ACK with command = 11 (as ArduPilot)
REQUEST_DATA_STREAM            stream groups (``SR0_*`` parameters)
PARAM_REQUEST_READ/LIST, _SET  PARAM_VALUE; a refused PARAM_SET echoes the unchanged value and
                               says why in a STATUSTEXT ("Param write denied ...")
TIMESYNC                       request (tc1 = 0) answered with tc1 = simulated time [ns]
=============================  ==============================================================

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
unchanged, "Param write denied") and count it in ``LinkCounters.non_finite``.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sitl.copter.autopilot import FORCE_MAGIC, SEVERITY_WARNING
from sitl.copter.params import STREAM_PARAMS
from sitl.copter.simulation import Simulation
from sitl.copter.streams import StreamScheduler
from sitl.copter.telemetry import TelemetryCounters, autopilot_version, build
from sitl.net.endpoint import LinkCounters, MavlinkEndpoint

__all__ = ["Dispatcher", "STEPPING_MESSAGES"]

M = mavlink
STEPPING_MESSAGES = frozenset({"SET_ATTITUDE_TARGET", "SET_ACTUATOR_CONTROL_TARGET"})
# ATTITUDE_TARGET_TYPEMASK bits: body roll/pitch/yaw rate ignore 1/2/4, throttle 64, attitude 128
_THROTTLE_IGNORE = 64
_ATTITUDE_IGNORE = 128
# How many leading parameters each handled command uses (all must be finite).
_COMMAND_PARAMS = {M.MAV_CMD_DO_SET_MODE: 2, M.MAV_CMD_COMPONENT_ARM_DISARM: 2, M.MAV_CMD_SET_MESSAGE_INTERVAL: 2,
                   M.MAV_CMD_GET_MESSAGE_INTERVAL: 1, M.MAV_CMD_REQUEST_MESSAGE: 1}
_ACCEPTED, _DENIED, _FAILED, _UNSUPPORTED = (M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_DENIED, M.MAV_RESULT_FAILED,
                                            M.MAV_RESULT_UNSUPPORTED)


def _text(value) -> str:
    if isinstance(value, (bytes, bytearray)):
        return bytes(value).split(b"\x00", 1)[0].decode("ascii", errors="replace")
    return str(value)


class Dispatcher:
    """Message handlers of one vehicle.

    Parameters
    ----------
    sim : Simulation
    streams : StreamScheduler
        Rates acted on when :meth:`handle` is given none (the server gives each message its link's).
    endpoint : MavlinkEndpoint
    telemetry_counters : TelemetryCounters
        Updated from the link counters for SYS_STATUS.
    """

    def __init__(self, sim: Simulation, streams: StreamScheduler, endpoint: MavlinkEndpoint,
                 telemetry_counters: TelemetryCounters) -> None:
        self.sim = sim
        self.streams = streams
        self.endpoint = endpoint
        self.tcounters = telemetry_counters
        self.counters: LinkCounters = endpoint.counters
        self._link: StreamScheduler | None = None
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
        }
        sim.params.add_listener(self._param_changed)

    # ------------------------------------------------------------------ entry
    def handle(self, msg: mavlink.MAVLink_message,
               streams: StreamScheduler | None = None) -> tuple[list[mavlink.MAVLink_message], bool]:
        """Act on ``msg`` received on the link whose stream rates are ``streams`` (default: the constructor's).

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
        try:
            handler(msg, replies)
        except Exception:  # noqa: BLE001 - a hostile field value must never stop the vehicle
            self.counters.handler_errors += 1
        finally:
            self._link = None
        return replies, kind in STEPPING_MESSAGES

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

    # ------------------------------------------------------------------ commands
    def _ack(self, msg, command: int, result: int, replies) -> None:
        replies.append(M.MAVLink_command_ack_message(command, result, 0, 0, msg.get_srcSystem(),
                                                     msg.get_srcComponent()))

    def _command_long(self, msg, replies) -> None:
        p = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7)
        self._command(msg, int(msg.command), p, replies)

    def _command_int(self, msg, replies) -> None:
        p = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y), msg.z)
        self._command(msg, int(msg.command), p, replies)

    def _command(self, msg, cmd: int, p, replies) -> None:
        ap = self.sim.autopilot
        now = self._now
        streams = self._link if self._link is not None else self.streams
        needed = _COMMAND_PARAMS.get(cmd, 0)
        if needed and self._non_finite(*p[:needed]):
            self._ack(msg, cmd, _DENIED, replies)
            return
        if cmd == M.MAV_CMD_DO_SET_MODE:
            if not int(p[0]) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                result = _FAILED
            else:
                result = _ACCEPTED if ap.set_mode(int(p[1]), now)[0] else _FAILED
        elif cmd == M.MAV_CMD_NAV_LAND:
            result = _ACCEPTED if ap.set_mode(9, now)[0] else _FAILED
        elif cmd == M.MAV_CMD_COMPONENT_ARM_DISARM:
            force = int(p[1]) == FORCE_MAGIC
            if p[0] == 1.0:
                ok = ap.arm(now, force)[0]
            elif p[0] == 0.0:
                ok = ap.disarm(now, force)[0]
            else:
                ok = False
            result = _ACCEPTED if ok else _FAILED
        elif cmd == M.MAV_CMD_SET_MESSAGE_INTERVAL:
            result = _ACCEPTED if streams.set_interval_us(int(p[0]), p[1], now) else _FAILED
        elif cmd == M.MAV_CMD_GET_MESSAGE_INTERVAL:
            # The field is int32: an interval set beyond it (a hostile request) reads back clamped.
            interval = max(-1, min(int(streams.interval_us(int(p[0]))), 2**31 - 1))
            replies.append(M.MAVLink_message_interval_message(int(p[0]) & 0xFFFF, interval))
            result = _ACCEPTED
        elif cmd == M.MAV_CMD_REQUEST_MESSAGE:
            result = _FAILED
            mid = int(p[0])
            if mid == M.MAVLINK_MSG_ID_SYS_STATUS:
                self.sync_counters()  # as the streamed one: the link counters of now
            m = autopilot_version(self.sim) if mid == M.MAVLINK_MSG_ID_AUTOPILOT_VERSION else build(
                mid, self.sim, self.tcounters)
            if m is not None:
                self._ack(msg, cmd, _ACCEPTED, replies)
                replies.append(m)
                return
        elif cmd == M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            self._ack(msg, cmd, _ACCEPTED, replies)
            replies.append(autopilot_version(self.sim))
            return
        else:
            result = _UNSUPPORTED
        self._ack(msg, cmd, result, replies)

    def _set_mode(self, msg, replies) -> None:
        ok = False
        if int(msg.base_mode) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            ok = self.sim.autopilot.set_mode(int(msg.custom_mode), self._now)[0]
        replies.append(M.MAVLink_command_ack_message(M.MAVLINK_MSG_ID_SET_MODE, _ACCEPTED if ok else _FAILED, 0, 0,
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
        if name == "SYSID_THISMAV":
            self.endpoint.system_id = int(value)
        if self._link is None:  # not changed by a link (start-up overrides): no link's rates change
            return
        for sid, pname in STREAM_PARAMS.items():
            if pname == name:
                self._link.set_group_rate(sid, value, self._now)

    def _param_value(self, name: str) -> mavlink.MAVLink_message:
        ps = self.sim.params
        return M.MAVLink_param_value_message(name.encode("ascii"), ps[name], ps.spec(name).ptype, len(ps),
                                             ps.index(name))

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

    def _param_set(self, msg, replies) -> None:
        ps = self.sim.params
        name = _text(msg.param_id)
        if name not in ps:
            self.counters.unhandled += 1
            self.sim.autopilot.events.append((SEVERITY_WARNING, f"Param write denied ({name[:16]}): unknown"))
            return
        if self._non_finite(float(msg.param_value)):
            ok, reason = False, f"not finite: {float(msg.param_value)!r}"
        else:
            ok, reason = ps.set(name, msg.param_value)
        if not ok:
            self.sim.autopilot.events.append((SEVERITY_WARNING, f"Param write denied ({name}): {reason}"[:50]))
        replies.append(self._param_value(name))

    # ------------------------------------------------------------------ misc
    def _timesync(self, msg, replies) -> None:
        if int(msg.tc1) == 0:
            replies.append(M.MAVLink_timesync_message(self._now, int(msg.ts1)))

