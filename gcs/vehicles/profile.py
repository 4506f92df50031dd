"""Autopilot profiles: the firmware family's conventions behind one small interface, chosen from HEARTBEAT.

A profile (:class:`~gcs.vehicles.ardupilot.ArduPilotProfile`,
:class:`~gcs.vehicles.px4.Px4Profile`) has

* ``name``, ``control_name``; ``flight_mode``, ``land_mode``, ``control_modes`` (HEARTBEAT
  ``custom_mode`` values), ``mode_name(custom_mode)``, ``stream_before_mode`` (setpoints must
  flow before the flight mode is asked for), ``hover_modes`` (a mode the vehicle takes by
  itself to hover, after which the ground station lands it);
* ``set_mode_message(link, mode)`` / ``request_mode(link, mode, on_message=...)``;
* ``configure(params, firmware, output) -> OutputParams`` and ``configure_output(...)``:
  parameters set for the flight (restored afterwards) and read for the output adapters;
* ``control_lost(status)``, ``spool_up_s(params, firmware)``, ``arming_refusal(status, result)``.

:func:`gcs.vehicles.autopilots.profile_for` picks one by HEARTBEAT ``autopilot``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gcs.errors import PreflightRefused
from gcs.link.mavlink import LinkError

__all__ = ["OutputParams", "velocity_var_m2_s2", "optional_param", "control_lost", "refuse_untaken_actuator"]


@dataclass(frozen=True)
class OutputParams:
    """What the output adapters need from the autopilot (read, and set, by a profile's ``configure``).

    Attributes
    ----------
    hover_throttle : float
        The thrust field that holds the vehicle (ArduPilot MOT_THST_HOVER, PX4 MPC_THR_HOVER).
    angle_gain_1_s : (3,) float
        The angle loop's gains [1/s] (ATC_ANG_RLL/PIT/YAW_P; MC_ROLL_P/PITCH_P/YAW_P).
    angle_accel_limit_rad_s2 : (3,) float
        The angle loop's square-root limits (ArduPilot: :func:`~gcs.vehicles.ardupilot.angle_accel_limits`;
        0: linear, as PX4's).
    rate_limit_rad_s : (3,) float
        Body-rate limits [rad/s] (0: none).
    output : str or None
        The output the parameters were set for (None: not yet; see the profile's ``configure_output``).
    drag_1_s : float or None
        Linear drag per unit mass [1/s] where the autopilot knows its vehicle's (PX4's simulator SIH:
        SIH_KDV / SIH_MASS); None: the config's ``[vehicle] drag_n_per_m_s / mass_kg``.
    horizontal_velocity_std_m_s : float or None
        The noise [m/s] to assume for the autopilot's horizontal velocity readings where the profile
        knows them to be worse than the config's ``[flight] velocity_std_m_s`` (PX4 with SIH: they lag
        its position, see :mod:`gcs.vehicles.px4`); None: the config's.
    """

    hover_throttle: float
    angle_gain_1_s: tuple[float, float, float]
    angle_accel_limit_rad_s2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rate_limit_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    output: str | None = None
    drag_1_s: float | None = None
    horizontal_velocity_std_m_s: float | None = None


def velocity_var_m2_s2(config_var: tuple[float, float, float], out: OutputParams) -> tuple[float, float, float]:
    """The variances [m^2/s^2] to fuse velocity readings (north, east, down) with: the config's
    ``config_var``, horizontally the profile's ``out.horizontal_velocity_std_m_s`` squared where set."""
    if out.horizontal_velocity_std_m_s is None:
        return config_var
    h = out.horizontal_velocity_std_m_s ** 2
    return (h, h, config_var[2])


def optional_param(params, name: str) -> float | None:
    """A parameter the flight can do without: its value, or None when the vehicle has none (quietly)."""
    params.check_interrupt()
    try:
        value = params.link.param_get(name, timeout_s=1.0, retries=1, on_message=params.on_message)
    except LinkError:
        return None
    return value if math.isfinite(value) else None


def control_lost(profile, status) -> str | None:
    """Why the vehicle no longer takes ``profile``'s setpoints (disarmed, or not in one of its
    ``control_modes``, by its own mode names), or None.  Both profiles' ``control_lost``."""
    if not status.armed:
        return "disarmed"
    if status.custom_mode not in profile.control_modes:
        return f"mode {profile.mode_name(status.custom_mode)}"
    return None


def refuse_untaken_actuator(output: str, firmware, note: str = "") -> None:
    """Refuse ``actuator`` where AUTOPILOT_VERSION says the firmware does not take it (unknown: flown).

    Raises
    ------
    PreflightRefused
        Naming the missing capability (``note``: the autopilot family's own reason, appended).
    """
    if output == "actuator" and firmware is not None and firmware.takes_actuator_targets() is False:
        raise PreflightRefused(f"{firmware.describe()} does not take SET_ACTUATOR_CONTROL_TARGET (its "
                               f"AUTOPILOT_VERSION lacks MAV_PROTOCOL_CAPABILITY_SET_ACTUATOR_TARGET{note}): fly "
                               "--output attitude or rates")
