"""The sections of an experiment config as frozen dataclasses, and :class:`Config` itself."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any
from collections.abc import Mapping

import numpy as np

from gcs.config.bounds import BOUNDS
from quadrotor.errors import ConfigError
from quadrotor.plant import ReducedParams
from quadrotor.sensors import SensorParams
from quadrotor.bounds import OutOfBounds, short_repr
from quadrotor.wind import WindParams

__all__ = ["Config", "ExperimentConfig", "MatrixSet", "PhaseConfig", "PdGains", "SimConfig", "EstimatorConfig",
           "FlightConfig", "AFTER_HORIZON", "MATRIX_MODES", "PHASE_KINDS", "DISTURBANCE_MODES", "Matrix"]

AFTER_HORIZON = ("pd", "terminal", "restart")
MATRIX_MODES = ("corrected", "printed")
PHASE_KINDS = ("takeoff", "hold", "circle", "land")

Matrix = tuple[tuple[float, ...], ...]


@dataclass(frozen=True)
class ExperimentConfig:
    """``[experiment]``: sampling, horizon and what the metrics measure.

    Attributes
    ----------
    name : str
    description : str
    ts_s : float
        Control period (the paper: 0.01 s).
    horizon_s : float
        Optimisation horizon t_f = N Ts.
    after_horizon : {"pd", "terminal", "restart"}
        What flies after the horizon: hand over to PD, keep the terminal
        policy (E = H / F(1)), or restart the horizon.
    duration_s : float
        Default simulated duration (``gcs sim --duration`` overrides).
    matrices : {"corrected", "printed"}
    zero_velocity_reference : bool
        Feed zero velocity references (the paper's literal circle setting; no acceleration
        references either).
    acceleration_reference : bool
        Feed the reference's acceleration forward (default): it enters the laws as a disturbance
        acceleration does, with the opposite sign (the error dynamics' drift, :mod:`gcs.mission`).
        False: the attitude references are 0, as the paper prints them.
    error_axes : tuple of str
        Position axes entering J_e (``"z"``, or ``"x", "y", "z"`` for the circle).
    """

    name: str
    ts_s: float
    horizon_s: float
    duration_s: float
    description: str = ""
    after_horizon: str = "pd"
    matrices: str = "corrected"
    zero_velocity_reference: bool = False
    acceleration_reference: bool = True
    error_axes: tuple[str, ...] = ("z",)

    @property
    def horizon_steps(self) -> int:
        """N = round(horizon_s / ts_s)."""
        return int(round(self.horizon_s / self.ts_s))


@dataclass(frozen=True)
class MatrixSet:
    """Penalty matrices of one subsystem.

    ``Q``, ``H`` (n x n) and ``R`` (m x m) are the matrices flown by default;
    ``printed`` maps a corrected name to the paper's literal matrix.
    """

    Q: Matrix
    R: Matrix
    H: Matrix
    source: str = ""
    note: str = ""
    printed: Mapping[str, Matrix] = field(default_factory=dict)
    same_as: str = ""
    mirror: bool = False

    def resolved(self, mode: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(Q, R, H)`` as arrays, the printed ones where ``mode == "printed"``."""
        pick = (lambda k: self.printed.get(k, getattr(self, k))) if mode == "printed" else (lambda k: getattr(self, k))
        return tuple(np.array(pick(k), dtype=float) for k in ("Q", "R", "H"))  # type: ignore[return-value]


@dataclass(frozen=True)
class PhaseConfig:
    """One mission phase: ``takeoff`` (ramp z to ``z_m``), ``hold``, ``circle``, ``land`` (ramp z to 0)."""

    kind: str
    duration_s: float
    z_m: float | None = None
    radius_m: float | None = None
    period_s: float | None = None
    center_m: tuple[float, float] | None = None


@dataclass(frozen=True)
class PdGains:
    """PD gains (eq. 26 names); thrust gets gravity feed-forward."""

    kp_z: float
    kd_z: float
    kp_psi: float
    kd_psi: float
    kp_x: float
    kd_x: float
    kp_y: float
    kd_y: float
    kp_theta: float
    kd_theta: float
    kp_phi: float
    kd_phi: float
    source: str = ""
    note: str = ""


#: ``[estimator] disturbance``: "auto" estimates it on a real firmware only (not in ``gcs sim``, not on
#: the built-in SITL), "on" always where the vehicle session can, "off" never.
DISTURBANCE_MODES = ("auto", "on", "off")


@dataclass(frozen=True)
class EstimatorConfig:
    """``[estimator]``: the constant-velocity position filters and the disturbance observer.

    Attributes
    ----------
    accel_noise_std_m_s2 : float
        Process noise: unmodelled acceleration.
    disturbance : {"auto", "on", "off"}
        Estimate a steady disturbance acceleration (a wrong hover throttle, a trim) and let the
        controllers compensate it (:class:`gcs.estimate.DisturbanceObserver`); "auto": on a real
        firmware, off on the built-in SITL and in ``gcs sim``.
    disturbance_time_constant_s : float
        How slowly the estimate follows the mismatch of measured and predicted acceleration [s].
        0.15 s: measured on ArduCopter and PX4 SITL, outdoor-circle (docs/FIRMWARE.md): 2 s left
        0.23-0.35 m RMS on PX4 (its inner loop realises about half the demanded rate, late), 0.15 s
        0.09-0.13 m; on ArduCopter 0.05-0.10 m either way.
    """

    accel_noise_std_m_s2: float = 2.0
    disturbance: str = "auto"
    disturbance_time_constant_s: float = 0.15


@dataclass(frozen=True)
class SimConfig:
    """``[sim]``: plant integration, wind, sensors and the default number of runs.

    ``wind_enabled`` (``[sim.wind] enabled``) says whether the wind blows by
    default: the paper's simulation columns had no disturbances, so the
    configs describe the wind but leave it off (``gcs sim --wind`` turns it on).
    """

    plant_substep_s: float = 0.001
    runs: int = 1
    seed: int = 0
    wind_enabled: bool = False
    wind: WindParams = field(default_factory=WindParams)
    sensors: SensorParams = field(default_factory=SensorParams)


@dataclass(frozen=True)
class FlightConfig:
    """``[flight]``: what ``gcs fly`` needs beyond the experiment (all optional, SI units).

    Attributes
    ----------
    output : {"attitude", "rates", "actuator"}
        Setpoint message (see :mod:`gcs.flight.output`).
    telemetry_rate_hz : float
        Rate requested for ATTITUDE and LOCAL_POSITION_NED.
    telemetry_stale_s : float
        Telemetry older than this triggers the link-loss failsafe.
    max_tilt_deg, fence_half_width_m, ceiling_m : float
        Safety envelope: tilt limit, geofence box half-width around takeoff, altitude ceiling.
    rate_gain_1_s : (3,) float
        ``K_d`` of the output adapters' body-rate demand ``omega + alpha / K_d``
        (:mod:`gcs.vehicles.output`), roll/pitch/yaw [1/s]: the controllers' own rate damping
        (65, 65, 80) makes the demand the rate their attitude loops settle to, which the
        autopilot's rate loop realises whatever its own gain and delay.
    rate_integral_max_rad : (3,) float
        The attitude output's rate-error integral (:class:`gcs.vehicles.output.RateErrorIntegral`), roll/pitch/
        yaw [rad]: the largest attitude offset it may add to the target (0: off on that axis).  It makes the
        autopilot realise the rate demand against a steady torque (a weak motor, an off-centre payload) that
        its own rate-loop integrator learns slowly.
    rate_response_s : float
        The time constant the autopilot's rate loop is modelled to follow the demand with (first order, after
        one control period), which the integral compares the measured rate against.
    tracking_lost_m, tracking_lost_s : float
        Farther than ``tracking_lost_m`` from the reference for ``tracking_lost_s`` lands the vehicle with
        exit reason ``out_of_authority`` (:class:`gcs.flight.authority.TrackingWatch`); 0 m: no watch.
    inertia_kg_m2, max_torque_nm : (3,) float
        For the actuator output: torque = I alpha, normalised by the maximum torque.
    position_std_m, velocity_std_m_s : float
        Noise assumed for LOCAL_POSITION_NED in the estimator.
    landing_speed_m_s : float
        Descent rate of the controlled landing after Ctrl-C.
    min_battery_v : float
        Preflight: refuse to arm below this voltage (0 = no check).
    land_timeout_s : float
        How long to wait for touchdown and disarm at the end.
    """

    output: str = "attitude"
    telemetry_rate_hz: float = 100.0
    telemetry_stale_s: float = 0.3
    max_tilt_deg: float = 35.0
    fence_half_width_m: float = 20.0
    ceiling_m: float = 10.0
    rate_gain_1_s: tuple[float, float, float] = (65.0, 65.0, 80.0)
    rate_integral_max_rad: tuple[float, float, float] = (0.1, 0.1, 0.2)
    rate_response_s: float = 0.04
    tracking_lost_m: float = 1.0
    tracking_lost_s: float = 2.0
    inertia_kg_m2: tuple[float, float, float] = (0.010, 0.010, 0.018)
    max_torque_nm: tuple[float, float, float] = (1.949, 1.949, 0.196)
    position_std_m: float = 0.05
    velocity_std_m_s: float = 0.05
    landing_speed_m_s: float = 0.5
    min_battery_v: float = 10.5
    land_timeout_s: float = 30.0


@dataclass(frozen=True)
class Config:
    """A whole experiment configuration."""

    source: str
    experiment: ExperimentConfig
    vehicle: ReducedParams
    mission: tuple[PhaseConfig, ...]
    loc: Mapping[str, MatrixSet]
    nlsoc: Mapping[str, MatrixSet]
    pd: PdGains
    sim: SimConfig
    estimator: EstimatorConfig
    flight: FlightConfig = field(default_factory=FlightConfig)
    raw: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)

    def with_matrices(self, mode: str) -> Config:
        """A copy flying the ``corrected`` or the ``printed`` matrices (re-validated).

        Raises
        ------
        ConfigError
            When ``mode`` is not one of :data:`MATRIX_MODES`, or the matrices fail validation.
        """
        if mode not in MATRIX_MODES:
            raise ConfigError(self.source, "experiment.matrices", f"must be one of {MATRIX_MODES}, got {mode!r}")
        return self.with_changes("experiment", matrices=mode)

    def with_changes(self, section: str, **values: Any) -> Config:
        """A copy with keys of a top-level ``section`` set (re-validated; ``raw`` records them, so a
        log's ``config.json`` is the config flown).

        Raises
        ------
        ConfigError
            When a value is invalid, naming ``section.key``.
        """
        from gcs.config.parse import parse_config

        raw = dict(self.raw)
        raw[section] = dict(raw.get(section, {}), **values)
        return parse_config(raw, self.source)

    def with_duration(self, duration_s: float) -> Config:
        """A copy whose mission ends at ``duration_s`` [s]: later phases dropped, the last one cut.

        A cut that would leave a phase shorter than one control period drops that phase
        (the mission then ends less than one period early).

        Raises
        ------
        ConfigError
            Keyed ``--duration``: not a finite number, shorter than one control period
            (``experiment.ts_s``) or longer than a week.
        """
        from gcs.config.parse import parse_config

        ts = self.experiment.ts_s
        number = isinstance(duration_s, (int, float)) and not isinstance(duration_s, bool)
        if number and duration_s < ts * (1 - 1e-9):
            raise ConfigError(self.source, "--duration",
                              f"must be at least one control period ({ts:g} s), got {short_repr(duration_s)}")
        try:
            duration = float(BOUNDS["--duration"].check(duration_s))
        except OutOfBounds as exc:
            raise ConfigError(self.source, "--duration", str(exc)) from None
        phases, t = [], 0.0
        for ph in self.raw["mission"]["phases"]:
            cut = min(float(ph["duration_s"]), duration - t)
            if cut < ts * (1 - 1e-9) and phases:
                break
            phases.append(dict(ph, duration_s=cut))
            t += float(ph["duration_s"])
            if t >= duration - 1e-12:
                break
        raw = dict(self.raw)
        raw["mission"] = dict(raw["mission"], phases=phases)
        return parse_config(raw, self.source)
