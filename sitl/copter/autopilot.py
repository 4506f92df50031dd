"""Emulated ArduCopter: modes, arming, guided targets, inner loops, land detector, failsafes.

Everything runs in simulated time (integer nanoseconds passed in by the caller) on plain Python
values; the MAVLink side is :mod:`sitl.copter.dispatch` and :mod:`sitl.copter.telemetry`.
Messages for the ground station (STATUSTEXT) are queued in :attr:`Autopilot.events`.

Failsafes
    No new accepted attitude target for ``GUID_TIMEOUT`` while armed in a guided mode: level, switch
    to LAND, STATUSTEXT.  (ArduCopter itself only levels and holds altitude on this timeout.)  GUIDED
    without attitude targets holds position (:mod:`sitl.copter.navigation`), as ArduCopter.
    Battery below ``BATT_LOW_VOLT`` (resting voltage) or ``BATT_LOW_MAH`` for 10 s: STATUSTEXT
    and, with ``BATT_FS_LOW_ACT >= 1``, LAND.
Landing and disarming
    Land detector: throttle below 85 % of hover while descending is demanded and the vehicle is
    still (|climb| < 0.3 m/s, horizontal < 1 m/s) for 1 s.  LAND descends at ``LAND_SPD_MS``
    (``LAND_SPD_HIGH_MS`` or ``WP_SPD_DN`` above ``LAND_ALT_LOW_M``), damps horizontal drift, and
    disarms on landing.  ``DISARM_DELAY`` s landed while armed disarms in every mode.  Disarming
    in flight is refused unless forced (param2 = 21196, which also skips the arming checks).
Ground handling
    In a guided mode a positive climb rate or thrust takes off; else the motors idle on the ground.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from quadrotor.frames import euler_to_quaternion
from sitl.copter.arming import arming_failure, battery_low
from sitl.copter.battery import BatteryState
from sitl.copter.control import (ClimbRateController, RateController, angle_boost, attitude_rate_demand, land_attitude,
                                 land_speed)
from sitl.copter.mixer import Mixer, MixResult
from sitl.copter.modes import GUIDED_ENABLED_MODES, GUIDED_MODES, Mode
from sitl.copter.autopilot_nav import NavigationMixin
from sitl.copter.navigation import Navigator
from sitl.copter.params import ParamStore
from sitl.copter.sensors import ImuReading, NavReading
from sitl.copter.targets import Target, actuator_target, attitude_target
from sitl.copter.vehicle import VehicleParams

__all__ = ["Autopilot", "FORCE_MAGIC", "SEVERITY_CRITICAL", "SEVERITY_WARNING", "SEVERITY_INFO"]

FORCE_MAGIC = 21196
SEVERITY_CRITICAL = 2
SEVERITY_WARNING = 4
SEVERITY_INFO = 6

_LAND_DETECT_S = 1.0
_BATT_LOW_TIMER_S = 10.0


class Autopilot(NavigationMixin):
    """The emulated flight controller of one vehicle.

    Parameters
    ----------
    vehicle : VehicleParams
    params : ParamStore
        ArduPilot parameters (:func:`sitl.copter.params.ardupilot_params`).
    prearm_delay_s : float
        Arming is refused ("Arm: AHRS not ready") until this simulated time (an EKF settling).
    """

    identity: tuple[int, int, list[int]] | None = None  # AUTOPILOT_VERSION fields of an emulated firmware

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
        #: The navigation modes (attached by the simulation, which has the mission and home); None: none.
        self.navigator: Navigator | None = None
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
        self._disarm_delay_ns = p["DISARM_DELAY"] * 1e9

    # ------------------------------------------------------------------ helpers
    def say(self, severity: int, text: str) -> None:
        """A STATUSTEXT for the ground station (MAV_SEVERITY ``severity``; cut at its 50 characters)."""
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
    def base_mode(self) -> int:
        """HEARTBEAT base_mode: CUSTOM_MODE_ENABLED | STABILIZE_ENABLED, + GUIDED_ENABLED, + SAFETY_ARMED."""
        guided = self.mode in GUIDED_ENABLED_MODES or self.mode == Mode.GUIDED_NOGPS
        return 1 | 16 | (8 if guided else 0) | (128 if self.armed else 0)

    def position_ready(self, now_ns: int) -> bool:
        """Whether LOCAL_POSITION_NED is sent (always here; an emulated EKF waits)."""
        return True

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
            self.say(SEVERITY_WARNING, reason)
            return False, reason
        if new == self.mode:
            return True, ""
        why = self._nav_refusal(new)
        if why:
            self.say(SEVERITY_WARNING, why)
            return False, why
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
        self._nav_enter(now_ns)

    def arm(self, now_ns: int, force: bool = False) -> tuple[bool, str]:
        """Arm (checks: :func:`~sitl.copter.arming.arming_failure`); returns ``(ok, reason)``."""
        if self.armed:
            return True, ""
        if not force:
            reason = arming_failure(self.mode, now_ns, self.prearm_delay_ns, self.params, self._last_imu,
                                    self._last_nav, self._battery, self._r_int)
            if reason:
                self.say(SEVERITY_CRITICAL, f"Arm: {reason}")
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
        self._nav_enter(now_ns)
        self.say(SEVERITY_INFO, "Arming motors")
        return True, ""

    def disarm(self, now_ns: int, force: bool = False, why: str = "") -> tuple[bool, str]:
        """Disarm; refused in flight unless ``force``."""
        if not self.armed:
            return True, ""
        if not force and not self.land_complete:
            self.say(SEVERITY_CRITICAL, "Disarm: vehicle is flying")
            return False, "vehicle is flying"
        self.armed = False
        self.land_complete = True
        self.target = None
        self._reset_loops()
        self.say(SEVERITY_INFO, f"Disarming motors{': ' + why if why else ''}")
        return True, ""

    def set_attitude_target(self, type_mask: int, q: Sequence[float], rates: Sequence[float], thrust: float,
                            now_ns: int) -> tuple[bool, str]:
        """Apply a SET_ATTITUDE_TARGET (see :func:`~sitl.copter.targets.attitude_target`); returns ``(ok, reason)``."""
        if self.mode not in GUIDED_MODES:
            return self._take(None, "not in a guided mode")
        return self._take(*attitude_target(type_mask, q, rates, thrust, now_ns, self.params))

    def set_actuator_controls(self, controls: Sequence[float], now_ns: int) -> tuple[bool, str]:
        """Apply SET_ACTUATOR_CONTROL_TARGET group 0 controls; returns ``(accepted, reason)``."""
        if self.mode not in GUIDED_MODES:
            return self._take(None, "not in a guided mode")
        return self._take(*actuator_target(controls, now_ns))

    def _take(self, target: Target | None, reason: str) -> tuple[bool, str]:
        if target is None:
            self.targets_rejected += 1
            return False, reason
        self.target = target
        self._timer_ns = target.time_ns
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
        if now_ns - self._timer_ns > self._timeout_ns and self.mode in GUIDED_MODES and not self._nav_flies():
            self._guided_timeout(now_ns)
        low, rest = battery_low(battery, self.params, self._r_int)
        if not low:
            self._batt_low_since_ns = None
        elif self._batt_low_since_ns is None:
            self._batt_low_since_ns = now_ns
        elif not self._batt_announced and now_ns - self._batt_low_since_ns >= _BATT_LOW_TIMER_S * 1e9:
            self._batt_announced = True
            self.say(SEVERITY_WARNING, f"Battery 1 is low {rest:.2f}V used {battery.consumed_mah:.0f} mAh")
            if self._p("BATT_FS_LOW_ACT") >= 1 and self.mode != Mode.LAND:
                self._enter(Mode.LAND, now_ns)
                self.failsafe = "battery"

    def _guided_timeout(self, now_ns: int) -> None:
        """No target for GUID_TIMEOUT in a guided mode: level and LAND (the emulations override it)."""
        self.say(SEVERITY_WARNING, f"Guided timeout: no target for {self._timeout_ns * 1e-9:g} s, LAND")
        self._enter(Mode.LAND, now_ns)
        self.failsafe = "guided timeout"

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
            rt = tuple(min(max(v, -m), m) if m > 0 else v for v, m in zip(rate_ff, lim, strict=True))
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
        if self._nav_flies():
            return self._run_nav(now_ns, dt, imu, nav)
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
            c = self.vehicle.control
            q = land_attitude(nav.vn, nav.ve, self._yaw_hold, c.land_damping_1_s, self.vehicle.gravity_m_s2)
            thr = self._climb_throttle(-land_speed(self.params, -nav.d), dt, nav)
            return self._fly(q, (0.0, 0.0, 0.0), False, thr, True, dt, imu)
        # STABILIZE without RC: zero throttle.
        if self.land_complete:
            return self._ground_idle()
        return self._fly(self._level_q(), (0.0, 0.0, 0.0), False, 0.0, False, dt, imu)

    def _descent_demanded(self) -> bool:
        if self.throttle >= 0.85 * self._hover:
            return False
        if self._nav_flies():
            return self._nav_descending()
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
                last = self.navigator.last if self._nav_flies() else None  # type: ignore[union-attr]
                if self.mode == Mode.LAND or (last is not None and last.land):
                    if last is not None:
                        self.navigator.touchdown()  # type: ignore[union-attr]
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
