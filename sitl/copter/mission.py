"""The MAVLink mission protocol of the emulated ArduCopter: missions (0), fences (1) and rally points (2).

As ArduPilot's ``libraries/GCS_MAVLink/MissionItemProtocol*.cpp`` and ``AP_Mission.cpp`` do:

* upload: MISSION_COUNT -> one request per item (MISSION_REQUEST_INT; MISSION_REQUEST once the
  client has sent a legacy MISSION_ITEM) -> MISSION_ITEM_INT / MISSION_ITEM -> MISSION_ACK when the
  last item is in ("Flight plan received").  Another client's upload during a transfer is DENIED; a
  new MISSION_COUNT from the same client restarts it.  An item with the wrong ``seq`` is answered
  INVALID_SEQUENCE (the transfer goes on); an invalid item ends the transfer with the error
  ArduPilot gives (UNSUPPORTED command, UNSUPPORTED_FRAME, INVALID_PARAMn, ERROR for a bad
  DO_JUMP).  The pending request is repeated after 1 s without an item; after 8 s the upload is
  cancelled (MISSION_ACK OPERATION_CANCELLED, "Mission upload timeout").  Times are the server's
  clock (wall clock, also in lockstep: a stalled client stalls simulated time).
* MISSION_WRITE_PARTIAL_LIST: the same for items ``start..end`` of a stored list.
* download: MISSION_REQUEST_LIST -> MISSION_COUNT; MISSION_REQUEST_INT -> MISSION_ITEM_INT,
  legacy MISSION_REQUEST -> MISSION_ITEM (lat/lon in degrees).  Item 0 of the mission is home.
  A ``seq`` beyond the list is answered MISSION_COUNT + MISSION_ACK INVALID_SEQUENCE.  Frames come
  back as ArduPilot stores them: GLOBAL (absolute), GLOBAL_RELATIVE_ALT or GLOBAL_TERRAIN_ALT
  for items with a location, 0 otherwise.
* MISSION_CLEAR_ALL -> MISSION_ACK; MISSION_SET_CURRENT -> MISSION_CURRENT with that ``seq``.

Like ArduPilot (which writes a mission item by item), a mission upload that ends early leaves the
mission truncated to the announced count with the items received so far; fences and rally points
are replaced only when their upload completes.  Mission type 255 (ALL) is UNSUPPORTED except for
MISSION_CLEAR_ALL (there too, as in ArduPilot).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field, replace

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sitl.copter.mission_store import MISSION_TYPES, MissionItem
from sitl.copter.simulation import Simulation

__all__ = ["MissionProtocol", "MISSION_MESSAGES", "MISSION_COMMANDS", "LOCATION_COMMANDS", "MAX_ITEMS"]

M = mavlink
MISSION_MESSAGES = frozenset({
    "MISSION_COUNT", "MISSION_ITEM", "MISSION_ITEM_INT", "MISSION_REQUEST", "MISSION_REQUEST_INT",
    "MISSION_REQUEST_LIST", "MISSION_CLEAR_ALL", "MISSION_SET_CURRENT", "MISSION_WRITE_PARTIAL_LIST",
    "MISSION_ACK"})
#: Commands AP_Mission::mavlink_int_to_mission_cmd accepts (ArduCopter build).
MISSION_COMMANDS = frozenset({
    16, 17, 18, 19, 20, 21, 22, 30, 31, 36, 82, 83, 84, 85, 92, 93, 94, 112, 114, 115, 177, 178, 179, 181, 182,
    183, 184, 188, 189, 191, 193, 194, 195, 197, 201, 202, 203, 205, 206, 207, 208, 210, 211, 212, 213, 215, 216,
    217, 218, 222, 223, 531, 532, 534, 600, 601, 1000, 2000, 2001, 2500, 2501, 3000, 42600, 42702, 42703})
#: AP_Mission::stored_in_location: x/y are latitude/longitude, ``frame`` applies.
LOCATION_COMMANDS = frozenset({
    16, 17, 18, 19, 21, 22, 30, 31, 82, 92, 179, 188, 189, 191, 195, 201, 84, 85, 94,
    5001, 5002, 5003, 5004, 5000, 5100, 36})
FENCE_COMMANDS = frozenset({5000, 5001, 5002, 5003, 5004})
RALLY_COMMANDS = frozenset({5100})
#: Storage limits of ArduCopter SITL (mission items incl. home, fence items, rally points).
MAX_ITEMS = {0: 724, 1: 84, 2: 20}
_GLOBAL_FRAMES = {M.MAV_FRAME_GLOBAL: 0, M.MAV_FRAME_GLOBAL_INT: 0, M.MAV_FRAME_MISSION: 0,
                  M.MAV_FRAME_GLOBAL_RELATIVE_ALT: 3, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: 3,
                  M.MAV_FRAME_GLOBAL_TERRAIN_ALT: 10, M.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT: 10}
# Param 4 (index 3) may be NaN for these (AP_Mission::sanity_check_params); ARC_WAYPOINT 2-4, VTOL_LAND 3-4.
_NAN_OK = {16: {3}, 17: {3}, 21: {3}, 22: {3}, 84: {3}, 36: {1, 2, 3}, 85: {2, 3}}
_INVALID_PARAM = (M.MAV_MISSION_INVALID_PARAM1, M.MAV_MISSION_INVALID_PARAM2, M.MAV_MISSION_INVALID_PARAM3,
                  M.MAV_MISSION_INVALID_PARAM4)
_LOCATION_ALT_MAX_M = 83000.0
_NAMES = {0: "Mission", 1: "Fence", 2: "Rally"}
UPLOAD_TIMEOUT_NS = 8_000_000_000
REREQUEST_NS = 1_000_000_000

Reply = Callable[[mavlink.MAVLink_message], None]


@dataclass
class _Upload:
    """One upload in progress (ArduPilot's ``receiving`` state)."""

    mission_type: int
    link: Hashable
    sysid: int
    compid: int
    request_i: int
    request_last: int
    count: int  # the list's length once complete
    last_rx_ns: int
    last_request_ns: int
    legacy: bool = False
    got: dict[int, MissionItem] = field(default_factory=dict)


def _command_check(it: MissionItem) -> int | None:
    """A mission item's command (None: accepted so far)."""
    if it.command in (0, 1):
        return M.MAV_MISSION_INVALID
    if it.command not in MISSION_COMMANDS:
        return M.MAV_MISSION_UNSUPPORTED
    if it.command == M.MAV_CMD_NAV_WAYPOINT and not 0 <= it.param1 <= 65535:
        return M.MAV_MISSION_INVALID_PARAM1
    return None


def _fence_check(it: MissionItem) -> int | None:
    """A fence item (MissionItemProtocol_Fence: frame first, no location check)."""
    if it.frame not in _GLOBAL_FRAMES or it.frame == M.MAV_FRAME_MISSION:
        return M.MAV_MISSION_UNSUPPORTED_FRAME
    if it.command not in FENCE_COMMANDS:
        return M.MAV_MISSION_UNSUPPORTED
    if it.command in (5001, 5002) and it.param1 > 255:
        return M.MAV_MISSION_INVALID_PARAM1
    return M.MAV_MISSION_ACCEPTED


def _rally_check(it: MissionItem) -> int | None:
    return None if it.command in RALLY_COMMANDS else M.MAV_MISSION_UNSUPPORTED


def _validate(mission_type: int, it: MissionItem) -> int:
    """MAV_MISSION_RESULT of storing ``it`` (ACCEPTED or ArduPilot's error), DO_JUMP aside."""
    for i, p in enumerate((it.param1, it.param2, it.param3, it.param4)):
        if math.isinf(p) or (math.isnan(p) and i not in _NAN_OK.get(it.command, ())):
            return _INVALID_PARAM[i]
    result = (_command_check, _fence_check, _rally_check)[mission_type](it)
    if result is not None:
        return result
    if it.command in LOCATION_COMMANDS:
        if abs(it.x) > 900_000_000:
            return M.MAV_MISSION_INVALID_PARAM5_X
        if abs(it.y) > 1_800_000_000:
            return M.MAV_MISSION_INVALID_PARAM6_Y
        if math.isnan(it.z) or abs(it.z) >= _LOCATION_ALT_MAX_M:
            return M.MAV_MISSION_INVALID_PARAM7
        if it.frame not in _GLOBAL_FRAMES or (mission_type == 2 and it.frame == M.MAV_FRAME_MISSION):
            return M.MAV_MISSION_UNSUPPORTED_FRAME
    return M.MAV_MISSION_ACCEPTED


def _item_from(msg, legacy: bool) -> MissionItem | int:
    """The MissionItem a MISSION_ITEM(_INT) carries, or a MAV_MISSION_RESULT error (legacy lat/lon)."""
    x, y = msg.x, msg.y
    if legacy:
        if int(msg.command) in LOCATION_COMMANDS:
            if not (math.isfinite(x) and abs(x) <= 90.0):
                return M.MAV_MISSION_INVALID_PARAM5_X
            if not (math.isfinite(y) and abs(y) <= 180.0):
                return M.MAV_MISSION_INVALID_PARAM6_Y
            x, y = round(x * 1e7), round(y * 1e7)
        else:
            x = int(x) if math.isfinite(x) else 0
            y = int(y) if math.isfinite(y) else 0
    return MissionItem(int(msg.seq), int(msg.frame), int(msg.command), int(msg.current), int(msg.autocontinue),
                       float(msg.param1), float(msg.param2), float(msg.param3), float(msg.param4), int(x), int(y),
                       float(msg.z), int(getattr(msg, "mission_type", 0)))


class MissionProtocol:
    """Mission, fence and rally transfers of one vehicle (the lists live in ``sim.missions``).

    Parameters
    ----------
    sim : Simulation
    system_id, component_id : callable / int
        This vehicle's ids (``system_id`` is called: SYSID_THISMAV can change).
    """

    def __init__(self, sim: Simulation, system_id: Callable[[], int], component_id: int = 1) -> None:
        self.sim = sim
        self._sysid = system_id
        self._compid = component_id
        self._uploads: dict[int, _Upload] = {}
        self._warned: set[str] = set()
        #: Messages not answering a message just handled (re-requests, cancellations): (link, message).
        self.outbox: list[tuple[Hashable, mavlink.MAVLink_message]] = []
        self._handlers = {
            "MISSION_COUNT": self._count, "MISSION_ITEM": self._item, "MISSION_ITEM_INT": self._item,
            "MISSION_REQUEST": self._request, "MISSION_REQUEST_INT": self._request,
            "MISSION_REQUEST_LIST": self._request_list, "MISSION_CLEAR_ALL": self._clear_all,
            "MISSION_SET_CURRENT": self._set_current, "MISSION_WRITE_PARTIAL_LIST": self._partial,
            "MISSION_ACK": lambda msg, link, now, out: None,
        }

    # ------------------------------------------------------------------ entry
    def handle(self, msg, link: Hashable, now_ns: int, out: list) -> None:
        """Act on mission message ``msg`` from ``link`` at ``now_ns`` (server clock); replies go to ``out``."""
        self._handlers[msg.get_type()](msg, link, now_ns, out)

    def receiving(self, mission_type: int) -> bool:
        """Whether an upload of ``mission_type`` is in progress."""
        return mission_type in self._uploads

    def poll(self, now_ns: int) -> None:
        """Repeat overdue requests and cancel stalled uploads (into :attr:`outbox`)."""
        for t, up in list(self._uploads.items()):
            if now_ns - up.last_rx_ns > UPLOAD_TIMEOUT_NS:
                self._end(up)
                self.outbox.append((up.link, M.MAVLink_mission_ack_message(
                    up.sysid, up.compid, M.MAV_MISSION_OPERATION_CANCELLED, t)))
                self.sim.autopilot.events.append((M.MAV_SEVERITY_WARNING, f"{_NAMES[t]} upload timeout"))
            elif now_ns - up.last_request_ns > REREQUEST_NS:
                up.last_request_ns = now_ns
                self.outbox.append((up.link, self._request_msg(up)))

    # ------------------------------------------------------------------ helpers
    def _ack(self, msg, result: int, mission_type: int, out: list) -> None:
        out.append(M.MAVLink_mission_ack_message(msg.get_srcSystem(), msg.get_srcComponent(), result,
                                                 mission_type))

    def _type(self, msg, out: list) -> int | None:
        t = int(getattr(msg, "mission_type", 0))
        if t not in MISSION_TYPES:
            self._ack(msg, M.MAV_MISSION_UNSUPPORTED, t, out)
            return None
        return t

    def _count_of(self, t: int) -> int:
        n = self.sim.missions.count(t)
        return max(n, 1) if t == 0 else n  # the mission always holds home

    def _request_msg(self, up: _Upload) -> mavlink.MAVLink_message:
        if up.legacy:
            return M.MAVLink_mission_request_message(up.sysid, up.compid, up.request_i, up.mission_type)
        return M.MAVLink_mission_request_int_message(up.sysid, up.compid, up.request_i, up.mission_type)

    def _cancel(self, msg, t: int, out: list) -> bool:
        """ArduPilot's cancel_upload: False (DENIED sent) if another client is uploading ``t``."""
        up = self._uploads.get(t)
        if up is None:
            return True
        if (msg.get_srcSystem(), msg.get_srcComponent()) != (up.sysid, up.compid):
            self._ack(msg, M.MAV_MISSION_DENIED, t, out)
            return False
        self._end(up, commit=False)
        return True

    def _begin(self, msg, link, t: int, first: int, last: int, count: int, now_ns: int, out: list) -> None:
        up = _Upload(t, link, msg.get_srcSystem(), msg.get_srcComponent(), first, last, count, now_ns, now_ns)
        self._uploads[t] = up
        out.append(self._request_msg(up))

    def _end(self, up: _Upload, commit: bool = True) -> None:
        """Finish ``up``: the mission keeps the items received (as ArduPilot writes them); fence/rally only whole."""
        self._uploads.pop(up.mission_type, None)
        if up.mission_type == 0 or commit:
            self._store(up)

    def _store(self, up: _Upload) -> None:
        store = self.sim.missions
        old = list(store.items[up.mission_type])
        keep = old[:up.count] if up.mission_type == 0 else (old if up.count == len(old) else [])
        new = keep + [None] * (up.count - len(keep))
        for seq, it in up.got.items():
            if seq < len(new):
                new[seq] = it
        store.replace(up.mission_type, [it for it in new if it is not None])

    # ------------------------------------------------------------------ upload
    def _count(self, msg, link, now_ns: int, out: list) -> None:
        t = self._type(msg, out)
        if t is None or not self._cancel(msg, t, out):
            return
        n = int(msg.count)
        if n > MAX_ITEMS[t]:
            self._ack(msg, M.MAV_MISSION_NO_SPACE, t, out)
            self.sim.autopilot.events.append((M.MAV_SEVERITY_WARNING, f"Only {MAX_ITEMS[t]} items are supported"))
            return
        if t == 0:  # AP_Mission::truncate
            store = self.sim.missions
            if store.count(0) > n:
                store.replace(0, list(store.items[0][:n]))
        if n == 0:
            self.sim.missions.clear(t)
            self._complete(msg, t, out)
            return
        self._begin(msg, link, t, 0, n - 1, n, now_ns, out)

    def _idle_type(self, msg, out: list) -> int | None:
        """The message's mission type, None (answered) if it is bad or being uploaded (DENIED)."""
        t = self._type(msg, out)
        if t is not None and t in self._uploads:
            self._ack(msg, M.MAV_MISSION_DENIED, t, out)
            return None
        return t

    def _partial(self, msg, link, now_ns: int, out: list) -> None:
        t = self._idle_type(msg, out)
        if t is None:
            return
        n = self._count_of(t)
        start, end = int(msg.start_index), int(msg.end_index)
        if start > n or end > n or end < start:
            self.sim.autopilot.events.append((M.MAV_SEVERITY_WARNING, "Flight plan update rejected"))
            self._ack(msg, M.MAV_MISSION_ERROR, t, out)
            return
        self._begin(msg, link, t, start, end, max(n, end + 1), now_ns, out)

    def _complete(self, msg, t: int, out: list) -> None:
        if t == 0:
            self.sim.autopilot.events.append((M.MAV_SEVERITY_INFO, "Flight plan received"))
        self._ack(msg, M.MAV_MISSION_ACCEPTED, t, out)

    def _item(self, msg, link, now_ns: int, out: list) -> None:
        legacy = msg.get_type() == "MISSION_ITEM"
        t = int(getattr(msg, "mission_type", 0))
        it = _item_from(msg, legacy)
        if isinstance(it, int):
            self._ack(msg, it, t, out)
            return
        if t not in MISSION_TYPES:
            self._ack(msg, M.MAV_MISSION_UNSUPPORTED, t, out)
            return
        if t == 0 and it.current in (2, 3):  # guided / change-alt request: not emulated here
            self._ack(msg, M.MAV_MISSION_ERROR, t, out)
            return
        if legacy and "item" not in self._warned:
            self._warned.add("item")
            self.sim.autopilot.events.append((M.MAV_SEVERITY_WARNING,
                                              "got MISSION_ITEM; GCS should send MISSION_ITEM_INT"))
        up = self._uploads.get(t)
        if up is None:
            self._ack(msg, M.MAV_MISSION_ERROR, t, out)
            return
        up.legacy = up.legacy or legacy
        if it.seq != up.request_i:
            self._ack(msg, M.MAV_MISSION_INVALID_SEQUENCE, t, out)
            return
        if (msg.get_srcSystem(), msg.get_srcComponent()) != (up.sysid, up.compid):
            self._ack(msg, M.MAV_MISSION_DENIED, t, out)
            return
        result = _validate(t, it)
        if result == M.MAV_MISSION_ACCEPTED and t == 0 and it.command == M.MAV_CMD_DO_JUMP:
            target = int(it.param1)
            if (target >= self.sim.missions.count(0) and target > up.request_last) or target == 0:
                result = M.MAV_MISSION_ERROR
        if result != M.MAV_MISSION_ACCEPTED:
            self._ack(msg, result, t, out)
            self._end(up, commit=False)
            return
        up.got[it.seq] = it
        up.last_rx_ns = now_ns
        up.request_i += 1
        if up.request_i > up.request_last:
            self._end(up)
            self._complete(msg, t, out)
            return
        up.last_request_ns = now_ns
        out.append(self._request_msg(up))

    # ------------------------------------------------------------------ download
    def _request_list(self, msg, link, now_ns: int, out: list) -> None:
        t = self._idle_type(msg, out)
        if t is None:
            return
        out.append(M.MAVLink_mission_count_message(msg.get_srcSystem(), msg.get_srcComponent(), self._count_of(t), t))

    def stored_item(self, t: int, seq: int) -> MissionItem | None:
        """Item ``seq`` of list ``t`` as a download returns it (mission item 0: home), None if beyond the list."""
        if t == 0 and seq == 0:
            h = self.sim.home
            return MissionItem(0, M.MAV_FRAME_GLOBAL, M.MAV_CMD_NAV_WAYPOINT, x=round(h.lat_deg * 1e7),
                               y=round(h.lon_deg * 1e7), z=float(h.alt_m))
        it = self.sim.missions.get(t, seq)
        if it is None:
            return None
        if t == 1:
            return replace(it, frame=0, z=0.0, current=0, autocontinue=0)
        frame = _GLOBAL_FRAMES.get(it.frame, 0) if it.command in LOCATION_COMMANDS else 0
        current = 1 if t == 0 and seq == self.sim.missions.current_seq else 0
        return replace(it, frame=frame, current=current, autocontinue=1 if t == 0 else it.autocontinue)

    def _request(self, msg, link, now_ns: int, out: list) -> None:
        legacy = msg.get_type() == "MISSION_REQUEST"
        t = self._type(msg, out)
        if t is None:
            return
        if not legacy and t in self._uploads:
            self._ack(msg, M.MAV_MISSION_DENIED, t, out)
            return
        it = self.stored_item(t, int(msg.seq))
        if it is None:
            if not legacy:
                out.append(M.MAVLink_mission_count_message(msg.get_srcSystem(), msg.get_srcComponent(),
                                                           self._count_of(t), t))
            self._ack(msg, M.MAV_MISSION_INVALID_SEQUENCE, t, out)
            return
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        args = (it.seq, it.frame, it.command, it.current, it.autocontinue, it.param1, it.param2, it.param3,
                it.param4)
        if legacy:
            loc = it.command in LOCATION_COMMANDS
            x, y = (it.x * 1e-7, it.y * 1e-7) if loc else (float(it.x), float(it.y))
            if "request" not in self._warned:
                self._warned.add("request")
                self.sim.autopilot.events.append((M.MAV_SEVERITY_WARNING,
                                                  "got MISSION_REQUEST; use MISSION_REQUEST_INT!"))
            out.append(M.MAVLink_mission_item_message(*src, *args, x, y, it.z, t))
        else:
            out.append(M.MAVLink_mission_item_int_message(*src, *args, it.x, it.y, it.z, t))

    # ------------------------------------------------------------------ others
    def _clear_all(self, msg, link, now_ns: int, out: list) -> None:
        t = int(msg.mission_type)
        if t not in (*MISSION_TYPES, M.MAV_MISSION_TYPE_ALL):
            self._ack(msg, M.MAV_MISSION_UNSUPPORTED, t, out)
            return
        for tt in (MISSION_TYPES if t == M.MAV_MISSION_TYPE_ALL else (t,)):
            if not self._cancel(msg, tt, out):
                return
        self.sim.missions.clear(t)
        self._ack(msg, M.MAV_MISSION_ACCEPTED, t, out)

    def _set_current(self, msg, link, now_ns: int, out: list) -> None:
        if self.sim.missions.set_current(int(msg.seq)):
            out.append(mission_current(self.sim, int(msg.seq)))


def mission_current(sim: Simulation, seq: int | None = None) -> mavlink.MAVLink_message:
    """MISSION_CURRENT: ``seq`` (default the current item), items without home, state, AUTO flag."""
    store = sim.missions
    n = store.count(0)
    total = max(n - 1, 0)
    auto = int(sim.autopilot.mode) == 3  # AUTO
    if total == 0:
        state = M.MISSION_STATE_NO_MISSION
    elif auto and sim.autopilot.armed:
        state = M.MISSION_STATE_ACTIVE
    else:
        state = M.MISSION_STATE_NOT_STARTED
    return M.MAVLink_mission_current_message(store.current_seq if seq is None else seq, total, state, int(auto))
