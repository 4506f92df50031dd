"""One simulated vehicle without any link: world, sensors and autopilot advanced tick by tick.

A tick is one period of the autopilot's inner loop (400 Hz by default)::

    rotor_cmd = autopilot.update(t, readings(t))   # targets received before t apply now
    world.step(rotor_cmd, tick)                    # plant sub-steps of <= 1 ms, wind, battery
    t += tick; readings(t) = sensors(world)        # what telemetry at t reports

Randomness is seeded per stream: wind ``default_rng([seed, 1])``, sensor noise
``default_rng([seed, 2])`` (the radios seed their own, :mod:`sitl.net.radio`), so the same
seed and the same command sequence give the same trajectory.  Time is integer
nanoseconds.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from quadrotor.frames import Kinematics
from quadrotor.wind import Wind, WindParams
from sitl.copter import rigid_body
from sitl.copter.ardupilot_emulation import EMULATIONS
from sitl.copter.ardupilot_emulation.autopilot import ArduCopterAutopilot
from sitl.copter.ardupilot_emulation.ekf import RATE_OFFSET_RAD_S, EkfHeight, EkfHorizontal, EkfTilt
from sitl.copter.ardupilot_emulation.ground import SmoothedSensors, sticky_ground_step
from sitl.copter.ardupilot_emulation.status import EKF_READY_S
from sitl.copter.ardupilot_emulation.vehicle import emulation_params
from sitl.copter.autopilot import Autopilot
from sitl.copter.mission_store import Home, MissionStore
from sitl.copter.navigation import Navigator
from sitl.copter.params import ParamStore, ardupilot_params
from sitl.copter.rigid_body import RigidBodyState, initial_state
from sitl.copter.sensors import NedSensors
from sitl.copter.vehicle import VehicleParams
from sitl.copter.world import World

__all__ = ["Simulation", "InitialConditions"]


@dataclass(frozen=True)
class InitialConditions:
    """Where and how the vehicle starts (at rest).

    ``altitude_m`` above home (0 = on the ground); Euler angles in degrees (a
    vehicle on the ground with a tilt rests on a slope).
    """

    altitude_m: float = 0.0
    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    yaw_deg: float = 0.0

    def __post_init__(self) -> None:
        for name in ("altitude_m", "roll_deg", "pitch_deg", "yaw_deg"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"initial {name} must be finite, got {getattr(self, name)!r}")
        if self.altitude_m < 0.0:
            raise ValueError(f"initial altitude_m must be >= 0, got {self.altitude_m!r}")

    def state(self) -> RigidBodyState:
        """The rigid-body state."""
        return initial_state(self.altitude_m, math.radians(self.roll_deg), math.radians(self.pitch_deg),
                             math.radians(self.yaw_deg))


class Simulation:
    """World + sensors + autopilot of one vehicle.

    Parameters
    ----------
    vehicle : VehicleParams
    seed : int
        Base seed of the random streams.
    wind : WindParams or None
        None = calm.
    initial : InitialConditions or None
    params : mapping, optional
        ArduPilot parameter overrides (name -> value).
    loop_rate_hz : int
        Inner-loop (tick) rate; 1e9 / rate must be an integer number of ns.
    max_substep_s : float
        Largest physics step.
    prearm_delay_s : float
        Simulated time after boot before arming is allowed (0 = at once).
    emulate : {"arducopter"} or None
        Fly ArduCopter's own inner loop, motors and start-up (:mod:`sitl.copter.ardupilot_emulation`;
        its parameter table) instead of the built-in autopilot.
    ekf_ready_s : float or None
        With ``emulate``: when the emulated EKF is ready [s after boot] (default: as measured, ~41.6 s).
    """

    def __init__(self, vehicle: VehicleParams, *, seed: int = 0, wind: WindParams | None = None,
                 initial: InitialConditions | None = None, params: Mapping[str, float] | None = None,
                 loop_rate_hz: int = 400, max_substep_s: float = 0.001, prearm_delay_s: float = 0.0,
                 emulate: str | None = None, ekf_ready_s: float | None = None) -> None:
        if loop_rate_hz <= 0 or 1_000_000_000 % loop_rate_hz:
            raise ValueError(f"loop_rate_hz must divide 1e9 ns exactly, got {loop_rate_hz!r}")
        self.vehicle = vehicle
        self.seed = seed
        self.tick_ns = 1_000_000_000 // loop_rate_hz
        self.dt_s = self.tick_ns * 1e-9
        if emulate not in (None, *EMULATIONS):
            raise ValueError(f"emulate must be one of {EMULATIONS}, got {emulate!r}")
        self.emulate = emulate
        specs = emulation_params(vehicle) if emulate else ardupilot_params(vehicle)
        self.params = ParamStore(specs, params)
        wind_model = Wind(wind, np.random.default_rng([seed, 1])) if wind is not None else None
        self.initial = initial or InitialConditions()
        # With the emulation, the ground holds the vehicle as ArduPilot's SITL does (ardupilot_emulation.ground).
        self.world = World(vehicle, wind_model, self.initial.state(), max_substep_s,
                           sticky_ground_step if emulate else rigid_body.step)
        self.sensors = NedSensors(vehicle.sensors, np.random.default_rng([seed, 2]))
        if emulate:
            ready = EKF_READY_S if ekf_ready_s is None else ekf_ready_s
            self.autopilot: Autopilot = ArduCopterAutopilot(vehicle, self.params, ready, self.dt_s)
        else:
            self.autopilot = Autopilot(vehicle, self.params, prearm_delay_s)
        # Uploaded by the ground stations (sitl.copter.mission); flown in AUTO; home moved by DO_SET_HOME.
        self.missions = MissionStore()
        h = vehicle.home
        self.home = Home(h.lat_deg, h.lon_deg, h.alt_m)
        self.autopilot.navigator = Navigator(self.params, vehicle.gravity_m_s2, self.missions,
                                             (h.lat_deg, h.lon_deg, h.alt_m), self.home, self.autopilot.say)
        self.time_ns = 0
        k = self.world.kinematics
        # With the emulation, the sensors read ArduPilot SITL's smoothed state, and the estimate is the
        # firmware EKF's: the height late and offset, the attitude tilted, the horizontal state pulled off
        # by the tilt (ardupilot_emulation.ekf).
        self._smoothed = SmoothedSensors(k) if emulate else None
        self._height = EkfHeight(k.d) if emulate else None
        self._tilt = EkfTilt() if emulate else None
        self._horizontal = EkfHorizontal(vehicle.gravity_m_s2) if emulate else None
        self._armed_ns: int | None = None
        self._lifted_off = False
        self._read(k, 0.0)
        self.autopilot.observe(self.imu, self.nav, self.world.battery)

    @property
    def time_s(self) -> float:
        """Simulated time since boot [s]."""
        return self.time_ns * 1e-9

    @property
    def boot_ns(self) -> int:
        """The vehicle's own clock since boot [ns]: the time stamps of its telemetry (``time_boot_ms``,
        ``time_usec``, TIMESYNC).  Simulated time times ``vehicle.faults.clock_rate`` (a drifting
        autopilot clock); the physics, the streams' schedule and the timeouts run on simulated time."""
        rate = self.vehicle.faults.clock_rate
        return self.time_ns if rate == 1.0 else int(self.time_ns * rate)

    def tick(self) -> None:
        """Advance one inner-loop period."""
        cmd = self.autopilot.update(self.time_ns, self.dt_s, self.imu, self.nav, self.world.battery)
        self.world.step(cmd, self.dt_s)
        self.time_ns += self.tick_ns
        self._read(self.world.kinematics, self.dt_s)

    def _read(self, k: Kinematics, dt_s: float) -> None:
        """What the sensors read of the true state ``k`` (NED), ``dt_s`` after the last reading:
        :attr:`imu` and :attr:`nav` (with the emulation, through the firmware EKF's errors)."""
        imu = self.sensors.imu(k)
        if not self.emulate:
            self.imu, self.nav = imu, self.sensors.nav(k)
            return
        if self._armed_ns is None and self.autopilot.armed:
            self._armed_ns = self.time_ns
        since_arm_s = None if self._armed_ns is None else (self.time_ns - self._armed_ns) * 1e-9
        tilt = self._tilt.error_rad(since_arm_s)
        self.imu = EkfTilt.apply(imu, tilt, RATE_OFFSET_RAD_S)
        sensed = self._smoothed.apply(k, dt_s)
        self._lifted_off = self._lifted_off or not self.world.on_ground
        self._horizontal.advance(tilt, dt_s, self._lifted_off)
        self.nav = self._height.apply(self._horizontal.apply(self.sensors.nav(sensed), dt_s), sensed.d, dt_s)
