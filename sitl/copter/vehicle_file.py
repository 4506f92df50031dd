"""Vehicle files (``configs/vehicles/*.toml``, shipped as the package ``sitl.vehicles``): a strict loader.

Every key is optional except ``vehicle.mass_kg``, ``vehicle.inertia_kg_m2`` and the ``[rotors]``
geometry and limits.  Unknown sections or keys, wrong types and out of range values are refused
with a :class:`~quadrotor.errors.ConfigError` naming the file, the key and the reason (with the
range of :data:`VEHICLE_BOUNDS`); so are vehicles the 1 ms physics step would not integrate stably.
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from dataclasses import fields, replace
from importlib import resources
from pathlib import Path
from typing import Any

from quadrotor.bounds import (ATTITUDE_NOISE_RAD, DRAG_N_PER_M_S, GRAVITY_M_S2, INERTIA_KG_M2, MASS_KG, NOISE_M,
                              RATE_NOISE_RAD_S, Bound, OutOfBounds, short_repr)
from quadrotor.errors import ConfigError
from sitl.copter.faults import FAULT_RANGES, FaultParams, hover_problem, true_inertia, true_mass_kg
from sitl.copter.vehicle import (MODELS, BatteryParams, ControlParams, DragParams, HomeParams, Mat3, RotorParams,
                                 SensorParams6, VehicleParams)

__all__ = ["load_vehicle", "parse_vehicle", "bundled_vehicles", "with_faults", "DEFAULT_VEHICLE", "VEHICLE_BOUNDS",
           "MAX_DAMPING_1_S", "MAX_ANGULAR_ACCEL_RAD_S2"]

DEFAULT_VEHICLE = "quad-1kg"

_GAIN = Bound(0.0, 1000.0, "1/s", "an inner-loop gain of the 400 Hz autopilot")
_IGAIN = Bound(0.0, 1e4, "1/s^2", "an integral gain")
_THRUST = Bound(0.0, 1e4, "N", "one rotor's thrust")

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
    "drag.linear_n_per_m_s": DRAG_N_PER_M_S, "drag.vertical_n_per_m_s": DRAG_N_PER_M_S,
    "drag.quadratic_n_per_m2_s2": Bound(0.0, 10.0, "N/(m/s)^2", "quadratic air drag"),
    "drag.rotational_n_m_s": Bound(0.0, 10.0, "N m/(rad/s)", "rotational damping"),
    "battery.cells": Bound(1, 23, "cells", "at most 100 V at 4.2 V a cell", integer=True),
    "battery.capacity_mah": Bound(10.0, 1e6, "mAh", "the range of BATT_CAPACITY"),
    "battery.internal_resistance_ohm": Bound(0.0, 10.0, "ohm", "pack resistance"),
    "battery.initial_charge": Bound(0.0, 1.0, "", "state of charge"),
    "battery.avionics_current_a": Bound(0.0, 100.0, "A", "electronics draw"),
    "sensors.attitude_noise_std_rad": ATTITUDE_NOISE_RAD,
    "sensors.rate_noise_std_rad_s": RATE_NOISE_RAD_S,
    "sensors.baro_noise_std_m": NOISE_M, "sensors.baro_resolution_m": NOISE_M,
    "sensors.position_noise_std_m": NOISE_M,
    "sensors.velocity_noise_std_m_s": Bound(0.0, 10.0, "m/s", "velocity noise; 0 = none"),
    "sensors.rangefinder_noise_std_m": NOISE_M, "sensors.rangefinder_resolution_m": NOISE_M,
    "sensors.rangefinder_max_m": Bound(0.1, 1000.0, "m", "rangefinder range"),
    "control.rate_p_1_s": _GAIN, "control.rate_i_1_s2": _IGAIN,
    "control.rate_imax_rad_s2": Bound(0.0, 1e4, "rad/s^2", "rate integrator clamp"),
    "control.climb_p_1_s": _GAIN, "control.climb_i_1_s2": _IGAIN, "control.land_damping_1_s": _GAIN,
    "home.lat_deg": Bound(-90.0, 90.0, "deg", "latitude"),
    "home.lon_deg": Bound(-180.0, 180.0, "deg", "longitude"),
    "home.alt_m": Bound(-500.0, 1e4, "m", "altitude above mean sea level"),
    "faults.motor_scale": Bound(*FAULT_RANGES["motor_scale"], "thrust produced per thrust commanded"),
    "faults.com_offset_m": Bound(*FAULT_RANGES["com_offset_m"], "centre-of-mass offset, FRD"),
    "faults.mass_scale": Bound(*FAULT_RANGES["mass_scale"], "true over nominal mass"),
    "faults.inertia_scale": Bound(*FAULT_RANGES["inertia_scale"], "true over nominal inertia"),
    "faults.clock_rate": Bound(*FAULT_RANGES["clock_rate"], "vehicle clock over simulated time"),
}
_INERTIA_ENTRY = Bound(-1e3, 1e3, "kg m^2", "an entry of the inertia matrix")
#: Fastest physical rates the 1 ms physics step integrates stably: drag and damping time constants
#: of at least 2 ms, angular accelerations (max torque / inertia) up to 1e5 rad/s^2.
MAX_DAMPING_1_S = 500.0
MAX_ANGULAR_ACCEL_RAD_S2 = 1e5


_SECTIONS = {
    "vehicle": None, "rotors": RotorParams, "drag": DragParams, "battery": BatteryParams,
    "sensors": SensorParams6, "control": ControlParams, "home": HomeParams, "faults": FaultParams,
}
_VEHICLE_KEYS = ("name", "description", "model", "mass_kg", "gravity_m_s2", "inertia_kg_m2")
_REQUIRED = {"vehicle": ("mass_kg", "inertia_kg_m2"), "rotors": ("arm_length_m", "max_thrust_n")}
_BOOLEANS = ("sensors.rangefinder",)
#: Vector keys: their length and what the elements are.
_VECTORS = {"control.rate_p_1_s": (3, "roll, pitch, yaw"), "control.rate_i_1_s2": (3, "roll, pitch, yaw"),
            "faults.motor_scale": (4, "motors 1..4"), "faults.com_offset_m": (3, "x, y, z")}


def _check(source: str, key: str, value: Any) -> Any:
    """``value`` of ``key`` checked against :data:`VEHICLE_BOUNDS` (booleans and 3-vectors too)."""
    if key in _BOOLEANS:
        if not isinstance(value, bool):
            raise ConfigError(source, key, f"must be true or false, got {short_repr(value)}")
        return value
    bound = VEHICLE_BOUNDS[key]
    try:
        if key in _VECTORS:
            n, what = _VECTORS[key]
            if not (isinstance(value, list) and len(value) == n):
                raise OutOfBounds(f"must be a list of {n} numbers ({what}), got {short_repr(value)}; "
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
    source, r = params.source, params.rotors
    for k in ("min_thrust_n", "idle_thrust_n"):
        if getattr(r, k) >= r.max_thrust_n:
            raise ConfigError(source, f"rotors.{k}", f"must be below max_thrust_n ({r.max_thrust_n})")
    if params.hover_thrust_fraction >= 0.9:
        raise ConfigError(source, "rotors.max_thrust_n",
                                 f"4 x {r.max_thrust_n} N cannot lift {params.mass_kg} kg with margin "
                                 f"(hover at {params.hover_thrust_fraction:.2f} of full thrust)")
    _check_stability(params, params.mass_kg, params.inertia_diagonal, params.max_torque_nm, "")


def _check_stability(params: VehicleParams, mass_kg: float, inertia: tuple[float, float, float],
                     torque_nm: tuple[float, float, float], key: str) -> None:
    """Rates the physics step integrates stably for this (true) mass [kg], inertia diagonal [kg m^2]
    and largest torques [N m]; ``key`` names the offending key (default: the rate's own)."""
    dr = params.drag
    what = " (with the [faults] scales)" if key else ""
    for k, rate in (("drag.linear_n_per_m_s", dr.linear_n_per_m_s / mass_kg),
                    ("drag.vertical_n_per_m_s", dr.vertical_n_per_m_s / mass_kg),
                    ("drag.rotational_n_m_s", dr.rotational_n_m_s / min(inertia))):
        if rate > MAX_DAMPING_1_S:
            raise ConfigError(params.source, key or k, f"damps at {rate:g} 1/s for this mass and inertia{what}: at "
                              f"most {MAX_DAMPING_1_S:g} 1/s (a 2 ms time constant) integrates stably")
    accel = max(t / i for t, i in zip(torque_nm, inertia, strict=True))
    if accel > MAX_ANGULAR_ACCEL_RAD_S2:
        raise ConfigError(params.source, key or "vehicle.inertia_kg_m2",
                          f"max torque / inertia{what} = {accel:.3g} rad/s^2: at most {MAX_ANGULAR_ACCEL_RAD_S2:g} "
                          f"rad/s^2 is physical (inertia too small for the rotors)")


def with_faults(params: VehicleParams, faults: FaultParams) -> VehicleParams:
    """``params`` flying with ``faults`` (:mod:`sitl.copter.faults`), checked.

    Raises
    ------
    ConfigError
        Key ``faults``: the true vehicle cannot hover with margin ("cannot hover: ..."), or its scaled
        mass and inertia would not integrate stably.
    """
    out = replace(params, faults=faults)
    reason = hover_problem(out)
    if reason is not None:
        raise ConfigError(params.source, "faults", reason)
    j = true_inertia(out)
    c = max(faults.motor_scale)
    f = sum(faults.motor_scale) * params.rotors.max_thrust_n
    arm = max(abs(x) for x in faults.com_offset_m[:2])
    torque = tuple(c * t + arm * f for t in params.max_torque_nm)
    _check_stability(out, true_mass_kg(out), (j[0][0], j[1][1], j[2][2]), torque, "faults")  # type: ignore[arg-type]
    return out


def _check_layout(data: Any, source: str) -> None:
    """Known sections only, each a table, and the required keys present."""
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


def _sections(data: Mapping[str, Any], source: str) -> dict[str, Any]:
    """The parameter dataclass of every section but ``[vehicle]`` (all keys checked, ``[vehicle]``'s too)."""
    built: dict[str, Any] = {}
    for section, cls in _SECTIONS.items():
        table = dict(data.get(section, {}))
        allowed = _VEHICLE_KEYS if cls is None else tuple(f.name for f in fields(cls))
        for k in table:
            if k not in allowed:
                raise ConfigError(source, f"{section}.{k}", f"unknown key (known: {', '.join(allowed)})")
        if cls is not None:
            built[section] = cls(**{k: _check(source, f"{section}.{k}", v) for k, v in table.items()})
    return built


def _vehicle_section(v: Mapping[str, Any], source: str) -> dict[str, Any]:
    """The :class:`VehicleParams` keywords of the ``[vehicle]`` table."""
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
    return kwargs


def parse_vehicle(data: Mapping[str, Any], source: str = "<vehicle>") -> VehicleParams:
    """Validate a parsed vehicle TOML document (``tomllib.load``'s result).

    Raises
    ------
    ConfigError
        Naming ``source`` (the file path), the offending key and the reason (with the allowed range).
    """
    _check_layout(data, source)
    built = _sections(data, source)
    faults = built.pop("faults")
    params = VehicleParams(source=source, **_vehicle_section(data.get("vehicle", {}), source), **built)
    _check_rates(params)
    return with_faults(params, faults) if not faults.nominal else params


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
