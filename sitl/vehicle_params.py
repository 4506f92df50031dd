"""Vehicle parameters of the 6-DOF SITL: frozen dataclasses and a strict TOML loader.

A vehicle file (``configs/vehicles/*.toml``, shipped as the package
``sitl.vehicles``) has the sections ``[vehicle]``, ``[rotors]``, ``[drag]``,
``[battery]``, ``[sensors]``, ``[control]`` and ``[home]``; every key is
optional except ``vehicle.mass_kg``, ``vehicle.inertia_kg_m2`` and the
``[rotors]`` geometry/limits.  Unknown sections or keys, wrong types and out
of range values are rejected with a :class:`~sitl.errors.ConfigError`
naming the file, the key and the reason.

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
import tomllib
from dataclasses import dataclass, field, fields, replace
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

from quadrotor.bounds import (ATTITUDE_NOISE_RAD, DRAG_N_PER_M_S, GRAVITY_M_S2, INERTIA_KG_M2, MASS_KG, NOISE_M,
                              RATE_NOISE_RAD_S, Bound, OutOfBounds, short_repr)
from quadrotor.errors import ConfigError

__all__ = [
    "VehicleParams", "RotorParams", "DragParams", "BatteryParams", "SensorParams6", "ControlParams",
    "HomeParams", "MODELS", "load_vehicle", "parse_vehicle", "bundled_vehicles", "DEFAULT_VEHICLE",
    "VEHICLE_BOUNDS",
]

MODELS = ("rigid_body", "reduced")
DEFAULT_VEHICLE = "quad-1kg"

# (x, y, spin) of the rotors, in units of d = L / sqrt(2); spin +1 = CCW.
ROTOR_LAYOUT_X = ((1.0, 1.0, 1.0), (-1.0, -1.0, 1.0), (1.0, -1.0, -1.0), (-1.0, 1.0, -1.0))

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

    def rotor_positions(self) -> tuple[tuple[float, float, float], ...]:
        """``(x_m, y_m, spin)`` of motors 1..4 (see the module docstring)."""
        d = self.rotors.arm_length_m / math.sqrt(2.0)
        return tuple((sx * d, sy * d, s) for sx, sy, s in ROTOR_LAYOUT_X)

    def with_model(self, model: str) -> "VehicleParams":
        """Copy with another plant model."""
        if model not in MODELS:
            raise ConfigError(self.source, "vehicle.model", f"must be one of {MODELS}, got {model!r}")
        return replace(self, model=model)


# --------------------------------------------------------------------------- ranges

_NOISE_M = NOISE_M
_GAIN = Bound(0.0, 1000.0, "1/s", "an inner-loop gain of the 400 Hz autopilot")
_IGAIN = Bound(0.0, 1e4, "1/s^2", "an integral gain")
_THRUST = Bound(0.0, 1e4, "N", "one rotor's thrust")
_DRAG = DRAG_N_PER_M_S

#: Allowed range of every number of a vehicle file, by key (``section.key``; vectors element by element).
VEHICLE_BOUNDS: dict[str, Bound] = {
    "vehicle.mass_kg": MASS_KG,
    "vehicle.gravity_m_s2": GRAVITY_M_S2,
    "vehicle.inertia_kg_m2": INERTIA_KG_M2,
    "rotors.arm_length_m": Bound(0.01, 5.0, "m", "centre to rotor axis"),
    "rotors.max_thrust_n": Bound(0.01, 1e4, "N", "one rotor's thrust"),
    "rotors.min_thrust_n": _THRUST, "rotors.idle_thrust_n": _THRUST,
    "rotors.time_constant_s": Bound(1e-3, 2.0, "s", "motor and propeller lag"),
    "rotors.yaw_moment_m": Bound(1e-4, 1.0, "m", "reaction torque per thrust"),
    "rotors.diameter_m": Bound(0.01, 5.0, "m", "propeller diameter"),
    "rotors.figure_of_merit": Bound(0.05, 1.0, "", "ideal over shaft power"),
    "rotors.electrical_efficiency": Bound(0.05, 1.0, "", "shaft over electrical power"),
    "drag.linear_n_per_m_s": _DRAG, "drag.vertical_n_per_m_s": _DRAG,
    "drag.quadratic_n_per_m2_s2": Bound(0.0, 10.0, "N/(m/s)^2", "quadratic air drag"),
    "drag.rotational_n_m_s": Bound(0.0, 10.0, "N m/(rad/s)", "rotational damping"),
    "battery.cells": Bound(1, 23, "cells", "at most 100 V at 4.2 V a cell", integer=True),
    "battery.capacity_mah": Bound(10.0, 1e6, "mAh", "the range of BATT_CAPACITY"),
    "battery.internal_resistance_ohm": Bound(0.0, 10.0, "ohm", "pack resistance"),
    "battery.initial_charge": Bound(0.0, 1.0, "", "state of charge"),
    "battery.avionics_current_a": Bound(0.0, 100.0, "A", "electronics draw"),
    "sensors.attitude_noise_std_rad": ATTITUDE_NOISE_RAD,
    "sensors.rate_noise_std_rad_s": RATE_NOISE_RAD_S,
    "sensors.baro_noise_std_m": _NOISE_M, "sensors.baro_resolution_m": _NOISE_M,
    "sensors.position_noise_std_m": _NOISE_M,
    "sensors.velocity_noise_std_m_s": Bound(0.0, 10.0, "m/s", "velocity noise; 0 = none"),
    "sensors.rangefinder_noise_std_m": _NOISE_M, "sensors.rangefinder_resolution_m": _NOISE_M,
    "sensors.rangefinder_max_m": Bound(0.1, 1000.0, "m", "rangefinder range"),
    "control.rate_p_1_s": _GAIN, "control.rate_i_1_s2": _IGAIN,
    "control.rate_imax_rad_s2": Bound(0.0, 1e4, "rad/s^2", "rate integrator clamp"),
    "control.climb_p_1_s": _GAIN, "control.climb_i_1_s2": _IGAIN, "control.land_damping_1_s": _GAIN,
    "home.lat_deg": Bound(-90.0, 90.0, "deg", "latitude"),
    "home.lon_deg": Bound(-180.0, 180.0, "deg", "longitude"),
    "home.alt_m": Bound(-500.0, 1e4, "m", "altitude above mean sea level"),
}
_INERTIA_ENTRY = Bound(-1e3, 1e3, "kg m^2", "an entry of the inertia matrix")
#: Fastest physical rates the 1 ms physics step integrates stably: drag and damping time constants
#: of at least 2 ms, angular accelerations (max torque / inertia) up to 1e5 rad/s^2.
MAX_DAMPING_1_S = 500.0
MAX_ANGULAR_ACCEL_RAD_S2 = 1e5


# --------------------------------------------------------------------------- loader

_SECTIONS = {
    "vehicle": None, "rotors": RotorParams, "drag": DragParams, "battery": BatteryParams,
    "sensors": SensorParams6, "control": ControlParams, "home": HomeParams,
}
_VEHICLE_KEYS = ("name", "description", "model", "mass_kg", "gravity_m_s2", "inertia_kg_m2")
_REQUIRED = {"vehicle": ("mass_kg", "inertia_kg_m2"), "rotors": ("arm_length_m", "max_thrust_n")}
_BOOLEANS = ("sensors.rangefinder",)
_VECTORS = ("control.rate_p_1_s", "control.rate_i_1_s2")


def _check(source: str, key: str, value: Any) -> Any:
    """``value`` of ``key`` checked against :data:`VEHICLE_BOUNDS` (booleans and 3-vectors too)."""
    if key in _BOOLEANS:
        if not isinstance(value, bool):
            raise ConfigError(source, key, f"must be true or false, got {short_repr(value)}")
        return value
    bound = VEHICLE_BOUNDS[key]
    try:
        if key in _VECTORS:
            if not (isinstance(value, list) and len(value) == 3):
                raise OutOfBounds(f"must be a list of 3 numbers (roll, pitch, yaw), got {short_repr(value)}; "
                                  f"{bound.describe()}")
            return tuple(bound.check(v) for v in value)
        return bound.check(value)
    except OutOfBounds as exc:
        raise ConfigError(source, key, str(exc)) from None


def _inertia(source: str, value: Any) -> Mat3:
    key = "vehicle.inertia_kg_m2"
    try:
        if isinstance(value, list) and len(value) == 3 and not any(isinstance(v, list) for v in value):
            d = [_INERTIA_ENTRY.check(v) for v in value]
            rows = [[d[0], 0.0, 0.0], [0.0, d[1], 0.0], [0.0, 0.0, d[2]]]
        elif isinstance(value, list) and len(value) == 3 and all(isinstance(r, list) and len(r) == 3 for r in value):
            rows = [[_INERTIA_ENTRY.check(v) for v in r] for r in value]
        else:
            raise OutOfBounds("must be 3 numbers (diagonal) or 3 rows of 3 numbers")
        for i in range(3):
            for j in range(i + 1, 3):
                if abs(rows[i][j] - rows[j][i]) > 1e-12 * max(1.0, abs(rows[i][j])):
                    raise OutOfBounds(f"not symmetric ([{i}][{j}] = {rows[i][j]} != [{j}][{i}] = {rows[j][i]})")
        a, b, c = rows[0][0], rows[1][1], rows[2][2]
        m2 = a * b - rows[0][1] * rows[1][0]
        det = (a * (b * c - rows[1][2] * rows[2][1]) - rows[0][1] * (rows[1][0] * c - rows[1][2] * rows[2][0])
               + rows[0][2] * (rows[1][0] * rows[2][1] - b * rows[2][0]))
        if not (a > 0 and m2 > 0 and det > 0):
            raise OutOfBounds("not positive definite")
        for i in range(3):
            VEHICLE_BOUNDS[key].check(rows[i][i])
    except OutOfBounds as exc:
        raise ConfigError(source, key, str(exc)) from None
    return tuple(tuple(r) for r in rows)  # type: ignore[return-value]


def _check_rates(params: VehicleParams) -> None:
    """Cross-checks: rotor thrusts, lift margin, and rates the physics step integrates stably."""
    source, r, dr = params.source, params.rotors, params.drag
    for k in ("min_thrust_n", "idle_thrust_n"):
        if getattr(r, k) >= r.max_thrust_n:
            raise ConfigError(source, f"rotors.{k}", f"must be below max_thrust_n ({r.max_thrust_n})")
    if params.hover_thrust_fraction >= 0.9:
        raise ConfigError(source, "rotors.max_thrust_n",
                                 f"4 x {r.max_thrust_n} N cannot lift {params.mass_kg} kg with margin "
                                 f"(hover at {params.hover_thrust_fraction:.2f} of full thrust)")
    least_inertia = min(params.inertia_diagonal)
    for key, rate in (("drag.linear_n_per_m_s", dr.linear_n_per_m_s / params.mass_kg),
                      ("drag.vertical_n_per_m_s", dr.vertical_n_per_m_s / params.mass_kg),
                      ("drag.rotational_n_m_s", dr.rotational_n_m_s / least_inertia)):
        if rate > MAX_DAMPING_1_S:
            raise ConfigError(source, key, f"damps at {rate:g} 1/s for this mass and inertia: at most "
                                                  f"{MAX_DAMPING_1_S:g} 1/s (a 2 ms time constant) integrates stably")
    accel = max(t / i for t, i in zip(params.max_torque_nm, params.inertia_diagonal, strict=True))
    if accel > MAX_ANGULAR_ACCEL_RAD_S2:
        raise ConfigError(source, "vehicle.inertia_kg_m2",
                                 f"max torque / inertia = {accel:.3g} rad/s^2: at most {MAX_ANGULAR_ACCEL_RAD_S2:g} "
                                 f"rad/s^2 is physical (inertia too small for the rotors)")


def parse_vehicle(data: Mapping[str, Any], source: str = "<vehicle>") -> VehicleParams:
    """Validate a parsed vehicle TOML document.

    Every number must be finite and in its range of :data:`VEHICLE_BOUNDS`.

    Parameters
    ----------
    data : mapping
        The TOML document (``tomllib.load`` result).
    source : str
        Name used in error messages (the file path).

    Returns
    -------
    VehicleParams

    Raises
    ------
    ConfigError
        Naming ``source``, the offending key and the reason (with the allowed range).
    """
    if not isinstance(data, Mapping):
        raise ConfigError(source, "", f"must be a table, got {short_repr(data)}")
    for section, value in data.items():
        if section not in _SECTIONS:
            raise ConfigError(source, str(section), f"unknown section (known: {', '.join(_SECTIONS)})")
        if not isinstance(value, dict):
            raise ConfigError(source, section, "must be a table")
    for section, keys in _REQUIRED.items():
        for k in keys:
            if k not in data.get(section, {}):
                raise ConfigError(source, f"{section}.{k}", "missing")
    built: dict[str, Any] = {}
    for section, cls in _SECTIONS.items():
        table = dict(data.get(section, {}))
        allowed = _VEHICLE_KEYS if cls is None else tuple(f.name for f in fields(cls))
        for k in table:
            if k not in allowed:
                raise ConfigError(source, f"{section}.{k}", f"unknown key (known: {', '.join(allowed)})")
        if cls is None:
            continue
        kwargs = {k: _check(source, f"{section}.{k}", v) for k, v in table.items()}
        built[section] = cls(**kwargs)
    v = data.get("vehicle", {})
    kwargs: dict[str, Any] = {}
    for k in ("name", "description"):
        if k in v:
            if not isinstance(v[k], str):
                raise ConfigError(source, f"vehicle.{k}", f"must be a string, got {short_repr(v[k])}")
            kwargs[k] = v[k]
    if "model" in v:
        if not isinstance(v["model"], str) or v["model"] not in MODELS:
            raise ConfigError(source, "vehicle.model", f"must be one of {MODELS}, got {short_repr(v['model'])}")
        kwargs["model"] = v["model"]
    for k in ("mass_kg", "gravity_m_s2"):
        if k in v:
            kwargs[k] = _check(source, f"vehicle.{k}", v[k])
    kwargs["inertia_kg_m2"] = _inertia(source, v["inertia_kg_m2"])
    params = VehicleParams(source=source, **kwargs, **built)
    _check_rates(params)
    return params


def bundled_vehicles() -> list[str]:
    """Names of the vehicle files shipped in ``sitl.vehicles``."""
    root = resources.files("sitl.vehicles")
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml"))


def load_vehicle(name_or_path: str | Path | None = None) -> VehicleParams:
    """Load a vehicle by bundled name (``"quad-1kg"``) or TOML path.

    Raises
    ------
    ConfigError
        Unknown name, unreadable file, bad TOML (nesting too deep included) or invalid values.
    """
    spec = DEFAULT_VEHICLE if name_or_path is None else str(name_or_path)
    path = Path(spec)
    if path.is_file():
        source = str(path)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise ConfigError(source, "", f"cannot read ({exc.strerror})") from None
        except UnicodeDecodeError as exc:
            raise ConfigError(source, "", f"invalid TOML (not UTF-8: {exc.reason})") from None
    else:
        stem = spec[:-5] if spec.endswith(".toml") else spec
        if "/" in spec or "\\" in spec or stem not in bundled_vehicles():
            raise ConfigError(spec, "", f"no such vehicle file or bundled vehicle "
                                               f"(bundled: {', '.join(bundled_vehicles())})")
        res = resources.files("sitl.vehicles") / f"{stem}.toml"
        source = f"sitl.vehicles/{stem}.toml"
        text = res.read_text(encoding="utf-8")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(source, "", f"invalid TOML ({exc})") from None
    except RecursionError:
        raise ConfigError(source, "", "invalid TOML (arrays or tables nested too deeply)") from None
    return parse_vehicle(data, source)
