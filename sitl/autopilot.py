"""Emulated ArduCopter: modes, arming, guided targets, inner loops, land detector, failsafes.

Everything here runs in simulated time (integer nanoseconds passed in by the
caller) and talks in plain Python values; MAVLink decoding/encoding lives in
:mod:`sitl.dispatch` and :mod:`sitl.telemetry`.  Messages for the ground
station (STATUSTEXT) are queued in :attr:`Autopilot.events`.

Behaviour (ArduCopter conventions)
----------------------------------
Modes
    STABILIZE (0), GUIDED (4), LAND (9), GUIDED_NOGPS (20).  STABILIZE has no
    RC here, so its throttle is zero: it levels the vehicle and idles on the
    ground (and falls if selected in flight, like a real copter without RC).
Guided targets (GUIDED and GUIDED_NOGPS)
    SET_ATTITUDE_TARGET as in ArduCopter's ``handle_message_set_attitude_target``:
    THROTTLE_IGNORE (64) and non-unit quaternions (``|1 - |q|^2| >= 1e-3``) are
    rejected; body rates are used only when all three rate-ignore bits
    (1, 2, 4) are clear (a partial set is rejected), as feed-forward with an
    attitude or alone with ATTITUDE_IGNORE (128).  With ``GUID_OPTIONS`` bit 3
    (8) the thrust field is throttle (0..1 of full thrust, angle-boosted when
    ``ATC_ANGLE_BOOST = 1`` as ArduPilot does); otherwise it is a climb-rate
    demand: 0.5 holds, 1.0 climbs at ``WP_SPD_UP``, 0.0 descends at
    ``WP_SPD_DN``.
    SET_ACTUATOR_CONTROL_TARGET (group 0) bypasses the attitude and rate loops:
    ``controls[0..2]`` in [-1, 1] times :attr:`VehicleParams.max_torque_nm`
    are the body torques, ``controls[3]`` in [0, 1] times the full thrust is
    the collective thrust (no angle boost); the mixer saturates them.
    A positive climb rate or thrust takes off; while landed anything else
    idles the motors (ArduCopter's ground handling).
Failsafes
    No new accepted target for ``GUID_TIMEOUT`` while armed in a guided mode:
    level, switch to LAND, STATUSTEXT.  (ArduCopter itself only levels and
    holds altitude on this timeout.)  Battery below ``BATT_LOW_VOLT`` (resting
    voltage) or ``BATT_LOW_MAH`` for 10 s: STATUSTEXT and, with
    ``BATT_FS_LOW_ACT >= 1``, LAND.
Landing and disarming
    Land detector: throttle below 85 % of hover while descending is demanded
    and the vehicle is still (|climb| < 0.3 m/s, horizontal < 1 m/s) for 1 s.
    LAND descends at ``LAND_SPD_MS`` (``LAND_SPD_HIGH_MS`` or ``WP_SPD_DN``
    above ``LAND_ALT_LOW_M``), damps horizontal drift, and disarms on landing.
    ``DISARM_DELAY`` s landed while armed disarms in every mode.
Arming (MAV_CMD_COMPONENT_ARM_DISARM)
    Refused, with an "Arm: ..." STATUSTEXT, in LAND, when leaning more than
    ``ATC_ANGLE_MAX``, when not landed (altitude above 1 m or speed above
    0.5 m/s), and when the battery is below ``BATT_ARM_VOLT``/``BATT_LOW_VOLT``/
    ``BATT_LOW_MAH``.  ``ARMING_CHECK = 0`` skips the checks; param2 = 21196
    forces arming and disarming.  Disarming in flight is refused unless forced.
"""

from __future__ import annotations

import math
from enum import IntEnum
from typing import NamedTuple, Sequence

from quadrotor.mavlink.modes import COPTER_MODES
from sitl.battery import BatteryState
from sitl.control import ClimbRateController, RateController, angle_boost, attitude_rate_demand
from quadrotor.frames import euler_to_quaternion, quat_is_unit
from sitl.mixer import Mixer, MixResult
from sitl.ned_sensors import ImuReading, NavReading
from sitl.params import ParamStore
from sitl.vehicle_params import VehicleParams

__all__ = ["Mode", "MODE_NAMES", "GUIDED_MODES", "Target", "Autopilot", "FORCE_MAGIC",
           "SEVERITY_CRITICAL", "SEVERITY_WARNING", "SEVERITY_NOTICE", "SEVERITY_INFO"]

FORCE_MAGIC = 21196
SEVERITY_CRITICAL = 2
SEVERITY_WARNING = 4
SEVERITY_NOTICE = 5
SEVERITY_INFO = 6

# SET_ATTITUDE_TARGET type_mask bits
_ROLL_RATE_IGNORE, _PITCH_RATE_IGNORE, _YAW_RATE_IGNORE = 1, 2, 4
_RATES_IGNORE = 7
_THROTTLE_IGNORE = 64
_ATTITUDE_IGNORE = 128
_GUID_OPTION_THRUST = 8

_LAND_DETECT_S = 1.0
_BATT_LOW_TIMER_S = 10.0


class Mode(IntEnum):
    """The ArduCopter custom modes emulated here (numbers from :data:`quadrotor.mavlink.modes.COPTER_MODES`)."""

    STABILIZE = COPTER_MODES["STABILIZE"]
    GUIDED = COPTER_MODES["GUIDED"]
    LAND = COPTER_MODES["LAND"]
    GUIDED_NOGPS = COPTER_MODES["GUIDED_NOGPS"]


MODE_NAMES = {m.value: m.name for m in Mode}
GUIDED_MODES = (Mode.GUIDED, Mode.GUIDED_NOGPS)
_ARMABLE = (Mode.STABILIZE, Mode.GUIDED, Mode.GUIDED_NOGPS)


class Target(NamedTuple):
    """An accepted guided target.

    ``kind``: ``"attitude"`` (quaternion, rates as feed-forward), ``"rates"``
    (body rates only) or ``"actuator"`` (normalised torques).  ``use_thrust``:
    ``value`` is throttle 0..1, else a climb rate [m/s, up].
    """

    kind: str
    q: tuple[float, float, float, float]
    rates: tuple[float, float, float]
    use_thrust: bool
    value: float
    torques: tuple[float, float, float]
    time_ns: int


class Autopilot:
    """The emulated flight controller of one vehicle.

    Parameters
    ----------
    vehicle : VehicleParams
    params : ParamStore
        ArduPilot parameters (:func:`sitl.params.ardupilot_params`).
    prearm_delay_s : float
        Arming is refused ("Arm: AHRS not ready") until this simulated time,
        like a real autopilot whose EKF is still settling after boot.
    """

    def __init__(self, vehicle: VehicleParams, params: ParamStore, prearm_delay_s: float = 0.0) -> None:
        self.vehicle = vehicle
        self.prearm_delay_ns = int(round(prearm_delay_s * 1e9))
        self.params = params
        self.mixer = Mixer(vehicle)
        c = vehicle.control
        self.rate_ctl = RateController(vehicle.inertia_kg_m2, c.rate_p_1_s, c.rate_i_1_s2, c.rate_imax_rad_s2)
        self.climb_ctl = ClimbRateController(c.climb_p_1_s, c.climb_i_1_s2, vehicle.gravity_m_s2)
        self.mode = Mode.STABILIZE
        self.armed = False
        self.land_complete = True
        self.target: Target | None = None
        self.failsafe = ""
        self.events: list[tuple[int, str]] = []
        self.targets_accepted = 0
        self.targets_rejected = 0
        self.throttle = 0.0
        self.rotor_cmd_n: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
        self.att_target_q: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
        self.rate_target: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._fmax = vehicle.max_total_thrust_n
        self._tmax = vehicle.max_torque_nm
        self._idle = (vehicle.rotors.idle_thrust_n,) * 4
        self._timer_ns = 0
        self._landed_since_ns: int | None = None
        self._land_cond_since_ns: int | None = None
        self._batt_low_since_ns: int | None = None
        self._batt_announced = False
        self._yaw_hold = 0.0
        self._last_mix: MixResult | None = None
        self._vz_filt = 0.0
        self._now_ns = 0
        self._last_imu: ImuReading | None = None
        self._last_nav: NavReading | None = None
        self._battery: BatteryState | None = None
        self._r_int = vehicle.battery.internal_resistance_ohm
        self._vz_dt = -1.0
        self._vz_a = 0.0
        self._refresh()
        params.add_listener(lambda name, value: self._refresh())

    def _refresh(self) -> None:
        """Cache the parameters read every tick (called on every parameter change)."""
        p = self.params
        self._timeout_ns = p["GUID_TIMEOUT"] * 1e9
        self._hover = p["MOT_THST_HOVER"]
        self._acc_z = p["WP_ACC_Z"]
        self._ang_p = (p["ATC_ANG_RLL_P"], p["ATC_ANG_PIT_P"], p["ATC_ANG_YAW_P"])
        self._rate_lim = tuple(math.radians(p[n]) for n in ("ATC_RATE_R_MAX", "ATC_RATE_P_MAX", "ATC_RATE_Y_MAX"))
        self._boost = p["ATC_ANGLE_BOOST"] >= 1
        self._batt_low_v = p["BATT_LOW_VOLT"]
        self._batt_low_mah = p["BATT_LOW_MAH"]
        self._batt_cap = p["BATT_CAPACITY"]
        self._disarm_delay_ns = p["DISARM_DELAY"] * 1e9

    # ------------------------------------------------------------------ helpers
    def _say(self, severity: int, text: str) -> None:
        self.events.append((severity, text[:50]))

    def _p(self, name: str) -> float:
        return self.params[name]

    @property
    def mode_name(self) -> str:
        """ArduCopter name of the current mode."""
        return self.mode.name

    @property
    def system_status(self) -> int:
        """MAV_STATE: STANDBY (3), ACTIVE (4) or CRITICAL (5, failsafe while armed)."""
        if not self.armed:
            return 3
        return 5 if self.failsafe else 4

    @property
    def landed_state(self) -> int:
        """MAV_LANDED_STATE: ON_GROUND (1), IN_AIR (2), LANDING (4)."""
        if self.land_complete:
            return 1
        return 4 if self.mode == Mode.LAND else 2

    def _reset_loops(self, climb_m_s: float = 0.0) -> None:
        self.rate_ctl.reset()
        self.climb_ctl.reset(climb_m_s)

    # ------------------------------------------------------------------ commands
    def set_mode(self, mode: int, now_ns: int) -> tuple[bool, str]:
        """Change flight mode; returns ``(accepted, reason)``."""
        try:
            new = Mode(int(mode))
        except ValueError:
            reason = f"Mode change to {int(mode)} failed: unsupported"
            self._say(SEVERITY_WARNING, reason)
            return False, reason
        if new == self.mode:
            return True, ""
        self._enter(new, now_ns)
        self.failsafe = ""
        return True, ""

    def _enter(self, mode: Mode, now_ns: int) -> None:
        self.mode = mode
        self.target = None
        self._timer_ns = now_ns
        imu = self._last_imu
        self._yaw_hold = imu.yaw if imu is not None else self._yaw_hold
        nav = self._last_nav
        self.climb_ctl.reset(-nav.vd if nav is not None and not self.land_complete else 0.0)

    def arm(self, now_ns: int, force: bool = False) -> tuple[bool, str]:
        """Arm (checks as in the module docstring); returns ``(ok, reason)``."""
        if self.armed:
            return True, ""
        if not force:
            reason = self._arming_failure(now_ns)
            if reason:
                self._say(SEVERITY_CRITICAL, f"Arm: {reason}")
                return False, reason
        self.armed = True
        self.land_complete = True
        self._timer_ns = now_ns
        self._landed_since_ns = now_ns
        self._land_cond_since_ns = None
        self.failsafe = ""
        self.target = None
        imu = self._last_imu
        self._yaw_hold = imu.yaw if imu is not None else 0.0
        self._reset_loops()
        self._say(SEVERITY_INFO, "Arming motors")
        return True, ""

    def _arming_failure(self, now_ns: int) -> str:
        if self.mode not in _ARMABLE:
            return "Mode not armable"
        if self._p("ARMING_CHECK") == 0:
            return ""
        if now_ns < self.prearm_delay_ns:
            return f"AHRS not ready ({(self.prearm_delay_ns - now_ns) * 1e-9:.1f} s)"
        imu, nav = self._last_imu, self._last_nav
        if imu is not None:
            tilt = math.degrees(math.acos(max(-1.0, min(1.0, math.cos(imu.roll) * math.cos(imu.pitch)))))
            if tilt > self._p("ATC_ANGLE_MAX"):
                return f"Leaning ({tilt:.0f} deg > ATC_ANGLE_MAX)"
        if nav is not None:
            speed = math.sqrt(nav.vn ** 2 + nav.ve ** 2 + nav.vd ** 2)
            if abs(nav.baro_alt_m) > 1.0 or speed > 0.5:
                return f"Not landed (alt {nav.baro_alt_m:.1f} m, {speed:.1f} m/s)"
        b = self._battery
        if b is not None:
            rest = self._resting_voltage(b)
            arm_v = self._p("BATT_ARM_VOLT")
            low_v = self._p("BATT_LOW_VOLT")
            if arm_v > 0 and rest < arm_v:
                return f"Battery 1 below min arming volt ({rest:.2f} V)"
            if low_v > 0 and rest < low_v:
                return f"Battery 1 low voltage failsafe ({rest:.2f} V)"
            low_mah = self._p("BATT_LOW_MAH")
            if low_mah > 0 and self._p("BATT_CAPACITY") - b.consumed_mah < low_mah:
                return "Battery 1 low capacity failsafe"
        return ""

    def _resting_voltage(self, b: BatteryState) -> float:
        return b.voltage_v + b.current_a * self._r_int

    def disarm(self, now_ns: int, force: bool = False, why: str = "") -> tuple[bool, str]:
        """Disarm; refused in flight unless ``force``."""
        if not self.armed:
            return True, ""
        if not force and not self.land_complete:
            self._say(SEVERITY_CRITICAL, "Disarm: vehicle is flying")
            return False, "vehicle is flying"
        self.armed = False
        self.land_complete = True
        self.target = None
        self._reset_loops()
        self._say(SEVERITY_INFO, f"Disarming motors{': ' + why if why else ''}")
        return True, ""

    def set_attitude_target(self, type_mask: int, q: Sequence[float], rates: Sequence[float], thrust: float,
                            now_ns: int) -> tuple[bool, str]:
        """Apply a SET_ATTITUDE_TARGET; returns ``(accepted, reason)``."""
        ok, reason = self._attitude_target(type_mask, q, rates, thrust, now_ns)
        if ok:
            self.targets_accepted += 1
        else:
            self.targets_rejected += 1
        return ok, reason

    def _attitude_target(self, type_mask: int, q: Sequence[float], rates: Sequence[float], thrust: float,
                         now_ns: int) -> tuple[bool, str]:
        if self.mode not in GUIDED_MODES:
            return False, "not in a guided mode"
        if type_mask & _THROTTLE_IGNORE:
            return False, "THROTTLE_IGNORE"
        quat = (1.0, 0.0, 0.0, 0.0)
        if not type_mask & _ATTITUDE_IGNORE:
            quat = tuple(float(v) for v in q)  # type: ignore[assignment]
            if not quat_is_unit(quat):
                return False, "attitude quaternion not unit length"
            n = math.sqrt(sum(v * v for v in quat))
            quat = tuple(v / n for v in quat)  # type: ignore[assignment]
        rates_used = (type_mask & _RATES_IGNORE) == 0
        if not rates_used and (type_mask & _RATES_IGNORE) != _RATES_IGNORE:
            return False, "body rates partly ignored"
        rr = tuple(float(v) for v in rates) if rates_used else (0.0, 0.0, 0.0)
        if not all(math.isfinite(v) for v in rr) or not math.isfinite(thrust):
            return False, "not finite"
        use_thrust = bool(int(self._p("GUID_OPTIONS")) & _GUID_OPTION_THRUST)
        if use_thrust:
            value = min(1.0, max(-1.0, thrust))
        else:
            t = min(1.0, max(0.0, thrust))
            if t == 0.5:
                value = 0.0
            elif t > 0.5:
                value = (t - 0.5) * 2.0 * self._p("WP_SPD_UP")
            else:
                value = (0.5 - t) * 2.0 * -self._p("WP_SPD_DN")
        kind = "rates" if type_mask & _ATTITUDE_IGNORE else "attitude"
        self.target = Target(kind, quat, rr, use_thrust, value, (0.0, 0.0, 0.0), now_ns)  # type: ignore[arg-type]
        self._timer_ns = now_ns
        return True, ""

    def set_actuator_controls(self, controls: Sequence[float], now_ns: int) -> tuple[bool, str]:
        """Apply SET_ACTUATOR_CONTROL_TARGET group 0 controls; returns ``(accepted, reason)``."""
        ok, reason = True, ""
        if self.mode not in GUIDED_MODES:
            ok, reason = False, "not in a guided mode"
        elif len(controls) < 4 or not all(math.isfinite(float(v)) for v in controls[:4]):
            ok, reason = False, "not finite"
        if not ok:
            self.targets_rejected += 1
            return ok, reason
        c = [float(v) for v in controls[:4]]
        tq = tuple(min(1.0, max(-1.0, v)) for v in c[:3])
        thr = min(1.0, max(0.0, c[3]))
        self.target = Target("actuator", (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), True, thr,
                             tq, now_ns)  # type: ignore[arg-type]
        self._timer_ns = now_ns
        self.targets_accepted += 1
        return True, ""

    # ------------------------------------------------------------------ loop
    def observe(self, imu: ImuReading, nav: NavReading, battery: BatteryState) -> None:
        """Take the latest sensor readings (arming checks use them between control periods)."""
        self._last_imu = imu
        self._last_nav = nav
        self._battery = battery

    def update(self, now_ns: int, dt: float, imu: ImuReading, nav: NavReading,
               battery: BatteryState) -> tuple[float, float, float, float]:
        """One control period: failsafes, mode logic, loops, mixer.

        Returns
        -------
        tuple of 4 floats
            Rotor thrust commands [N] for motors 1..4.
        """
        self._now_ns = now_ns
        self.observe(imu, nav, battery)
        if dt != self._vz_dt:
            self._vz_dt = dt
            self._vz_a = math.exp(-dt / 0.2)
        a = self._vz_a
        self._vz_filt = a * self._vz_filt + (1.0 - a) * nav.vd
        if not self.armed:
            self.land_complete = True
            self.throttle = 0.0
            self.rotor_cmd_n = (0.0, 0.0, 0.0, 0.0)
            return self.rotor_cmd_n
        self._check_failsafes(now_ns, battery)
        if not self.armed:
            self.rotor_cmd_n = (0.0, 0.0, 0.0, 0.0)
            return self.rotor_cmd_n
        cmd = self._run_mode(now_ns, dt, imu, nav)
        self._land_detector(now_ns, nav)
        self._auto_disarm(now_ns)
        if not self.armed:
            cmd = (0.0, 0.0, 0.0, 0.0)
        self.rotor_cmd_n = cmd
        return cmd

    def _check_failsafes(self, now_ns: int, battery: BatteryState) -> None:
        if now_ns - self._timer_ns > self._timeout_ns and self.mode in GUIDED_MODES:
            self._say(SEVERITY_WARNING, f"Guided timeout: no target for {self._timeout_ns * 1e-9:g} s, LAND")
            self._enter(Mode.LAND, now_ns)
            self.failsafe = "guided timeout"
        low_v = self._batt_low_v
        low_mah = self._batt_low_mah
        rest = battery.voltage_v + battery.current_a * self._r_int
        low = (low_v > 0 and rest < low_v) or (low_mah > 0 and self._batt_cap - battery.consumed_mah < low_mah)
        if not low:
            self._batt_low_since_ns = None
        elif self._batt_low_since_ns is None:
            self._batt_low_since_ns = now_ns
        elif not self._batt_announced and now_ns - self._batt_low_since_ns >= _BATT_LOW_TIMER_S * 1e9:
            self._batt_announced = True
            self._say(SEVERITY_WARNING, f"Battery 1 is low {rest:.2f}V used {battery.consumed_mah:.0f} mAh")
            if self._p("BATT_FS_LOW_ACT") >= 1 and self.mode != Mode.LAND:
                self._enter(Mode.LAND, now_ns)
                self.failsafe = "battery"

    def _level_q(self) -> tuple[float, float, float, float]:
        return euler_to_quaternion(0.0, 0.0, self._yaw_hold)

    def _ground_idle(self) -> tuple[float, float, float, float]:
        self._reset_loops()
        self.throttle = 0.0
        self._last_mix = None
        self.att_target_q = self._level_q()
        self.rate_target = (0.0, 0.0, 0.0)
        return self._idle

    def _fly(self, q_target, rate_ff, rates_only: bool, throttle: float, boost: bool, dt: float,
             imu: ImuReading) -> tuple[float, float, float, float]:
        lim = self._rate_lim
        if rates_only:
            rt = tuple(min(max(v, -l), l) if l > 0 else v for v, l in zip(rate_ff, lim))
        else:
            rt = attitude_rate_demand(q_target, (imu.qw, imu.qx, imu.qy, imu.qz), self._ang_p, rate_ff, lim)
        self.att_target_q = q_target
        self.rate_target = rt  # type: ignore[assignment]
        freeze = self._last_mix is not None and self._last_mix.rp_limited
        tx, ty, tz = self.rate_ctl.update(rt, (imu.p, imu.q, imu.r), dt, freeze)
        if boost and self._boost:
            throttle = angle_boost(throttle, math.cos(imu.roll) * math.cos(imu.pitch))
        throttle = 0.0 if throttle < 0.0 else 1.0 if throttle > 1.0 else throttle
        return self._mix(throttle, tx, ty, tz)

    def _mix(self, throttle: float, tx: float, ty: float, tz: float) -> tuple[float, float, float, float]:
        self.throttle = throttle
        m = self.mixer.mix(throttle * self._fmax, tx, ty, tz)
        self._last_mix = m
        return (m.t1, m.t2, m.t3, m.t4)

    def _climb_throttle(self, climb_m_s: float, dt: float, nav: NavReading) -> float:
        return self.climb_ctl.update(climb_m_s, -nav.vd, dt, self._hover, self._acc_z)

    def _run_mode(self, now_ns: int, dt: float, imu: ImuReading, nav: NavReading) -> tuple[float, float, float, float]:
        mode = self.mode
        if mode in GUIDED_MODES:
            t = self.target
            if t is None:  # mode entry / after arming: level, hold altitude (ArduCopter angle_control_start)
                t = Target("attitude", self._level_q(), (0.0, 0.0, 0.0), False, 0.0, (0.0, 0.0, 0.0), now_ns)
            positive = t.value > 0.0
            if self.land_complete:
                if not positive:
                    return self._ground_idle()
                self.land_complete = False
                self._landed_since_ns = None
                self._reset_loops()
            if t.kind == "actuator":
                self.att_target_q = (imu.qw, imu.qx, imu.qy, imu.qz)
                self.rate_target = (imu.p, imu.q, imu.r)
                return self._mix(t.value, t.torques[0] * self._tmax[0], t.torques[1] * self._tmax[1],
                                 t.torques[2] * self._tmax[2])
            thr = t.value if t.use_thrust else self._climb_throttle(t.value, dt, nav)
            return self._fly(t.q, t.rates, t.kind == "rates", thr, True, dt, imu)
        if mode == Mode.LAND:
            if self.land_complete:
                self.disarm(now_ns, force=True, why="landed")
                return (0.0, 0.0, 0.0, 0.0)
            alt = -nav.d
            if alt > self._p("LAND_ALT_LOW_M"):
                high = self._p("LAND_SPD_HIGH_MS")
                speed = high if high > 0 else self._p("WP_SPD_DN")
            else:
                speed = self._p("LAND_SPD_MS")
            k = self.vehicle.control.land_damping_1_s
            g = self.vehicle.gravity_m_s2
            amax = g * math.tan(math.radians(10.0))
            an, ae = -k * nav.vn, -k * nav.ve
            norm = math.hypot(an, ae)
            if norm > amax:
                an, ae = an * amax / norm, ae * amax / norm
            cy, sy = math.cos(self._yaw_hold), math.sin(self._yaw_hold)
            fwd = cy * an + sy * ae
            right = -sy * an + cy * ae
            q = euler_to_quaternion(math.atan(right / g), -math.atan(fwd / g), self._yaw_hold)
            thr = self._climb_throttle(-speed, dt, nav)
            return self._fly(q, (0.0, 0.0, 0.0), False, thr, True, dt, imu)
        # STABILIZE without RC: zero throttle.
        if self.land_complete:
            return self._ground_idle()
        return self._fly(self._level_q(), (0.0, 0.0, 0.0), False, 0.0, False, dt, imu)

    def _descent_demanded(self) -> bool:
        if self.throttle >= 0.85 * self._hover:
            return False
        if self.mode == Mode.LAND:
            return True
        t = self.target
        if self.mode in GUIDED_MODES and t is not None and not t.use_thrust:
            return t.value <= 0.0
        return True

    def _land_detector(self, now_ns: int, nav: NavReading) -> None:
        if self.land_complete:
            return
        if self._descent_demanded() and abs(self._vz_filt) < 0.3 and math.hypot(nav.vn, nav.ve) < 1.0:
            if self._land_cond_since_ns is None:
                self._land_cond_since_ns = now_ns
            elif now_ns - self._land_cond_since_ns >= _LAND_DETECT_S * 1e9:
                self.land_complete = True
                self._landed_since_ns = now_ns
                self._land_cond_since_ns = None
                self._reset_loops()
                if self.mode == Mode.LAND:
                    self.disarm(now_ns, force=True, why="landed")
        else:
            self._land_cond_since_ns = None

    def _auto_disarm(self, now_ns: int) -> None:
        if not self.armed or not self.land_complete:
            self._landed_since_ns = None
            return
        if self._landed_since_ns is None:
            self._landed_since_ns = now_ns
        delay = self._disarm_delay_ns
        if delay > 0 and now_ns - self._landed_since_ns >= delay:
            self.disarm(now_ns, force=True, why=f"landed for {delay * 1e-9:g} s")
