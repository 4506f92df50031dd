"""The allowed range of every number of an experiment config, in one table.

:data:`BOUNDS` maps each key (``section.key``; ``mission.phases[].key`` for every
phase; vectors and matrices element by element) to a :class:`~quadrotor.bounds.Bound`:
``[lo, hi]``, the unit and why.  The reader looks every number up here, so a key
without an entry cannot be read, and every message names the key and the allowed
range.  Ranges shared with the SITL's vehicle files (mass, gravity, sensor noise)
are taken from :mod:`quadrotor.bounds`, so they are defined once.

Besides the table, the loader cross-checks values against each other: a horizon,
duration and phase of at least one control period, a plant sub-step of at most
``ts_s`` and at least ``ts_s / MAX_SUBSTEPS_PER_TICK``, thrust above the hover
thrust, a drag time constant longer than the plant sub-step, a ceiling above the
mission, and a telemetry rate that fits :data:`MIN_STALE_MESSAGES` messages into
``telemetry_stale_s``.
"""

from __future__ import annotations

import re

from quadrotor import bounds as shared
from quadrotor.bounds import Bound

__all__ = ["BOUNDS", "bound_for", "WEEK_S", "MAX_RUNS", "MAX_HORIZON_STEPS", "MAX_SUBSTEPS_PER_TICK",
           "MIN_STALE_MESSAGES", "LOC_SUBSYSTEMS", "NLSOC_SUBSYSTEMS", "PD_GAINS", "MATRIX_NAMES"]

#: The longest flight, horizon or phase [s].
WEEK_S = 7 * 24 * 3600.0
#: Most simulated runs per controller (``[sim] runs``, ``gcs sim --runs``).
MAX_RUNS = 10_000
#: Longest horizon in steps (a LOC gain table row per step; 10^7 steps = 28 h at 10 ms).
MAX_HORIZON_STEPS = 10_000_000
#: Most plant sub-steps per control period (``ts_s / plant_substep_s``).
MAX_SUBSTEPS_PER_TICK = 10_000
#: Telemetry messages that must fit into the stale timeout.
MIN_STALE_MESSAGES = 3

# Subsystem dimensions: (state size n, input size m).
LOC_SUBSYSTEMS = {"z": (2, 1), "psi": (2, 1), "y_phi": (4, 1), "x_theta": (4, 1)}
NLSOC_SUBSYSTEMS = {"z_psi": (4, 2), "y_phi": (4, 1), "x_theta": (4, 1)}
MATRIX_NAMES = ("Q", "R", "H", "Q_printed", "R_printed", "H_printed")
PD_GAINS = ("kp_z", "kd_z", "kp_psi", "kd_psi", "kp_x", "kd_x", "kp_y", "kd_y", "kp_theta", "kd_theta",
            "kp_phi", "kd_phi")

_PERIOD = Bound(1e-4, WEEK_S, "s", "from the shortest control period, 0.1 ms, to a week")
_MATRIX = Bound(-1e12, 1e12, "", "a penalty-matrix entry")
_KP = Bound(0.0, 1e7, "1/s^2", "a proportional PD gain")
_KD = Bound(0.0, 1e7, "1/s", "a derivative PD gain")
_WIND = Bound(0.0, 50.0, "m/s", "wind no quadrotor flies in is stronger")
_TORQUE = Bound(1e-4, 1e4, "N m", "the autopilot's maximum torque about one axis")

#: Allowed range of every number of a config, by key.
BOUNDS: dict[str, Bound] = {
    "experiment.ts_s": Bound(1e-4, 1.0, "s", "a control period from 0.1 ms to 1 s"),
    "experiment.horizon_s": _PERIOD,
    "experiment.duration_s": _PERIOD,
    "--duration": _PERIOD,
    "vehicle.mass_kg": shared.MASS_KG,
    "vehicle.gravity_m_s2": shared.GRAVITY_M_S2,
    "vehicle.max_thrust_n": Bound(0.01, 1e5, "N", "the collective thrust limit"),
    "vehicle.max_angular_accel_rad_s2": Bound(1.0, 1e5, "rad/s^2", "the angular-acceleration limit"),
    "vehicle.drag_n_per_m_s": shared.DRAG_N_PER_M_S,
    "mission.phases[].duration_s": _PERIOD,
    "mission.phases[].z_m": Bound(0.01, 1e4, "m", "an altitude set point below the ceiling"),
    "mission.phases[].radius_m": Bound(0.01, 1e4, "m", "a circle radius"),
    "mission.phases[].period_s": Bound(0.1, WEEK_S, "s", "one lap of the circle"),
    "mission.phases[].center_m": Bound(-1e4, 1e4, "m", "a circle centre, x and y from takeoff"),
    **{f"{group}.{sub}.{m}": _MATRIX for group, subs in (("loc", LOC_SUBSYSTEMS), ("nlsoc", NLSOC_SUBSYSTEMS))
       for sub in subs for m in MATRIX_NAMES},
    **{f"pd.{g}": _KP if g.startswith("kp") else _KD for g in PD_GAINS},
    "sim.plant_substep_s": Bound(1e-5, 1.0, "s", "the RK4 sub-step of the plant, at most ts_s"),
    "sim.runs": Bound(1, MAX_RUNS, "runs", "runs per controller", integer=True),
    "sim.seed": Bound(0, 2 ** 63 - 1, "", "a TOML integer", integer=True),
    "sim.wind.mean_speed_m_s": _WIND,
    "sim.wind.direction_deg": Bound(-360.0, 360.0, "deg", "the direction the wind blows towards"),
    "sim.wind.vertical_m_s": Bound(-50.0, 50.0, "m/s", "steady vertical wind, up positive"),
    "sim.wind.gust_std_m_s": _WIND,
    "sim.wind.gust_tau_s": Bound(0.01, 3600.0, "s", "the gust correlation time"),
    "sim.sensors.altitude_noise_std_m": shared.NOISE_M,
    "sim.sensors.altitude_resolution_m": shared.NOISE_M,
    "sim.sensors.position_noise_std_m": shared.NOISE_M,
    "sim.sensors.attitude_noise_std_rad": shared.ATTITUDE_NOISE_RAD,
    "sim.sensors.rate_noise_std_rad_s": shared.RATE_NOISE_RAD_S,
    "estimator.accel_noise_std_m_s2": Bound(1e-3, 1e3, "m/s^2", "unmodelled acceleration, at most 100 g"),
    "estimator.disturbance_time_constant_s": Bound(0.1, 3600.0, "s", "the disturbance observer's time constant"),
    "flight.telemetry_rate_hz": Bound(1.0, 1000.0, "Hz", "a MAVLink stream rate"),
    "flight.telemetry_stale_s": Bound(0.003, 60.0, "s", "the telemetry age that triggers the failsafe"),
    "flight.max_tilt_deg": Bound(1.0, 89.0, "deg", "the tilt limit; at 90 deg thrust has no vertical part"),
    "flight.fence_half_width_m": Bound(0.1, 1e4, "m", "the geofence box around takeoff"),
    "flight.ceiling_m": Bound(0.1, 1e4, "m", "the altitude ceiling, above the mission"),
    "flight.rate_gain_1_s": Bound(0.1, 1000.0, "1/s", "the output adapters' rate-demand gain"),
    "flight.rate_integral_max_rad": Bound(0.0, 0.5, "rad", "the attitude offset the rate-error integral may add"),
    "flight.rate_response_s": Bound(0.001, 1.0, "s", "the modelled response time of the autopilot's rate loop"),
    "flight.tracking_lost_m": Bound(0.0, 1e3, "m", "the distance from the reference that is not following; 0 = off"),
    "flight.tracking_lost_s": Bound(0.1, 600.0, "s", "how long not following lasts before landing"),
    "flight.inertia_kg_m2": shared.INERTIA_KG_M2,
    "flight.max_torque_nm": _TORQUE,
    "flight.position_std_m": Bound(1e-4, 100.0, "m", "the noise assumed for LOCAL_POSITION_NED"),
    "flight.velocity_std_m_s": Bound(1e-4, 100.0, "m/s", "the noise assumed for LOCAL_POSITION_NED"),
    "flight.landing_speed_m_s": Bound(0.01, 10.0, "m/s", "a controlled descent, not a fall"),
    "flight.min_battery_v": Bound(0.0, 100.0, "V", "a pack voltage; 0 = no check"),
    "flight.land_timeout_s": Bound(0.1, 3600.0, "s", "the wait for touchdown and disarm"),
}

_INDEX = re.compile(r"\[\d+\]")


def bound_for(key: str) -> Bound:
    """The :class:`Bound` of a config key (``mission.phases[3].z_m`` is looked up as ``mission.phases[].z_m``).

    Raises
    ------
    KeyError
        The key has no entry in :data:`BOUNDS` (a programming error: every number read needs one).
    """
    return BOUNDS[_INDEX.sub("[]", key)]
