"""Non-nominal vehicles: faults and variations of the true vehicle the autopilot does not know about.

The ``[faults]`` section of a vehicle file (and the ``sitl`` options ``--motor-scale``,
``--com-offset``, ``--mass-scale``, ``--inertia-scale``, ``--clock-rate``, which override it) makes
the *simulated* vehicle differ from the *nominal* one of the rest of the file.  The autopilot, its
mixer and its parameters (``MOT_THST_HOVER``, the torque normalisation) keep the nominal values; only
the plant (:mod:`sitl.copter.rigid_body`, :class:`sitl.copter.world.ReducedPlant`) and the telemetry
time stamps use these:

==================  ==============  =========================================================
key                 range           effect
==================  ==============  =========================================================
motor_scale         4 x 0.3 .. 1.5  thrust actually produced by motor i = scale_i x its command
                                    (ArduPilot SITL's ``SIM_ENGINE_MUL``; the yaw reaction scales too)
com_offset_m        3 x -0.1 .. 0.1 centre of mass (x, y, z) [m, FRD] from the nominal one: the rotor
                                    arms are taken about it (``tau_x += y F``, ``tau_y -= x F``; z gives no
                                    moment, the thrust being along body z); the inertia stays the file's
mass_scale          0.5 .. 2.0      true mass = scale x ``vehicle.mass_kg``
inertia_scale       0.5 .. 2.0      true inertia = scale x ``vehicle.inertia_kg_m2``
clock_rate          0.9 .. 1.1      the vehicle's boot clock (``time_boot_ms``, ``time_usec``, TIMESYNC)
                                    runs at this rate relative to simulated time (PX4 SITL: about 0.988)
==================  ==============  =========================================================

A combination whose rotors cannot hold the true vehicle level and yaw-balanced with every motor
below :data:`HOVER_MARGIN` of its full thrust is refused (:func:`hover_problem`, "cannot hover ...").
This module imports no link code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pragma: no cover
    from sitl.copter.vehicle import VehicleParams

__all__ = ["FaultParams", "FAULT_RANGES", "HOVER_MARGIN", "true_mass_kg", "true_inertia", "hover_trim_n",
           "hover_problem"]

#: Allowed range ``(low, high, unit)`` of every ``[faults]`` key (each element of a vector).
FAULT_RANGES: dict[str, tuple[float, float, str]] = {
    "motor_scale": (0.3, 1.5, ""),
    "com_offset_m": (-0.1, 0.1, "m"),
    "mass_scale": (0.5, 2.0, ""),
    "inertia_scale": (0.5, 2.0, ""),
    "clock_rate": (0.9, 1.1, ""),
}
#: Largest fraction of a motor's full thrust the hover trim may need (the vehicle files' lift margin).
HOVER_MARGIN = 0.9

Vec3 = tuple[float, float, float]
Vec4 = tuple[float, float, float, float]


def _check(name: str, value: float) -> float:
    low, high, unit = FAULT_RANGES[name]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"faults.{name}: must be a finite number, got {value!r}")
    if not low <= value <= high:
        raise ValueError(f"faults.{name}: must be in [{low:g}, {high:g}]{' ' + unit if unit else ''}, got {value:g}")
    return float(value)


@dataclass(frozen=True)
class FaultParams:
    """``[faults]``: how the simulated vehicle differs from the nominal one (module docstring).

    Attributes
    ----------
    motor_scale : (float, float, float, float)
        Thrust produced per thrust commanded, motors 1..4 (ArduPilot numbering), each 0.3 .. 1.5.
    com_offset_m : (float, float, float)
        Centre of mass from the nominal one, FRD body frame [m], each -0.1 .. 0.1.
    mass_scale : float
        True mass / nominal mass, 0.5 .. 2.0.
    inertia_scale : float
        True inertia / nominal inertia, 0.5 .. 2.0.
    clock_rate : float
        Vehicle boot clock seconds per simulated second, 0.9 .. 1.1.

    Raises
    ------
    ValueError
        A value out of its range (:data:`FAULT_RANGES`), not a number or a vector of the wrong length.
    """

    motor_scale: Vec4 = (1.0, 1.0, 1.0, 1.0)
    com_offset_m: Vec3 = (0.0, 0.0, 0.0)
    mass_scale: float = 1.0
    inertia_scale: float = 1.0
    clock_rate: float = 1.0

    def __post_init__(self) -> None:
        for name, n in (("motor_scale", 4), ("com_offset_m", 3)):
            v = getattr(self, name)
            if not isinstance(v, (tuple, list)) or len(v) != n:
                raise ValueError(f"faults.{name}: must be {n} numbers, got {v!r}")
            object.__setattr__(self, name, tuple(_check(name, x) for x in v))
        for name in ("mass_scale", "inertia_scale", "clock_rate"):
            object.__setattr__(self, name, _check(name, getattr(self, name)))

    @property
    def nominal(self) -> bool:
        """No fault: the simulated vehicle is the nominal one."""
        return self == FaultParams()

    def describe(self) -> str:
        """One line for ``sitl --describe`` and logs."""
        m, c = self.motor_scale, self.com_offset_m
        return (f"motor scale {m[0]:g},{m[1]:g},{m[2]:g},{m[3]:g}; CoM offset {c[0]:g},{c[1]:g},{c[2]:g} m; "
                f"mass x{self.mass_scale:g}; inertia x{self.inertia_scale:g}; clock rate {self.clock_rate:g}")


def true_mass_kg(vehicle: VehicleParams) -> float:
    """Mass of the simulated vehicle [kg]: ``mass_kg * faults.mass_scale``."""
    return vehicle.mass_kg * vehicle.faults.mass_scale


def true_inertia(vehicle: VehicleParams) -> tuple[Vec3, Vec3, Vec3]:
    """Inertia matrix of the simulated vehicle [kg m^2]: ``inertia_kg_m2 * faults.inertia_scale``."""
    s = vehicle.faults.inertia_scale
    j = vehicle.inertia_kg_m2
    return tuple(tuple(s * x for x in row) for row in j)  # type: ignore[return-value]


def hover_trim_n(vehicle: VehicleParams) -> Vec4:
    """Thrusts [N] motors 1..4 must *produce* to hover the true vehicle level with no net torque.

    With ``d = L / sqrt(2)``, weight ``W`` and the centre of mass at ``(cx, cy)``: zero roll, pitch
    and yaw torque give ``T1 - T2 = (cx + cy) W / (2 d)``, ``T3 - T4 = (cx - cy) W / (2 d)`` and
    ``T1 + T2 = T3 + T4 = W / 2`` (layout in :mod:`sitl.copter.vehicle`).  Commanded thrusts are
    these divided by the motor scales.
    """
    w = true_mass_kg(vehicle) * vehicle.gravity_m_s2
    d = vehicle.rotors.arm_length_m / math.sqrt(2.0)
    cx, cy, _ = vehicle.faults.com_offset_m
    d12 = (cx + cy) * w / (2.0 * d)
    d34 = (cx - cy) * w / (2.0 * d)
    q = 0.25 * w
    return (q + 0.5 * d12, q - 0.5 * d12, q + 0.5 * d34, q - 0.5 * d34)


def hover_problem(vehicle: VehicleParams) -> str | None:
    """Why the true vehicle cannot hover with margin (None if it can).

    Refused: total rotor capacity ``sum(scale_i) T_max`` below ``W / HOVER_MARGIN``; or a motor
    whose commanded hover-trim thrust ``T_i / scale_i`` exceeds ``HOVER_MARGIN T_max`` or falls
    below ``rotors.min_thrust_n`` (a centre of mass too far out for the rotor arms).
    """
    f, r = vehicle.faults, vehicle.rotors
    m = true_mass_kg(vehicle)
    w = m * vehicle.gravity_m_s2
    capacity = sum(f.motor_scale) * r.max_thrust_n
    if w > HOVER_MARGIN * capacity:
        return (f"cannot hover: the rotors give {capacity:.3g} N at full thrust (motor scales "
                f"{','.join(f'{s:g}' for s in f.motor_scale)} x {r.max_thrust_n:g} N) for a {m:.3g} kg vehicle "
                f"({w:.3g} N), more than {HOVER_MARGIN:.0%} of it needed")
    for i, (t, s) in enumerate(zip(hover_trim_n(vehicle), f.motor_scale, strict=True), start=1):
        cmd = t / s
        if cmd > HOVER_MARGIN * r.max_thrust_n:
            return (f"cannot hover: motor {i} (scale {s:g}) would need {cmd / r.max_thrust_n:.1%} of its full "
                    f"thrust to hold the {m:.3g} kg vehicle level (at most {HOVER_MARGIN:.0%})")
        if cmd < r.min_thrust_n:
            return (f"cannot hover: the centre-of-mass offset {f.com_offset_m[0]:g},{f.com_offset_m[1]:g} m "
                    f"needs motor {i} below its minimum thrust ({cmd:.3g} < {r.min_thrust_n:g} N) to hold the "
                    f"vehicle level (arm {r.arm_length_m:g} m)")
    return None
