"""The 6-DOF vehicle's parameters: frozen dataclasses, one per section of a vehicle file, and derived values.

Rotor layout (ArduPilot QUAD/X numbering, FRD body frame, ``d = L/sqrt(2)``)::

    motor 1: front-right (+d, +d), spins CCW
    motor 2: back-left   (-d, -d), spins CCW
    motor 3: front-left  (+d, -d), spins CW
    motor 4: back-right  (-d, +d), spins CW

A rotor of thrust ``T`` at ``(x, y)`` gives the body torque ``(-y T, x T, s k T)``
with ``s = +1`` for CCW rotors (their reaction turns the body clockwise seen
from above, i.e. positive yaw) and ``k = rotors.yaw_moment_m``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from quadrotor.errors import ConfigError
from sitl.copter.faults import FaultParams

__all__ = ["VehicleParams", "RotorParams", "DragParams", "BatteryParams", "SensorParams6", "ControlParams",
           "HomeParams", "FaultParams", "MODELS"]

MODELS = ("rigid_body", "reduced")

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]


@dataclass(frozen=True)
class RotorParams:
    """``[rotors]``: four identical rotors in X configuration.

    Attributes
    ----------
    arm_length_m : float
        Distance from the centre of mass to each rotor axis, L.
    max_thrust_n : float
        Maximum thrust of one rotor.
    min_thrust_n : float
        Lowest thrust of one rotor while armed and flying (ArduPilot's spin-min).
    idle_thrust_n : float
        Thrust of one rotor when armed on the ground (spin-arm); below lift-off.
    time_constant_s : float
        First-order motor/propeller lag, dT/dt = (T_cmd - T) / tau.
    yaw_moment_m : float
        Reaction torque per unit thrust, k [N m / N].
    diameter_m : float
        Propeller diameter (rotor power for the battery model).
    figure_of_merit : float
        Ideal induced power / shaft power, in (0, 1].
    electrical_efficiency : float
        Shaft power / electrical power (motor and ESC), in (0, 1].
    """

    arm_length_m: float
    max_thrust_n: float
    min_thrust_n: float = 0.0
    idle_thrust_n: float = 0.05
    time_constant_s: float = 0.025
    yaw_moment_m: float = 0.016
    diameter_m: float = 0.254
    figure_of_merit: float = 0.65
    electrical_efficiency: float = 0.8


@dataclass(frozen=True)
class DragParams:
    """``[drag]``: air drag, F = -(c_lin + c_quad |v_air|) v_air per axis (NED).

    Attributes
    ----------
    linear_n_per_m_s : float
        Horizontal linear coefficient (the reduced model's ``drag_n_per_m_s``).
    vertical_n_per_m_s : float
        Vertical linear coefficient.
    quadratic_n_per_m2_s2 : float
        Quadratic coefficient (all axes).
    rotational_n_m_s : float
        Rotational damping torque per body rate [N m / (rad/s)].
    """

    linear_n_per_m_s: float = 0.25
    vertical_n_per_m_s: float = 0.25
    quadratic_n_per_m2_s2: float = 0.0
    rotational_n_m_s: float = 0.0


@dataclass(frozen=True)
class BatteryParams:
    """``[battery]``: LiPo pack.

    Attributes
    ----------
    cells : int
        Cells in series.
    capacity_mah : float
        Capacity.
    internal_resistance_ohm : float
        Pack resistance (voltage sag under load).
    initial_charge : float
        State of charge at start, 0..1.
    avionics_current_a : float
        Constant draw of the electronics.
    """

    cells: int = 3
    capacity_mah: float = 3000.0
    internal_resistance_ohm: float = 0.03
    initial_charge: float = 1.0
    avionics_current_a: float = 0.3


@dataclass(frozen=True)
class SensorParams6:
    """``[sensors]``: noise and resolution of the emulated autopilot's sensors.

    Attributes
    ----------
    attitude_noise_std_rad, rate_noise_std_rad_s : float
        IMU attitude (a random rotation about each body axis) and body-rate white noise.
    baro_noise_std_m, baro_resolution_m : float
        Barometric altitude noise and quantisation (MS5611: 0.10 m).
    position_noise_std_m, velocity_noise_std_m_s : float
        Local position / velocity estimate noise (LOCAL_POSITION_NED).
    rangefinder : bool
        Fit a downward rangefinder (sends DISTANCE_SENSOR).
    rangefinder_noise_std_m, rangefinder_resolution_m, rangefinder_max_m : float
        Its noise, resolution (ultrasonic: 0.04 m) and range.
    """

    attitude_noise_std_rad: float = 0.002
    rate_noise_std_rad_s: float = 0.01
    baro_noise_std_m: float = 0.05
    baro_resolution_m: float = 0.10
    position_noise_std_m: float = 0.05
    velocity_noise_std_m_s: float = 0.03
    rangefinder: bool = False
    rangefinder_noise_std_m: float = 0.01
    rangefinder_resolution_m: float = 0.04
    rangefinder_max_m: float = 4.0


@dataclass(frozen=True)
class ControlParams:
    """``[control]``: gains of the emulated autopilot's inner loops (SI units).

    The angle loop gains are the ArduPilot parameters ``ATC_ANG_*_P``; the rest
    are physical here because ArduPilot's rate PIDs output normalised motor
    commands that depend on the airframe.

    Attributes
    ----------
    rate_p_1_s : (float, float, float)
        Rate loop: angular acceleration demand per rate error (roll, pitch, yaw).
    rate_i_1_s2 : (float, float, float)
        Rate loop integral gains.
    rate_imax_rad_s2 : float
        Clamp of the rate integrators (angular acceleration).
    climb_p_1_s, climb_i_1_s2 : float
        Climb-rate loop: vertical acceleration demand per climb-rate error, and integral.
    land_damping_1_s : float
        LAND mode horizontal velocity damping (acceleration per velocity).
    """

    rate_p_1_s: Vec3 = (25.0, 25.0, 10.0)
    rate_i_1_s2: Vec3 = (10.0, 10.0, 2.0)
    rate_imax_rad_s2: float = 20.0
    climb_p_1_s: float = 4.0
    climb_i_1_s2: float = 2.0
    land_damping_1_s: float = 1.0


@dataclass(frozen=True)
class HomeParams:
    """``[home]``: where the vehicle boots (GLOBAL_POSITION_INT, ALTITUDE)."""

    lat_deg: float = -35.363261
    lon_deg: float = 149.165230
    alt_m: float = 584.0


@dataclass(frozen=True)
class VehicleParams:
    """A complete vehicle.

    Attributes
    ----------
    mass_kg : float
    inertia_kg_m2 : 3x3 tuple
        Inertia matrix about the centre of mass in FRD (symmetric, positive definite).
    gravity_m_s2 : float
    model : {"rigid_body", "reduced"}
        Plant used by default (``--model`` overrides).
    faults : FaultParams
        How the simulated vehicle differs from this nominal one (:mod:`sitl.copter.faults`); the
        derived values below and the autopilot are the nominal vehicle's.
    """

    mass_kg: float
    inertia_kg_m2: Mat3
    rotors: RotorParams
    name: str = "vehicle"
    description: str = ""
    gravity_m_s2: float = 9.81
    model: str = "rigid_body"
    drag: DragParams = field(default_factory=DragParams)
    battery: BatteryParams = field(default_factory=BatteryParams)
    sensors: SensorParams6 = field(default_factory=SensorParams6)
    control: ControlParams = field(default_factory=ControlParams)
    home: HomeParams = field(default_factory=HomeParams)
    faults: FaultParams = field(default_factory=FaultParams)
    source: str = "<defaults>"

    # ------------------------------------------------------------ derived values
    @property
    def max_total_thrust_n(self) -> float:
        """Thrust with every rotor at ``max_thrust_n`` (thrust 1.0 in GUID_OPTIONS=8 mode)."""
        return 4.0 * self.rotors.max_thrust_n

    @property
    def hover_thrust_fraction(self) -> float:
        """m g / max total thrust: the default of ``MOT_THST_HOVER``."""
        return self.mass_kg * self.gravity_m_s2 / self.max_total_thrust_n

    @property
    def max_torque_nm(self) -> Vec3:
        """Normalisation of SET_ACTUATOR_CONTROL_TARGET torques (N m at control = 1).

        ``(sqrt(2) L T_max, sqrt(2) L T_max, 2 k T_max)``: the torque of two
        rotors at full thrust against two stopped ones.
        """
        r = self.rotors
        t = math.sqrt(2.0) * r.arm_length_m * r.max_thrust_n
        return (t, t, 2.0 * r.yaw_moment_m * r.max_thrust_n)

    @property
    def inertia_diagonal(self) -> Vec3:
        """(Ixx, Iyy, Izz) [kg m^2]."""
        j = self.inertia_kg_m2
        return (j[0][0], j[1][1], j[2][2])

    def with_model(self, model: str) -> VehicleParams:
        """Copy with another plant model."""
        if model not in MODELS:
            raise ConfigError(self.source, "vehicle.model", f"must be one of {MODELS}, got {model!r}")
        return replace(self, model=model)
