"""ArduPilot-style parameter table of the emulated autopilot.

Names, units and defaults follow ArduCopter 4.x/4.8-dev (``GUID_OPTIONS``,
``GUID_TIMEOUT``, ``MOT_THST_HOVER``, ``DISARM_DELAY``, ``WP_SPD_UP``, ...),
so a ground station that configures this SITL configures a real autopilot
the same way.  ``MOT_THST_HOVER`` defaults to the vehicle's true hover thrust
(what ArduPilot learns with ``MOT_HOVER_LEARN = 2``) and ``BATT_*`` to the
vehicle's pack.

Values are stored as floats; integer types are rounded on write.  Like the
MAVLink parameter protocol, every value travels as a float with its
``MAV_PARAM_TYPE``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass

from sitl.copter.vehicle import VehicleParams

__all__ = ["ParamSpec", "ParamStore", "ardupilot_params", "STREAM_PARAMS",
           "MAV_PARAM_TYPE_INT8", "MAV_PARAM_TYPE_INT16", "MAV_PARAM_TYPE_INT32", "MAV_PARAM_TYPE_REAL32"]

MAV_PARAM_TYPE_INT8 = 2
MAV_PARAM_TYPE_INT16 = 4
MAV_PARAM_TYPE_INT32 = 6
MAV_PARAM_TYPE_REAL32 = 9
_INT_TYPES = (1, 2, 3, 4, 5, 6, 7, 8)
# MAV_PARAM_TYPE -> 2 ** (bits - 1) of the signed integer holding it (unsigned types alike, ArduPilot has none)
_INT_LIMITS = {1: 128.0, 2: 128.0, 3: 32768.0, 4: 32768.0, 5: 2.0 ** 31, 6: 2.0 ** 31}

# REQUEST_DATA_STREAM stream id -> rate parameter (ArduPilot SRn_*; one link here, n = 0).
STREAM_PARAMS = {
    1: "SR0_RAW_SENS", 2: "SR0_EXT_STAT", 3: "SR0_RC_CHAN", 4: "SR0_RAW_CTRL",
    6: "SR0_POSITION", 10: "SR0_EXTRA1", 11: "SR0_EXTRA2", 12: "SR0_EXTRA3",
}


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: name (<= 16 chars), default, MAV_PARAM_TYPE, range, units, description."""

    name: str
    default: float
    ptype: int = MAV_PARAM_TYPE_REAL32
    minimum: float = -math.inf
    maximum: float = math.inf
    units: str = ""
    description: str = ""
    readonly: bool = False


def ardupilot_params(vehicle: VehicleParams) -> list[ParamSpec]:
    """The parameter table for ``vehicle`` (ArduCopter names and defaults)."""
    i8, i16, i32, f = MAV_PARAM_TYPE_INT8, MAV_PARAM_TYPE_INT16, MAV_PARAM_TYPE_INT32, MAV_PARAM_TYPE_REAL32
    hover = float(round(vehicle.hover_thrust_fraction, 4))
    cells = vehicle.battery.cells
    specs = [
        ParamSpec("SYSID_THISMAV", 1, i16, 1, 255, "", "MAVLink system id of this vehicle"),
        ParamSpec("SYSID_MYGCS", 255, i16, 1, 255, "", "System id of the ground station"),
        ParamSpec("FRAME_CLASS", 1, i8, 1, 1, "", "1 = Quad", readonly=True),
        ParamSpec("FRAME_TYPE", 1, i8, 1, 1, "", "1 = X", readonly=True),
        ParamSpec("GUID_OPTIONS", 0, i32, 0, 2 ** 31 - 1, "",
                  "Guided options bitmask; bit 3 (8): SET_ATTITUDE_TARGET thrust is thrust, not climb rate"),
        ParamSpec("GUID_TIMEOUT", 3.0, f, 0.1, 5.0, "s", "Guided attitude target timeout (then level and LAND)"),
        ParamSpec("MOT_THST_HOVER", hover, f, 0.125, 0.6875, "",
                  "Thrust (0..1 of full) to hover; the vehicle's true value (learned in ArduPilot)"),
        ParamSpec("DISARM_DELAY", 10, i8, 0, 127, "s", "Auto-disarm delay when landed (0 = off)"),
        ParamSpec("WP_SPD_UP", 2.5, f, 0.1, 10.0, "m/s", "Climb speed (SET_ATTITUDE_TARGET thrust 1.0)"),
        ParamSpec("WP_SPD_DN", 1.5, f, 0.1, 5.0, "m/s", "Descent speed (SET_ATTITUDE_TARGET thrust 0.0)"),
        ParamSpec("WP_ACC_Z", 1.0, f, 0.1, 5.0, "m/s/s", "Vertical acceleration limit of climb-rate targets"),
        ParamSpec("LAND_SPD_MS", 0.5, f, 0.3, 2.0, "m/s", "Final landing descent speed"),
        ParamSpec("LAND_SPD_HIGH_MS", 0.0, f, 0.0, 5.0, "m/s", "Descent speed above LAND_ALT_LOW_M (0 = WP_SPD_DN)"),
        ParamSpec("LAND_ALT_LOW_M", 10.0, f, 1.0, 20.0, "m", "Altitude below which LAND descends at LAND_SPD_MS"),
        ParamSpec("ATC_ANGLE_MAX", 30.0, f, 10.0, 80.0, "deg", "Lean angle limit (arming: 'Leaning' above it)"),
        # Navigation modes (sitl.copter.navigation): ArduCopter 4.8's names and defaults.
        ParamSpec("WP_SPD", 10.0, f, 0.1, 20.0, "m/s", "Horizontal speed of AUTO and GUIDED positions"),
        ParamSpec("WP_ACC", 2.5, f, 0.5, 10.0, "m/s/s", "Horizontal acceleration of AUTO and GUIDED positions"),
        ParamSpec("WP_RADIUS_M", 2.0, f, 0.05, 10.0, "m", "A waypoint is reached within this distance"),
        ParamSpec("LOIT_SPEED_MS", 12.5, f, 0.2, 35.0, "m/s", "LOITER / POSHOLD horizontal speed limit"),
        ParamSpec("LOIT_ACC_MAX_M", 5.0, f, 1.0, 10.0, "m/s/s", "LOITER / POSHOLD acceleration limit"),
        ParamSpec("RTL_ALT_M", 15.0, f, 0.3, 300.0, "m", "RTL return altitude above home"),
        ParamSpec("RTL_ALT_FINAL_M", 0.0, f, 0.0, 1000.0, "m", "RTL final altitude above home (0 = land)"),
        ParamSpec("RTL_CLIMB_MIN_M", 0.0, f, 0.0, 30.0, "m", "RTL climbs at least this much first"),
        ParamSpec("RTL_LOIT_TIME", 5000, i32, 0, 60000, "ms", "RTL loiter over home before descending"),
        ParamSpec("RTL_SPEED_MS", 0.0, f, 0.0, 20.0, "m/s", "RTL return speed (0 = WP_SPD)"),
        ParamSpec("ATC_ANGLE_BOOST", 1, i8, 0, 1, "",
                  "Scale throttle by 1/cos(tilt) (applies to guided thrust, as in ArduPilot)"),
        ParamSpec("ATC_ANG_RLL_P", 4.5, f, 0.5, 20.0, "1/s", "Roll angle P: rate demand per angle error"),
        ParamSpec("ATC_ANG_PIT_P", 4.5, f, 0.5, 20.0, "1/s", "Pitch angle P"),
        ParamSpec("ATC_ANG_YAW_P", 4.5, f, 0.5, 20.0, "1/s", "Yaw angle P"),
        ParamSpec("ATC_RATE_R_MAX", 0.0, f, 0.0, 1080.0, "deg/s", "Roll rate limit (0 = none)"),
        ParamSpec("ATC_RATE_P_MAX", 0.0, f, 0.0, 1080.0, "deg/s", "Pitch rate limit (0 = none)"),
        ParamSpec("ATC_RATE_Y_MAX", 0.0, f, 0.0, 1080.0, "deg/s", "Yaw rate limit (0 = none)"),
        # Known so that a ground station can set them as it does on ArduCopter (ArduPilot's defaults);
        # the emulated inner loop does not model them yet: it always flies the quaternion
        # unshaped (as ATC_RATE_FF_ENAB = 0) and has no GCS failsafe.
        ParamSpec("ATC_RATE_FF_ENAB", 1, i8, 0, 1, "",
                  "Rate feed-forward and input shaping (1); 0: targets flown unshaped (not modelled)"),
        ParamSpec("ATC_ACC_R_MAX", 1100.0, f, 0.0, 180000.0, "deg/s/s", "Roll acceleration limit (not modelled)"),
        ParamSpec("ATC_ACC_P_MAX", 1100.0, f, 0.0, 180000.0, "deg/s/s", "Pitch acceleration limit (not modelled)"),
        ParamSpec("ATC_ACC_Y_MAX", 270.0, f, 0.0, 72000.0, "deg/s/s", "Yaw acceleration limit (not modelled)"),
        ParamSpec("FS_GCS_ENABLE", 0, i8, 0, 7, "",
                  "Ground-station failsafe: 0 off, 1 RTL, ..., 5 Land (not modelled: no GCS failsafe)"),
        ParamSpec("FS_GCS_TIMEOUT", 5.0, f, 2.0, 120.0, "s", "Ground-station failsafe timeout (not modelled)"),
        ParamSpec("MAV_GCS_SYSID", 255, i16, 1, 255, "",
                  "System id of the ground station (ArduPilot 4.7+ name of SYSID_MYGCS)"),
        ParamSpec("ARMING_CHECK", 1, i32, 0, 2 ** 31 - 1, "", "Arming checks (0 = none)"),
        ParamSpec("BATT_CAPACITY", float(round(vehicle.battery.capacity_mah)), i32, 0, 1e6, "mAh", "Pack capacity"),
        ParamSpec("BATT_LOW_VOLT", round(3.5 * cells, 2), f, 0.0, 100.0, "V",
                  "Low-battery voltage: no arming below, STATUSTEXT in flight (0 = off)"),
        ParamSpec("BATT_ARM_VOLT", 0.0, f, 0.0, 100.0, "V", "Minimum voltage to arm (0 = off)"),
        ParamSpec("BATT_LOW_MAH", 0.0, f, 0.0, 1e6, "mAh", "Low-battery remaining capacity (0 = off)"),
        ParamSpec("BATT_FS_LOW_ACT", 0, i8, 0, 5, "", "Low-battery action: 0 none, 1 (and above) LAND"),
    ]
    for name in STREAM_PARAMS.values():
        specs.append(ParamSpec(name, 0, i16, 0, 400, "Hz", "Stream rate (REQUEST_DATA_STREAM group)"))
    return specs


class ParamStore:
    """Parameter values with ArduPilot's protocol semantics.

    Parameters
    ----------
    specs : list of ParamSpec
        In index order (PARAM_VALUE.param_index).
    overrides : mapping, optional
        Initial values replacing defaults (validated like :meth:`set`).
    """

    def __init__(self, specs: list[ParamSpec], overrides: Mapping[str, float] | None = None) -> None:
        self._specs = list(specs)
        self._index = {s.name: i for i, s in enumerate(self._specs)}
        self._values = [float(s.default) for s in self._specs]
        self._listeners: list[Callable[[str, float], None]] = []
        for name, value in (overrides or {}).items():
            ok, reason = self.set(name, value, force=True)
            if not ok:
                raise ValueError(f"parameter {name}: {reason}")

    def __len__(self) -> int:
        return len(self._specs)

    def __contains__(self, name: object) -> bool:
        return name in self._index

    def __iter__(self) -> Iterator[str]:
        return (s.name for s in self._specs)

    def __getitem__(self, name: str) -> float:
        return self._values[self._index[name]]

    def spec(self, name: str) -> ParamSpec:
        """Specification of ``name`` (KeyError if unknown)."""
        return self._specs[self._index[name]]

    def index(self, name: str) -> int:
        """Index of ``name`` (KeyError if unknown)."""
        return self._index[name]

    def name_at(self, index: int) -> str | None:
        """Name at ``index`` or None."""
        return self._specs[index].name if 0 <= index < len(self._specs) else None

    def add_listener(self, callback: Callable[[str, float], None]) -> None:
        """Call ``callback(name, value)`` after every successful change."""
        self._listeners.append(callback)

    def set(self, name: str, value: float, *, force: bool = False, check_range: bool = True) -> tuple[bool, str]:
        """Set ``name`` to ``value``.

        ``check_range=False`` is ArduPilot's PARAM_SET: a value outside the documented range is set
        all the same (integer types are clamped to what the type holds).

        Returns
        -------
        (bool, str)
            ``(True, "")`` or ``(False, reason)``: unknown name, read-only,
            not finite or out of range (``force`` skips the read-only check).
        """
        i = self._index.get(name)
        if i is None:
            return False, "unknown parameter"
        spec = self._specs[i]
        try:
            v = float(value)
        except (TypeError, ValueError):
            return False, f"not a number: {value!r}"
        if not math.isfinite(v):
            return False, f"not finite: {v!r}"
        if spec.readonly and not force and v != self._values[i]:
            return False, "read-only"
        if spec.ptype in _INT_TYPES:
            v = float(round(v))
            if not check_range:
                lim = _INT_LIMITS.get(spec.ptype, 2.0 ** 31)
                v = min(max(v, -lim), lim - 1)
        if check_range and not spec.minimum <= v <= spec.maximum:
            return False, f"{v:g} outside [{spec.minimum:g}, {spec.maximum:g}]"
        self._values[i] = v
        for cb in self._listeners:
            cb(name, v)
        return True, ""
