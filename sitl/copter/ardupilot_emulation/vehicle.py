"""The vehicle and parameter defaults ArduCopter's own SITL flies (``--model x`` with ``copter.parm``).

The airframe is ArduPilot SITL's default multicopter model (``libraries/SITL/SIM_Frame.cpp``
``Model``): 3 kg, motors 0.35 m from the centre on the diagonals, inertia from "half the mass on
a ring" (``m/4 (d/2)^2``, ``m/2 (d/2)^2`` about z), rotational damping ``400 deg/s^2 per 120
deg/s``, momentum drag of the rotors (linear, ~0.72 N per m/s at hover) and body drag
(``areaCd`` from the 15.08 m/s at 45 deg reference: ~0.10 N per (m/s)^2).  Its motors give the
``MOT_THST_EXPO`` curve back linearly; full thrust is set so that the true hover throttle is
``TRUE_HOVER`` (0.366: measured on the firmware, where ``MOT_THST_HOVER`` says 0.39).  The
reaction torque per thrust, ``0.05 x 0.35 m x command``, is linearised at hover.

Its sensors are noise-free, as the firmware SITL's (``SIM_*_RND`` 0 in ``copter.parm``): what the
firmware sends is its EKF's smooth output.  Measured in a hover (high-pass, 0.5 s moving average
removed): LOCAL_POSITION_NED position 0.13-0.17 mm, velocity 0.30-0.35 mm/s, ATTITUDE angles 0.007
deg, rates 0.07 deg/s.  The emulation had 5 mm, 5 mm/s, 0.03 deg and 0.11 deg/s of white noise (read
the same way: 5 mm, 5 mm/s, 0.07 deg, 1.8 deg/s), which the disturbance observer and the rate damping
passed on to the commands.  The EKF's *errors* are in
:mod:`.ekf`.
"""

from __future__ import annotations

from dataclasses import replace

from sitl.copter.params import MAV_PARAM_TYPE_REAL32, ParamSpec, ardupilot_params
from sitl.copter.vehicle import (BatteryParams, ControlParams, DragParams, RotorParams, SensorParams6,
                                 VehicleParams)

__all__ = ["arducopter_sitl_vehicle", "emulation_params", "TRUE_HOVER", "INITIAL_YAW_DEG"]

TRUE_HOVER = 0.366
#: Heading the firmware's SITL reports at boot (its --home heading 353 deg, then its EKF): about -4.8 deg.
INITIAL_YAW_DEG = -4.8
_MASS_KG = 3.0
_DIAGONAL_M = 0.35
_G = 9.81


def arducopter_sitl_vehicle() -> VehicleParams:
    """ArduPilot SITL's X quad as a :class:`VehicleParams`."""
    ixx = _MASS_KG * 0.25 * (_DIAGONAL_M / 2) ** 2
    izz = _MASS_KG * 0.5 * (_DIAGONAL_M / 2) ** 2
    full = _MASS_KG * _G / (4.0 * TRUE_HOVER)
    damping = 0.0582  # rad/s^2 per rad/s: radians(400) / 120
    return VehicleParams(
        mass_kg=_MASS_KG, inertia_kg_m2=((ixx, 0.0, 0.0), (0.0, ixx, 0.0), (0.0, 0.0, izz)),
        rotors=RotorParams(arm_length_m=_DIAGONAL_M, max_thrust_n=full, min_thrust_n=0.0, idle_thrust_n=0.0,
                           time_constant_s=0.001, yaw_moment_m=0.0154, diameter_m=0.35),
        name="arducopter-sitl-x", description="ArduPilot SITL's default X quad (SIM_Frame Model), 3 kg",
        gravity_m_s2=_G, drag=DragParams(linear_n_per_m_s=0.72, vertical_n_per_m_s=0.72,
                                         quadratic_n_per_m2_s2=0.10, rotational_n_m_s=damping * ixx),
        battery=BatteryParams(cells=3, capacity_mah=1e6, internal_resistance_ohm=0.01, avionics_current_a=0.0),
        sensors=SensorParams6(attitude_noise_std_rad=0.0, rate_noise_std_rad_s=0.0, baro_noise_std_m=0.0,
                              baro_resolution_m=0.01, position_noise_std_m=0.0, velocity_noise_std_m_s=0.0),
        control=ControlParams(climb_p_1_s=5.0, climb_i_1_s2=1.0), source="<ardupilot_emulation>")


def emulation_params(vehicle: VehicleParams) -> list[ParamSpec]:
    """The built-in table with ArduCopter SITL's values, plus the inner loop's own parameters."""
    f = MAV_PARAM_TYPE_REAL32
    defaults = {"MOT_THST_HOVER": 0.39, "ATC_RATE_FF_ENAB": 1.0, "GUID_TIMEOUT": 3.0}
    specs = [replace(s, default=defaults[s.name]) if s.name in defaults else s for s in ardupilot_params(vehicle)]
    specs = [replace(s, description=s.description.replace(" (not modelled)", "")) for s in specs]
    specs.append(ParamSpec("ATC_INPUT_TC", 0.15, f, 0.0, 1.0, "s", "Attitude input time constant (shaping)"))
    for axis, (p, i, d, flte) in (("RLL", (0.135, 0.135, 0.0036, 0.0)), ("PIT", (0.135, 0.135, 0.0036, 0.0)),
                                  ("YAW", (0.3, 0.02, 0.0, 2.5))):
        specs += [
            ParamSpec(f"ATC_RAT_{axis}_P", p, f, 0.0, 2.0, "", "Rate P (normalised output per rad/s)"),
            ParamSpec(f"ATC_RAT_{axis}_I", i, f, 0.0, 2.0, "", "Rate I"),
            ParamSpec(f"ATC_RAT_{axis}_D", d, f, 0.0, 0.2, "", "Rate D"),
            ParamSpec(f"ATC_RAT_{axis}_IMAX", 0.5, f, 0.0, 1.0, "", "Rate I limit"),
            ParamSpec(f"ATC_RAT_{axis}_FLTT", 20.0, f, 0.0, 200.0, "Hz", "Rate target filter (0 = none)"),
            ParamSpec(f"ATC_RAT_{axis}_FLTE", flte, f, 0.0, 200.0, "Hz", "Rate error filter (0 = none)"),
            ParamSpec(f"ATC_RAT_{axis}_FLTD", 20.0, f, 0.0, 200.0, "Hz", "Rate derivative filter (0 = none)"),
        ]
    specs += [
        ParamSpec("INS_GYRO_FILTER", 20.0, f, 0.0, 256.0, "Hz", "Gyro low-pass (two-pole)"),
        ParamSpec("MOT_THST_EXPO", 0.65, f, -1.0, 1.0, "", "Thrust curve exponent"),
        ParamSpec("MOT_SPIN_ARM", 0.10, f, 0.0, 1.0, "", "Motor output when armed on the ground"),
        ParamSpec("MOT_SPIN_MIN", 0.15, f, 0.0, 1.0, "", "Motor output at zero thrust in flight"),
        ParamSpec("MOT_SPIN_MAX", 0.95, f, 0.0, 1.0, "", "Motor output at full thrust"),
        ParamSpec("MOT_SPOOL_TIME", 0.5, f, 0.05, 2.0, "s", "Spool-up time"),
        ParamSpec("MOT_YAW_HEADROOM", 200, f, 0.0, 1000.0, "",
                  "Yaw headroom kept for yaw (x 0.001)"),
        ParamSpec("ATC_THR_MIX_MAX", 0.5, f, 0.5, 0.9, "", "Throttle vs attitude priority in flight"),
    ]
    return specs
