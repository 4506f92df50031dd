"""ArduCopter's navigation modes on the emulated inner loop: ALT_HOLD, LOITER, POSHOLD, BRAKE, RTL,
AUTO, and GUIDED's position/velocity targets and NAV_TAKEOFF.

Simple but physical, not ArduPilot's jerk-limited path shaping: a position target becomes a velocity
demand through ArduPilot's square-root controller (linear near the target, ``sqrt(2 a d)`` far from
it, so the vehicle decelerates within the acceleration limit), limited to the mode's speed; the
velocity error becomes an acceleration demand (P + I, at most ``g tan(ATC_ANGLE_MAX)``) flown as a
lean at the measured heading; the altitude error becomes a climb rate (at most ``WP_SPD_UP`` /
``WP_SPD_DN``) that the autopilot's climb-rate loop flies.  The heading target turns towards the
next point (AUTO, RTL, GUIDED positions more than 2 m away) at :data:`YAW_SLEW_RAD_S`.

Modes (no RC here: the sticks are centred)

=========  ==============================================================================================
ALT_HOLD   level; holds the altitude of entry (drifts with the wind)
LOITER     holds the stopping point of entry (``LOIT_SPEED_MS``, ``LOIT_ACC_MAX_M``); POSHOLD alike
BRAKE      as LOITER, with ArduCopter's hard deceleration (:data:`BRAKE_ACC_M_S2`)
RTL        climb to ``RTL_ALT_M`` above home (at least ``RTL_CLIMB_MIN_M`` up), return at ``RTL_SPEED_MS``
           (0: ``WP_SPD``), loiter ``RTL_LOIT_TIME`` ms over home, then hold ``RTL_ALT_FINAL_M`` or, at 0,
           land and disarm; refused before home is set
GUIDED     without an attitude target: holds position; NAV_TAKEOFF climbs to its altitude above home;
           SET_POSITION_TARGET_* positions and velocities (a velocity target older than
           ``GUID_TIMEOUT`` stops the vehicle, as ArduCopter)
AUTO       the uploaded mission, from its current item (below); entered landed, the next navigation item
           must be a TAKEOFF ("Missing takeoff command", as ArduCopter)
=========  ==============================================================================================

Landed, a mode takes off only when it demands a climb (a take-off, a target above).

AUTO's items (as uploaded; frames GLOBAL = AMSL, GLOBAL_RELATIVE_ALT = above home, GLOBAL_TERRAIN_ALT
flown as relative (the world is flat), their ``_INT`` forms, LOCAL_NED in metres; latitude = longitude
= 0: where the vehicle is): NAV_WAYPOINT (reached within ``WP_RADIUS_M`` horizontally and 1 m
vertically, then held ``param1`` s), NAV_TAKEOFF, NAV_LOITER_UNLIM, NAV_LOITER_TIME (``param1`` s),
NAV_LAND (fly there, land, disarm), NAV_RETURN_TO_LAUNCH (RTL's sequence inside AUTO), DO_CHANGE_SPEED
(``param2`` m/s); other DO_/CONDITION_ items are passed over.  The store's ``current_seq`` follows the
mission (MISSION_CURRENT) and every navigation item reached is appended to its ``reached`` list
(MISSION_ITEM_REACHED).  After the last item the vehicle holds where it is, as ArduCopter's AUTO.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

from quadrotor.frames import euler_to_quaternion
from quadrotor.geodesy import local_from_geodetic
from sitl.copter.control import land_speed
from sitl.copter.mission_store import Home, MissionItem, MissionStore
from sitl.copter.modes import Mode
from sitl.copter.params import ParamStore
from sitl.copter.sensors import NavReading

__all__ = ["NavDemand", "Navigator", "NAV_MODES", "sqrt_controller", "BRAKE_ACC_M_S2", "YAW_SLEW_RAD_S"]

#: Modes the navigator flies (GUIDED too, while it has no attitude target).
NAV_MODES = (Mode.ALT_HOLD, Mode.AUTO, Mode.LOITER, Mode.RTL, Mode.POSHOLD, Mode.BRAKE)
BRAKE_ACC_M_S2 = 7.5
YAW_SLEW_RAD_S = math.radians(60.0)
POS_P_1_S = 1.0  # PSC_NE_POS_P / PSC_D_POS_P
VEL_P_1_S = 2.0  # PSC_NE_VEL_P
VEL_I_1_S2 = 1.0  # PSC_NE_VEL_I
VEL_IMAX_M_S2 = 1.0
_ALT_REACHED_M = 0.3
#: Landed, a navigation mode takes off for a target at least this much higher.
TAKEOFF_MIN_M = 0.5
_FACE_DISTANCE_M = 2.0

# MAV_CMD of mission items
_WAYPOINT, _LOITER_UNLIM, _LOITER_TIME, _RTL, _LAND, _TAKEOFF, _SPLINE = 16, 17, 19, 20, 21, 22, 82
_CHANGE_SPEED = 178
_NAV_COMMANDS = (_WAYPOINT, _LOITER_UNLIM, _LOITER_TIME, _RTL, _LAND, _TAKEOFF, _SPLINE)
# AP_Mission's names of the commands, in ArduCopter's "Mission: <seq> <name>" text
_NAMES = {_WAYPOINT: "WP", _LOITER_UNLIM: "LoitUnlim", _LOITER_TIME: "LoitTime", _RTL: "RTL", _LAND: "Land",
          _TAKEOFF: "Takeoff", _SPLINE: "SplineWP"}


class NavDemand(NamedTuple):
    """What the navigator asks of the inner loop: an attitude (body to NED), a climb rate [m/s, up],
    and ``land`` (descend at LAND's speed here and disarm on touchdown)."""

    q: tuple[float, float, float, float]
    climb_m_s: float
    land: bool = False


def sqrt_controller(error: float, p: float, accel: float) -> float:
    """ArduPilot's square-root controller: ``p * error`` near zero, ``sqrt(2 accel |error|)`` beyond
    ``accel / p**2`` (a deceleration within ``accel``), continuous in between."""
    if accel <= 0.0 or p <= 0.0:
        return error * p
    linear = accel / (p * p)
    if abs(error) <= linear:
        return error * p
    return math.copysign(math.sqrt(2.0 * accel * (abs(error) - 0.5 * linear)), error)


class Navigator:
    """Position control and the navigation modes of one vehicle (composed into the autopilot).

    Parameters
    ----------
    params : ParamStore
    gravity_m_s2 : float
    missions : MissionStore
        The uploaded mission (AUTO) and its progress.
    origin : (lat_deg, lon_deg, alt_m)
        The local NED origin (the EKF origin: the boot position).
    home : Home
        Home (RTL's destination, relative altitudes); moves with DO_SET_HOME.
    say : callable
        ``say(severity, text)``: a STATUSTEXT.
    """

    def __init__(self, params: ParamStore, gravity_m_s2: float, missions: MissionStore,
                 origin: tuple[float, float, float], home: Home, say: Callable[[int, str], None]) -> None:
        self.params = params
        self.g = gravity_m_s2
        self.missions = missions
        self.origin = origin
        self.home = home
        self._say = say
        self.mode: Mode | None = None
        self.target = (0.0, 0.0, 0.0)  # position target, NED [m]
        self.velocity: tuple[float, float, float] | None = None  # GUIDED velocity target, NED [m/s]
        self._velocity_ns = 0
        self.yaw = 0.0
        self._yaw_goal: float | None = None
        self._speed_override: float | None = None
        self._int = [0.0, 0.0]
        self.phase = ""  # RTL: climb, return, loiter, final, land; AUTO: the item's command or "done"
        self._since_ns = 0
        self._item: MissionItem | None = None
        self._hold_level = False  # ALT_HOLD: no horizontal control
        self.last: NavDemand | None = None
        self._home_key: tuple[float, float, float] | None = None
        self._home_ned = (0.0, 0.0, 0.0)

    # ------------------------------------------------------------------ geometry
    def home_ned(self) -> tuple[float, float, float]:
        """Home as NED [m] from the origin (recomputed only when home moves: RTL reads it every tick)."""
        h, (lat0, lon0, alt0) = self.home, self.origin
        key = (h.lat_deg, h.lon_deg, h.alt_m)
        if key != self._home_key:
            n, e = local_from_geodetic(lat0, lon0, h.lat_deg, h.lon_deg)
            self._home_key, self._home_ned = key, (n, e, alt0 - h.alt_m)
        return self._home_ned

    def item_ned(self, it: MissionItem, nav: NavReading) -> tuple[float, float, float] | None:
        """A mission item's position, NED [m] (None: a frame not flown)."""
        lat0, lon0, alt0 = self.origin
        if it.frame == 1:  # MAV_FRAME_LOCAL_NED, metres x 1e4 in MISSION_ITEM_INT
            return it.x * 1e-4, it.y * 1e-4, float(it.z)
        if it.frame not in (0, 3, 5, 6, 10, 11):
            return None
        if it.x == 0 and it.y == 0:
            n, e = nav.n, nav.e
        else:
            n, e = local_from_geodetic(lat0, lon0, it.x * 1e-7, it.y * 1e-7)
        d = alt0 - float(it.z) if it.frame in (0, 5) else self.home_ned()[2] - float(it.z)
        return n, e, d

    def _stopping_point(self, nav: NavReading, accel: float) -> tuple[float, float]:
        v = math.hypot(nav.vn, nav.ve)
        if v < 1e-6:
            return nav.n, nav.e
        s = v / (2.0 * accel)  # distance / speed
        return nav.n + nav.vn * s, nav.e + nav.ve * s

    # ------------------------------------------------------------------ modes
    def refusal(self, mode: Mode, landed: bool) -> str:
        """Why ``mode`` cannot be entered now ("" if it can)."""
        if mode == Mode.RTL and not self.home.is_set:
            return "RTL: home not set"
        if mode == Mode.AUTO:
            item = self._next_nav_item(self.missions.current_seq)
            if item is None:
                return "Auto: no mission"
            if landed and item.command != _TAKEOFF:
                return "Auto: Missing takeoff command"
        return ""

    def enter(self, mode: Mode, nav: NavReading, yaw: float, landed: bool, now_ns: int) -> None:
        """Start ``mode`` (any mode: the navigator keeps to the ones it flies) at the current state."""
        self.mode = mode
        self.velocity = None
        self._int = [0.0, 0.0]
        self.yaw, self._yaw_goal = yaw, None
        self._hold_level = mode == Mode.ALT_HOLD
        self._speed_override = None
        self.phase, self._since_ns, self._item = "", now_ns, None
        self.last = None
        n, e = self._stopping_point(nav, self._speed_accel()[1])
        self.target = (n, e, nav.d)
        if mode == Mode.RTL:
            self._rtl_start(nav, landed, now_ns)
        elif mode == Mode.AUTO:
            self._auto_next(self.missions.current_seq, nav, now_ns)

    def takeoff(self, alt_above_home_m: float, nav: NavReading) -> None:
        """GUIDED's NAV_TAKEOFF: climb to ``alt_above_home_m`` over where the vehicle is."""
        self.velocity = None
        self.target = (nav.n, nav.e, self.home_ned()[2] - alt_above_home_m)

    def goto(self, n: float, e: float, d: float, yaw: float | None) -> None:
        """GUIDED position target, NED [m]; ``yaw`` [rad] or None (face the way)."""
        self.velocity = None
        self.target = (n, e, d)
        self._yaw_goal = yaw

    def set_velocity(self, vn: float, ve: float, vd: float, yaw: float | None, nav: NavReading, now_ns: int) -> None:
        """GUIDED velocity target, NED [m/s] (held until ``GUID_TIMEOUT`` passes without another)."""
        self.velocity = (vn, ve, vd)
        self._velocity_ns = now_ns
        self.target = (nav.n, nav.e, nav.d)
        self._yaw_goal = yaw

    def set_speed(self, speed_m_s: float) -> None:
        """DO_CHANGE_SPEED (horizontal; <= 0 keeps the current one)."""
        if speed_m_s > 0.0:
            self._speed_override = float(speed_m_s)

    # ------------------------------------------------------------------ RTL
    def _rtl_start(self, nav: NavReading, landed: bool, now_ns: int) -> None:
        if landed:
            self.phase = "land"
            return
        up = -nav.d
        home_d = self.home_ned()[2]
        climb_to = max(up + self.params["RTL_CLIMB_MIN_M"], -home_d + self.params["RTL_ALT_M"], up)
        n, e = self.target[:2] if self.mode == Mode.RTL else (nav.n, nav.e)  # RTL: from the stopping point
        self.target = (n, e, -climb_to)
        self.phase, self._since_ns = "climb", now_ns

    def _rtl_step(self, nav: NavReading, now_ns: int) -> None:
        p = self.params
        hn, he, hd = self.home_ned()
        if self.phase == "climb" and nav.d - self.target[2] < _ALT_REACHED_M:
            self.phase, self.target = "return", (hn, he, self.target[2])
        elif self.phase == "return" and self._h_dist(nav) < p["WP_RADIUS_M"] and math.hypot(nav.vn, nav.ve) < 0.5:
            self.phase, self._since_ns = "loiter", now_ns
        elif self.phase == "loiter" and now_ns - self._since_ns >= p["RTL_LOIT_TIME"] * 1e6:
            final = p["RTL_ALT_FINAL_M"]
            if final > 0.0:
                self.phase, self.target = "final", (hn, he, hd - final)
            else:
                self.phase = "land"

    # ------------------------------------------------------------------ AUTO
    def _next_nav_item(self, seq: int) -> MissionItem | None:
        store = self.missions
        for s in range(max(seq, 1), store.count(0)):
            it = store.get(0, s)
            if it is not None and it.command in _NAV_COMMANDS:
                return it
        return None

    def _auto_next(self, seq: int, nav: NavReading, now_ns: int) -> None:
        """Start the mission at item ``seq``: DO_ items on the way are done, the next navigation item begun."""
        store = self.missions
        seq = max(seq, 1)
        while seq < store.count(0):
            it = store.get(0, seq)
            if it is not None and it.command in _NAV_COMMANDS:
                break
            if it is not None and it.command == _CHANGE_SPEED:
                self.set_speed(it.param2)
            seq += 1
        else:
            self._item, self.phase = None, "done"
            self.target = (nav.n, nav.e, nav.d)
            return
        store.current_seq = seq
        self._item, self.phase, self._since_ns = it, "go", now_ns
        self._say(6, f"Mission: {seq} {_NAMES[it.command]}")
        cmd = it.command
        if cmd == _RTL:
            self._rtl_start(nav, False, now_ns)
            return
        pos = self.item_ned(it, nav)
        if pos is None:
            self._say(4, f"Mission: item {seq} frame {it.frame} not flown, skipped")
            self._auto_done(nav, now_ns)
            return
        if cmd == _TAKEOFF:
            self.target = (nav.n, nav.e, pos[2])
        elif cmd == _LAND and it.x == 0 and it.y == 0:
            self.target, self.phase = (nav.n, nav.e, nav.d), "land"
        elif cmd == _LAND:
            self.target = (pos[0], pos[1], nav.d)
        else:
            self.target = pos

    def _auto_done(self, nav: NavReading, now_ns: int) -> None:
        """The current item is reached: report it, go on with the next."""
        it = self._item
        if it is None:
            return
        self._reached(it.seq)
        self._auto_next(it.seq + 1, nav, now_ns)

    def _reached(self, seq: int) -> None:
        self.missions.reached.append(seq)
        self._say(6, f"Reached command #{seq}")

    def _auto_step(self, nav: NavReading, now_ns: int) -> None:
        it = self._item
        if it is None:
            return
        cmd, p = it.command, self.params
        if cmd == _RTL:
            self._rtl_step(nav, now_ns)
            return
        if self.phase == "land":
            return
        near = self._h_dist(nav) < p["WP_RADIUS_M"] and abs(nav.d - self.target[2]) < 1.0
        if cmd == _TAKEOFF:
            if nav.d - self.target[2] < _ALT_REACHED_M:
                self._auto_done(nav, now_ns)
        elif cmd == _LAND:
            if near or self._h_dist(nav) < p["WP_RADIUS_M"]:
                self.phase = "land"
        elif self.phase == "go" and near:
            self.phase, self._since_ns = "hold", now_ns
        elif self.phase == "hold" and cmd != _LOITER_UNLIM and now_ns - self._since_ns >= it.param1 * 1e9:
            self._auto_done(nav, now_ns)

    def wants_takeoff(self, nav: NavReading) -> bool:
        """Landed: whether the mode demands a take-off (a target :data:`TAKEOFF_MIN_M` above, or a
        climbing velocity target); if not, the altitude target follows the ground (sensor noise never
        lifts the vehicle off)."""
        if self.phase == "land":
            return False
        if self.velocity is not None:
            return -self.velocity[2] > 0.2
        if nav.d - self.target[2] > TAKEOFF_MIN_M:
            return True
        self.target = (self.target[0], self.target[1], nav.d)
        return False

    def touchdown(self) -> None:
        """Landed by the navigator's landing: AUTO's LAND or RTL item is reached (the vehicle disarms)."""
        it = self._item
        if self.mode == Mode.AUTO and it is not None and it.command in (_LAND, _RTL):
            self._reached(it.seq)
            self._item, self.phase = None, "done"

    # ------------------------------------------------------------------ control
    def _h_dist(self, nav: NavReading) -> float:
        return math.hypot(self.target[0] - nav.n, self.target[1] - nav.e)

    def _speed_accel(self) -> tuple[float, float]:
        """Speed [m/s] and acceleration [m/s^2] limits of the mode (the latter at most what the lean
        limit gives, so that the square-root controller's deceleration can be flown)."""
        speed, accel = self._mode_speed_accel()
        return speed, min(accel, self.g * math.tan(math.radians(self.params["ATC_ANGLE_MAX"])))

    def _mode_speed_accel(self) -> tuple[float, float]:
        p, mode = self.params, self.mode
        if mode == Mode.BRAKE:
            return p["LOIT_SPEED_MS"], BRAKE_ACC_M_S2
        if mode in (Mode.LOITER, Mode.POSHOLD):
            return p["LOIT_SPEED_MS"], p["LOIT_ACC_MAX_M"]
        speed = p["WP_SPD"]
        if mode == Mode.RTL or (mode == Mode.AUTO and self._item is not None and self._item.command == _RTL):
            speed = p["RTL_SPEED_MS"] or speed
        if self._speed_override is not None:
            speed = self._speed_override
        return speed, p["WP_ACC"]

    def _yaw_step(self, nav: NavReading, dt: float) -> None:
        goal = self._yaw_goal
        if goal is None and self.mode in (Mode.AUTO, Mode.RTL, Mode.GUIDED) and self._h_dist(nav) > _FACE_DISTANCE_M:
            goal = math.atan2(self.target[1] - nav.e, self.target[0] - nav.n)
        if goal is None:
            return
        err = (goal - self.yaw + math.pi) % (2.0 * math.pi) - math.pi
        step = YAW_SLEW_RAD_S * dt
        self.yaw += max(-step, min(step, err))

    def _lean(self, an: float, ae: float, yaw_meas: float) -> tuple[float, float]:
        # at most twice the mode's acceleration (room for disturbances) and the lean angle limit
        lim = min(2.0 * self._speed_accel()[1], self.g * math.tan(math.radians(self.params["ATC_ANGLE_MAX"])))
        norm = math.hypot(an, ae)
        if norm > lim:
            an, ae = an * lim / norm, ae * lim / norm
        cy, sy = math.cos(yaw_meas), math.sin(yaw_meas)
        fwd, right = cy * an + sy * ae, -sy * an + cy * ae
        pitch = -math.atan(fwd / self.g)
        return math.atan(right * math.cos(pitch) / self.g), pitch

    def _horizontal(self, nav: NavReading, dt: float) -> tuple[float, float]:
        speed, accel = self._speed_accel()
        en, ee = self.target[0] - nav.n, self.target[1] - nav.e
        dist = math.hypot(en, ee)
        v = min(sqrt_controller(dist, POS_P_1_S, accel), speed)
        vn, ve = (en / dist * v, ee / dist * v) if dist > 1e-9 else (0.0, 0.0)
        if self.velocity is not None:
            vn, ve = self.velocity[0], self.velocity[1]
        err = (vn - nav.vn, ve - nav.ve)
        for i in (0, 1):
            self._int[i] = max(-VEL_IMAX_M_S2, min(VEL_IMAX_M_S2, self._int[i] + VEL_I_1_S2 * err[i] * dt))
        return VEL_P_1_S * err[0] + self._int[0], VEL_P_1_S * err[1] + self._int[1]

    def _climb(self, nav: NavReading) -> float:
        p = self.params
        if self.velocity is not None:
            c = -self.velocity[2]
        else:
            c = sqrt_controller(nav.d - self.target[2], POS_P_1_S, p["WP_ACC_Z"])
        return max(-p["WP_SPD_DN"], min(p["WP_SPD_UP"], c))

    def update(self, now_ns: int, dt: float, nav: NavReading, yaw_meas: float) -> NavDemand:
        """One control period of the current mode."""
        if self.velocity is not None and now_ns - self._velocity_ns > self.params["GUID_TIMEOUT"] * 1e9:
            self.velocity = None  # velocity timeout: stop and hold where it stops
            n, e = self._stopping_point(nav, self.params["WP_ACC"])
            self.target = (n, e, nav.d)
        if self.mode == Mode.RTL:
            self._rtl_step(nav, now_ns)
        elif self.mode == Mode.AUTO:
            self._auto_step(nav, now_ns)
        self._yaw_step(nav, dt)
        if self._hold_level:
            roll = pitch = 0.0
        else:
            roll, pitch = self._lean(*self._horizontal(nav, dt), yaw_meas)
        land = self.phase == "land"
        climb = -land_speed(self.params, -nav.d + self.home_ned()[2]) if land else self._climb(nav)
        self.last = NavDemand(euler_to_quaternion(roll, pitch, self.yaw), climb, land)
        return self.last
