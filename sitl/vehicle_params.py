"""Vehicle parameters of the 6-DOF SITL: frozen dataclasses and a strict TOML loader.

A vehicle file (``configs/vehicles/*.toml``, shipped as the package
``sitl.vehicles``) has the sections ``[vehicle]``, ``[rotors]``, ``[drag]``,
``[battery]``, ``[sensors]``, ``[control]`` and ``[home]``; every key is
optional except ``vehicle.mass_kg``, ``vehicle.inertia_kg_m2`` and the
``[rotors]`` geometry/limits.  Unknown sections or keys, wrong types and out
of range values are rejected with a :class:`~sitl.errors.VehicleConfigError`
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

from sitl.errors import VehicleConfigError

__all__ = [
    "VehicleParams", "RotorParams", "DragParams", "BatteryParams", "SensorParams6", "ControlParams",
    "HomeParams", "MODELS", "load_vehicle", "parse_vehicle", "bundled_vehicles", "DEFAULT_VEHICLE",
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
            raise VehicleConfigError(self.source, "vehicle.model", f"must be one of {MODELS}, got {model!r}")
        return replace(self, model=model)


# --------------------------------------------------------------------------- loader

_SECTIONS = {
    "vehicle": None, "rotors": RotorParams, "drag": DragParams, "battery": BatteryParams,
    "sensors": SensorParams6, "control": ControlParams, "home": HomeParams,
}
_VEHICLE_KEYS = ("name", "description", "model", "mass_kg", "gravity_m_s2", "inertia_kg_m2")
_REQUIRED = {"vehicle": ("mass_kg", "inertia_kg_m2"), "rotors": ("arm_length_m", "max_thrust_n")}

# key -> check: "pos" (> 0), "nonneg" (>= 0), "frac" (0..1], "unit" ([0, 1]), "any", "int_pos", "bool", "vec3_nonneg"
_CHECKS: dict[str, str] = {
    "mass_kg": "pos", "gravity_m_s2": "pos",
    "arm_length_m": "pos", "max_thrust_n": "pos", "min_thrust_n": "nonneg", "idle_thrust_n": "nonneg",
    "time_constant_s": "pos", "yaw_moment_m": "pos", "diameter_m": "pos", "figure_of_merit": "frac",
    "electrical_efficiency": "frac",
    "linear_n_per_m_s": "nonneg", "vertical_n_per_m_s": "nonneg", "quadratic_n_per_m2_s2": "nonneg",
    "rotational_n_m_s": "nonneg",
    "cells": "int_pos", "capacity_mah": "pos", "internal_resistance_ohm": "nonneg", "initial_charge": "unit",
    "avionics_current_a": "nonneg",
    "attitude_noise_std_rad": "nonneg", "rate_noise_std_rad_s": "nonneg", "baro_noise_std_m": "nonneg",
    "baro_resolution_m": "nonneg", "position_noise_std_m": "nonneg", "velocity_noise_std_m_s": "nonneg",
    "rangefinder": "bool", "rangefinder_noise_std_m": "nonneg", "rangefinder_resolution_m": "nonneg",
    "rangefinder_max_m": "pos",
    "rate_p_1_s": "vec3_nonneg", "rate_i_1_s2": "vec3_nonneg", "rate_imax_rad_s2": "nonneg",
    "climb_p_1_s": "nonneg", "climb_i_1_s2": "nonneg", "land_damping_1_s": "nonneg",
    "lat_deg": "lat", "lon_deg": "lon", "alt_m": "any",
}


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _check(source: str, key: str, name: str, value: Any) -> Any:
    kind = _CHECKS[name]
    fail = lambda reason: VehicleConfigError(source, key, reason)  # noqa: E731
    if kind == "bool":
        if not isinstance(value, bool):
            raise fail(f"must be true or false, got {value!r}")
        return value
    if kind == "int_pos":
        if not isinstance(value, int) or isinstance(value, bool) or value < 1:
            raise fail(f"must be a positive integer, got {value!r}")
        return value
    if kind == "vec3_nonneg":
        if not (isinstance(value, list) and len(value) == 3 and all(_is_number(v) for v in value)):
            raise fail(f"must be a list of 3 numbers, got {value!r}")
        vec = tuple(float(v) for v in value)
        if not all(math.isfinite(v) and v >= 0 for v in vec):
            raise fail(f"must be finite and >= 0, got {value!r}")
        return vec
    if not _is_number(value):
        raise fail(f"must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise fail(f"must be finite, got {value!r}")
    if kind == "pos" and not v > 0:
        raise fail(f"must be > 0, got {value!r}")
    if kind == "nonneg" and v < 0:
        raise fail(f"must be >= 0, got {value!r}")
    if kind == "frac" and not 0 < v <= 1:
        raise fail(f"must be in (0, 1], got {value!r}")
    if kind == "unit" and not 0 <= v <= 1:
        raise fail(f"must be in [0, 1], got {value!r}")
    if kind == "lat" and not -90 <= v <= 90:
        raise fail(f"must be in [-90, 90], got {value!r}")
    if kind == "lon" and not -180 <= v <= 180:
        raise fail(f"must be in [-180, 180], got {value!r}")
    return v


def _inertia(source: str, value: Any) -> Mat3:
    key = "vehicle.inertia_kg_m2"
    if isinstance(value, list) and len(value) == 3 and all(_is_number(v) for v in value):
        rows = [[float(value[0]), 0.0, 0.0], [0.0, float(value[1]), 0.0], [0.0, 0.0, float(value[2])]]
    elif (isinstance(value, list) and len(value) == 3
          and all(isinstance(r, list) and len(r) == 3 and all(_is_number(v) for v in r) for r in value)):
        rows = [[float(v) for v in r] for r in value]
    else:
        raise VehicleConfigError(source, key, "must be 3 numbers (diagonal) or 3 rows of 3 numbers")
    if not all(math.isfinite(v) for r in rows for v in r):
        raise VehicleConfigError(source, key, "must be finite")
    for i in range(3):
        for j in range(i + 1, 3):
            if abs(rows[i][j] - rows[j][i]) > 1e-12 * max(1.0, abs(rows[i][j])):
                raise VehicleConfigError(source, key,
                                         f"not symmetric ([{i}][{j}] = {rows[i][j]} != [{j}][{i}] = {rows[j][i]})")
    a, b, c = rows[0][0], rows[1][1], rows[2][2]
    m2 = a * b - rows[0][1] * rows[1][0]
    det = (a * (b * c - rows[1][2] * rows[2][1]) - rows[0][1] * (rows[1][0] * c - rows[1][2] * rows[2][0])
           + rows[0][2] * (rows[1][0] * rows[2][1] - b * rows[2][0]))
    if not (a > 0 and m2 > 0 and det > 0):
        raise VehicleConfigError(source, key, "not positive definite")
    return tuple(tuple(r) for r in rows)  # type: ignore[return-value]


def parse_vehicle(data: Mapping[str, Any], source: str = "<vehicle>") -> VehicleParams:
    """Validate a parsed vehicle TOML document.

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
    VehicleConfigError
        Naming ``source``, the offending key and the reason.
    """
    for section, value in data.items():
        if section not in _SECTIONS:
            raise VehicleConfigError(source, section, f"unknown section (known: {', '.join(_SECTIONS)})")
        if not isinstance(value, dict):
            raise VehicleConfigError(source, section, "must be a table")
    for section, keys in _REQUIRED.items():
        for k in keys:
            if k not in data.get(section, {}):
                raise VehicleConfigError(source, f"{section}.{k}", "missing")
    built: dict[str, Any] = {}
    for section, cls in _SECTIONS.items():
        table = dict(data.get(section, {}))
        allowed = _VEHICLE_KEYS if cls is None else tuple(f.name for f in fields(cls))
        for k in table:
            if k not in allowed:
                raise VehicleConfigError(source, f"{section}.{k}", f"unknown key (known: {', '.join(allowed)})")
        if cls is None:
            continue
        kwargs = {k: _check(source, f"{section}.{k}", k, v) for k, v in table.items()}
        built[section] = cls(**kwargs)
    v = data.get("vehicle", {})
    kwargs: dict[str, Any] = {}
    for k in ("name", "description"):
        if k in v:
            if not isinstance(v[k], str):
                raise VehicleConfigError(source, f"vehicle.{k}", f"must be a string, got {v[k]!r}")
            kwargs[k] = v[k]
    if "model" in v:
        if v["model"] not in MODELS:
            raise VehicleConfigError(source, "vehicle.model", f"must be one of {MODELS}, got {v['model']!r}")
        kwargs["model"] = v["model"]
    for k in ("mass_kg", "gravity_m_s2"):
        if k in v:
            kwargs[k] = _check(source, f"vehicle.{k}", k, v[k])
    kwargs["inertia_kg_m2"] = _inertia(source, v["inertia_kg_m2"])
    r: RotorParams = built["rotors"]
    if r.min_thrust_n >= r.max_thrust_n:
        raise VehicleConfigError(source, "rotors.min_thrust_n", f"must be below max_thrust_n ({r.max_thrust_n})")
    if r.idle_thrust_n >= r.max_thrust_n:
        raise VehicleConfigError(source, "rotors.idle_thrust_n", f"must be below max_thrust_n ({r.max_thrust_n})")
    params = VehicleParams(source=source, **kwargs, **built)
    if params.hover_thrust_fraction >= 0.9:
        raise VehicleConfigError(source, "rotors.max_thrust_n",
                                 f"4 x {r.max_thrust_n} N cannot lift {params.mass_kg} kg with margin "
                                 f"(hover at {params.hover_thrust_fraction:.2f} of full thrust)")
    return params


def bundled_vehicles() -> list[str]:
    """Names of the vehicle files shipped in ``sitl.vehicles``."""
    root = resources.files("sitl.vehicles")
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml"))


def load_vehicle(name_or_path: str | Path | None = None) -> VehicleParams:
    """Load a vehicle by bundled name (``"quad-1kg"``) or TOML path.

    Raises
    ------
    VehicleConfigError
        Unknown name, unreadable file, bad TOML or invalid values.
    """
    spec = DEFAULT_VEHICLE if name_or_path is None else str(name_or_path)
    path = Path(spec)
    if path.is_file():
        source = str(path)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise VehicleConfigError(source, "", f"cannot read ({exc.strerror})") from None
    else:
        stem = spec[:-5] if spec.endswith(".toml") else spec
        if "/" in spec or "\\" in spec or stem not in bundled_vehicles():
            raise VehicleConfigError(spec, "", f"no such vehicle file or bundled vehicle "
                                               f"(bundled: {', '.join(bundled_vehicles())})")
        res = resources.files("sitl.vehicles") / f"{stem}.toml"
        source = f"sitl.vehicles/{stem}.toml"
        text = res.read_text(encoding="utf-8")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise VehicleConfigError(source, "", f"invalid TOML ({exc})") from None
    return parse_vehicle(data, source)
