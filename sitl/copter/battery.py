"""LiPo battery: voltage under load, current and consumed charge/energy from rotor power.

Rotor power is momentum theory: the ideal induced power of a rotor of thrust
``T`` and disc area ``A`` is ``T^1.5 / sqrt(2 rho A)``; dividing by the
figure of merit gives shaft power and by the electrical efficiency the
power drawn from the pack.  The pack is an open-circuit voltage (a LiPo
discharge curve of the state of charge) in series with a resistance, so
with ``E`` = OCV and load power ``P`` the current is the smaller root of
``R I^2 - E I + P = 0``.  ``step`` is pure.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import NamedTuple

from sitl.copter.vehicle import BatteryParams, RotorParams

__all__ = ["BatteryState", "open_circuit_voltage", "power_coefficient", "rotor_power_w", "step", "initial_battery",
           "AIR_DENSITY_KG_M3"]

AIR_DENSITY_KG_M3 = 1.225

# LiPo resting cell voltage vs state of charge (typical discharge curve).
_OCV_CURVE = (
    (0.00, 3.27), (0.05, 3.61), (0.10, 3.69), (0.15, 3.71), (0.20, 3.73), (0.30, 3.77), (0.40, 3.79),
    (0.50, 3.82), (0.60, 3.87), (0.70, 3.92), (0.80, 3.98), (0.90, 4.06), (1.00, 4.20),
)


class BatteryState(NamedTuple):
    """Pack state.

    ``charge`` state of charge 0..1, ``voltage_v`` terminal voltage under the
    last load, ``current_a`` last current, ``consumed_mah`` and
    ``consumed_wh`` since start.
    """

    charge: float
    voltage_v: float
    current_a: float = 0.0
    consumed_mah: float = 0.0
    consumed_wh: float = 0.0


# The curve resampled every 5 % (its points are on that grid), for an O(1) lookup.
_OCV_TABLE = tuple(v for _, v in _OCV_CURVE[:1]) + tuple(
    next(a[1] + (c - a[0]) / (b[0] - a[0]) * (b[1] - a[1])
         for a, b in itertools.pairwise(_OCV_CURVE) if a[0] <= c <= b[0] + 1e-12)
    for c in (i / 20.0 for i in range(1, 21)))


def open_circuit_voltage(charge: float, params: BatteryParams) -> float:
    """Resting pack voltage [V] at state of charge ``charge`` (clipped to 0..1)."""
    c = 0.0 if charge < 0.0 else 1.0 if charge > 1.0 else charge
    x = c * 20.0
    i = int(x)
    if i >= 20:
        return params.cells * _OCV_TABLE[20]
    lo = _OCV_TABLE[i]
    return params.cells * (lo + (x - i) * (_OCV_TABLE[i + 1] - lo))


def initial_battery(params: BatteryParams) -> BatteryState:
    """Pack at ``params.initial_charge``, unloaded."""
    return BatteryState(params.initial_charge, open_circuit_voltage(params.initial_charge, params))


def power_coefficient(rotors: RotorParams) -> float:
    """``k`` such that the electrical power of a rotor of thrust ``T`` is ``k T^1.5`` [W]."""
    area = math.pi * 0.25 * rotors.diameter_m ** 2
    return 1.0 / (math.sqrt(2.0 * AIR_DENSITY_KG_M3 * area) * rotors.figure_of_merit * rotors.electrical_efficiency)


def rotor_power_w(thrusts: Sequence[float], rotors: RotorParams) -> float:
    """Electrical power [W] drawn by rotors producing ``thrusts`` [N] (negative thrust counts as 0)."""
    return power_coefficient(rotors) * sum(t * math.sqrt(t) for t in thrusts if t > 0.0)


def step(state: BatteryState, power_w: float, dt: float, params: BatteryParams) -> BatteryState:
    """Draw ``power_w`` (rotors) plus the avionics current for ``dt`` seconds.

    Parameters
    ----------
    state : BatteryState
    power_w : float
        Rotor electrical power [W], >= 0.
    dt : float
        Duration [s].
    params : BatteryParams

    Returns
    -------
    BatteryState
        An empty pack (charge 0) keeps its curve's last voltage.
    """
    e = open_circuit_voltage(state.charge, params)
    res = params.internal_resistance_ohm
    p = power_w if power_w > 0.0 else 0.0
    if res > 0.0:
        disc = e * e - 4.0 * res * p
        # Beyond the maximum power point the pack delivers what it can (I = E / 2R).
        i_motor = (e - math.sqrt(disc)) / (2.0 * res) if disc > 0.0 else e / (2.0 * res)
    else:
        i_motor = p / e if e > 0.0 else 0.0
    current = i_motor + params.avionics_current_a
    voltage = e - res * current
    used_mah = current * dt / 3.6
    charge = state.charge - used_mah / params.capacity_mah
    return tuple.__new__(BatteryState, (
        charge if charge > 0.0 else 0.0,
        voltage,
        current,
        state.consumed_mah + used_mah,
        state.consumed_wh + voltage * current * dt / 3600.0,
    ))
