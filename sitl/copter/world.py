"""The simulated world of one vehicle: plant (6-DOF or reduced), motors, wind and battery.

Two plants share one interface (:class:`RigidBodyPlant`, :class:`ReducedPlant`):
``step(rotor_cmd_n, dt, wind_ned)`` and the NED :class:`~quadrotor.frames.Kinematics`
they expose.  Both take rotor thrust commands, so the autopilot, mixer and
motor lag are the same whichever plant flies; the reduced plant turns the
lagged rotor thrusts into the paper's inputs (collective thrust [N] and
angular accelerations ``tau / I`` [rad/s^2]) and its state into NED through
:func:`quadrotor.frames.ned_from_paper` (the one conversion).  Both fly the true vehicle of
``vehicle.faults`` (:mod:`sitl.copter.faults`): scaled mass, inertia and motor thrusts, moved centre
of mass.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from quadrotor import plant as reduced
from quadrotor.frames import Kinematics, ned_from_paper, ned_wind_from_paper, paper_from_ned
from quadrotor.state import State
from quadrotor.wind import Wind
from sitl.copter import battery as batt
from sitl.copter import rigid_body
from sitl.copter.faults import true_inertia, true_mass_kg
from sitl.copter.rigid_body import RigidBodyModel, RigidBodyState, rotor_wrench
from sitl.copter.vehicle import VehicleParams

__all__ = ["RigidBodyPlant", "ReducedPlant", "World", "make_plant"]

_CALM = (0.0, 0.0, 0.0)


class RigidBodyPlant:
    """The 6-DOF plant (:mod:`sitl.copter.rigid_body`).

    Parameters
    ----------
    vehicle : VehicleParams
    initial : RigidBodyState
    max_substep_s : float
        Largest physics step; a call of :meth:`step` is split evenly.
    step_fn : callable
        The physics step, :func:`sitl.copter.rigid_body.step` or one of its signature with another
        ground contact (the ArduCopter emulation's:
        :func:`sitl.copter.ardupilot_emulation.ground.sticky_ground_step`).
    """

    def __init__(self, vehicle: VehicleParams, initial: RigidBodyState, max_substep_s: float = 0.001,
                 step_fn=rigid_body.step) -> None:
        self.model = RigidBodyModel(vehicle)
        self.state = initial
        self.max_substep_s = max_substep_s
        self.step_fn = step_fn
        self._split = (-1.0, 1, 0.0)

    def step(self, rotor_cmd_n: Sequence[float], dt: float, wind_ned: Sequence[float] = _CALM) -> None:
        """Advance ``dt`` seconds with the rotor commands [N] and wind [m/s, NED] held."""
        last_dt, n, h = self._split
        if dt != last_dt:
            n = max(1, math.ceil(dt / self.max_substep_s - 1e-9))
            h = dt / n
            self._split = (dt, n, h)
        s = self.state
        f = self.step_fn
        m = self.model
        for _ in range(n):
            s = f(s, rotor_cmd_n, h, m, wind_ned)
        self.state = s

    @property
    def kinematics(self) -> Kinematics:
        return tuple.__new__(Kinematics, self.state[:13])

    @property
    def rotor_thrusts(self) -> tuple[float, float, float, float]:
        s = self.state
        return (s.t1, s.t2, s.t3, s.t4)

    @property
    def on_ground(self) -> bool:
        return bool(self.state.on_ground)


class ReducedPlant:
    """The paper's reduced plant (:mod:`quadrotor.plant`, z up) behind the NED interface.

    The motors (first-order lag, clipped to ``[0, max_thrust_n]``) are
    integrated here; the plant receives ``(sum T_i, tau_x / Ixx, tau_y / Iyy,
    tau_z / Izz)`` (true mass and inertia diagonal; the rotor thrusts are the commands times the
    motor scales, the torques about the moved centre of mass).  The initial attitude must be level on
    the ground (the reduced plant levels a grounded vehicle).
    """

    def __init__(self, vehicle: VehicleParams, initial: RigidBodyState, max_substep_s: float = 0.001) -> None:
        self.vehicle = vehicle
        j = true_inertia(vehicle)
        inertia = (j[0][0], j[1][1], j[2][2])
        self._inv_i = (1.0 / inertia[0], 1.0 / inertia[1], 1.0 / inertia[2])
        f = vehicle.faults
        self._scale = f.motor_scale
        capacity = sum(f.motor_scale) * vehicle.rotors.max_thrust_n
        moment = max(abs(c) for c in f.com_offset_m[:2]) * capacity
        amax = max((max(f.motor_scale) * t + moment) / i
                   for t, i in zip(vehicle.max_torque_nm, inertia, strict=True))
        self.params = reduced.ReducedParams(
            mass_kg=true_mass_kg(vehicle), gravity_m_s2=vehicle.gravity_m_s2, max_thrust_n=capacity,
            max_angular_accel_rad_s2=1.01 * amax, drag_n_per_m_s=vehicle.drag.linear_n_per_m_s,
            max_substep_s=max_substep_s)
        self.state = State(*paper_from_ned(initial.kinematics()))
        self._thrusts = [initial.t1, initial.t2, initial.t3, initial.t4]
        self._tau = vehicle.rotors.time_constant_s
        self._tmax = vehicle.rotors.max_thrust_n
        self._kin = ned_from_paper(self.state)

    def step(self, rotor_cmd_n: Sequence[float], dt: float, wind_ned: Sequence[float] = _CALM) -> None:
        """Advance ``dt`` seconds (motors exact over ``dt``, then the plant with their mean wrench)."""
        a = 1.0 - math.exp(-dt / self._tau)
        old = self._thrusts
        new = []
        for t, c, s in zip(old, rotor_cmd_n, self._scale, strict=True):
            c = s * (0.0 if c < 0.0 else self._tmax if c > self._tmax else c)
            new.append(t + a * (c - t))
        mean = [0.5 * (x + y) for x, y in zip(old, new, strict=True)]
        f, tx, ty, tz = rotor_wrench(mean, self.vehicle)
        ix, iy, iz = self._inv_i
        wind_paper = (wind_ned[0], wind_ned[1], -wind_ned[2])
        self.state = reduced.step(self.state, (f, tx * ix, ty * iy, tz * iz), dt, self.params, wind_paper)
        self._thrusts = new
        self._kin = ned_from_paper(self.state)

    @property
    def kinematics(self) -> Kinematics:
        return self._kin

    @property
    def rotor_thrusts(self) -> tuple[float, float, float, float]:
        t = self._thrusts
        return (t[0], t[1], t[2], t[3])

    @property
    def on_ground(self) -> bool:
        return self.state.z <= 0.0 and self.state.vz <= 0.0


def make_plant(vehicle: VehicleParams, initial: RigidBodyState, max_substep_s: float = 0.001,
               step_fn=rigid_body.step):
    """The plant selected by ``vehicle.model``; ``step_fn`` is the 6-DOF plant's physics step (the
    reduced plant keeps its own ground contact)."""
    if vehicle.model == "reduced":
        return ReducedPlant(vehicle, initial, max_substep_s)
    return RigidBodyPlant(vehicle, initial, max_substep_s, step_fn)


class World:
    """Plant, wind and battery of one vehicle, advanced together.

    Parameters
    ----------
    vehicle : VehicleParams
    wind : Wind or None
        Seeded wind (paper frame; converted to NED here); None = calm.
    initial : RigidBodyState or None
        Initial state (default: at rest on the ground at home).
    max_substep_s : float
        Largest physics step.
    step_fn : callable
        The 6-DOF plant's physics step (see :class:`RigidBodyPlant`).
    """

    def __init__(self, vehicle: VehicleParams, wind: Wind | None = None, initial: RigidBodyState | None = None,
                 max_substep_s: float = 0.001, step_fn=rigid_body.step) -> None:
        self.vehicle = vehicle
        self.plant = make_plant(vehicle, initial or RigidBodyState(), max_substep_s, step_fn)
        self.wind = wind
        self.wind_ned: tuple[float, float, float] = _CALM
        self.battery = batt.initial_battery(vehicle.battery)
        self._bparams = vehicle.battery
        self._power_k = batt.power_coefficient(vehicle.rotors)
        #: True NED kinematics (updated by :meth:`step`).
        self.kinematics: Kinematics = self.plant.kinematics

    def step(self, rotor_cmd_n: Sequence[float], dt: float) -> None:
        """Advance ``dt`` seconds with the rotor commands [N] held (wind sampled once per call)."""
        if self.wind is not None:
            self.wind_ned = ned_wind_from_paper(self.wind.sample(dt))
        plant = self.plant
        plant.step(rotor_cmd_n, dt, self.wind_ned)
        self.kinematics = plant.kinematics
        t1, t2, t3, t4 = plant.rotor_thrusts
        power = self._power_k * (t1 * math.sqrt(t1) + t2 * math.sqrt(t2) + t3 * math.sqrt(t3) + t4 * math.sqrt(t4))
        self.battery = batt.step(self.battery, power, dt, self._bparams)

    @property
    def on_ground(self) -> bool:
        """Resting on the ground."""
        return self.plant.on_ground
