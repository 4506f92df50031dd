"""Loading a config: finding the file, parsing TOML, validating each section into its dataclass."""

from __future__ import annotations

import dataclasses
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any
from collections.abc import Mapping

from gcs.config.bounds import (LOC_SUBSYSTEMS, MAX_HORIZON_STEPS, MAX_SUBSTEPS_PER_TICK, MIN_STALE_MESSAGES,
                               NLSOC_SUBSYSTEMS, PD_GAINS)
from gcs.config.reader import Reader, matrix_group
from gcs.config.sections import (AFTER_HORIZON, DISTURBANCE_MODES, MATRIX_MODES, PHASE_KINDS, Config, EstimatorConfig,
                                 ExperimentConfig, FlightConfig, PdGains, PhaseConfig, SimConfig)
from quadrotor.errors import ConfigError
from quadrotor.plant import ReducedParams
from quadrotor.sensors import ALTITUDE_KINDS, SensorParams
from quadrotor.bounds import short_repr
from quadrotor.wind import WindParams

__all__ = ["load_config", "parse_config", "resolve_config_path", "bundled_configs"]


def bundled_configs() -> list[str]:
    """Names of the configs shipped with the package (``configs/*.toml``)."""
    return sorted(p.name[:-5] for p in resources.files("gcs.configs").iterdir() if p.name.endswith(".toml"))


def resolve_config_path(name_or_path: str | Path) -> Path:
    """A path as given if it exists, else a bundled config by name (with or without ``.toml``).

    Raises
    ------
    ConfigError
        Neither a file nor a bundled config.
    """
    p = Path(name_or_path)
    if p.is_file():
        return p
    if p.parent != Path("."):
        raise ConfigError(str(name_or_path), "", "no such file")
    stem = p.name[:-5] if p.name.endswith(".toml") else p.name
    candidate = resources.files("gcs.configs") / f"{stem}.toml"
    if candidate.is_file():
        return Path(str(candidate))
    raise ConfigError(str(name_or_path), "",
                      f"no such file, and not a bundled config (bundled: {', '.join(bundled_configs())})")


def load_config(path: str | Path) -> Config:
    """Load and validate a TOML experiment config.

    Raises
    ------
    ConfigError
        Naming the file, the key and the reason.
    """
    p = resolve_config_path(path)
    source = str(path)
    try:
        with open(p, "rb") as fh:
            raw = tomllib.load(fh)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(source, "", f"not valid TOML: {exc}") from None
    except RecursionError:
        raise ConfigError(source, "", "not valid TOML: arrays or tables nested too deeply") from None
    except OSError as exc:
        raise ConfigError(source, "", f"cannot read: {exc.strerror or exc}") from None
    return parse_config(raw, source)


def parse_config(raw: Mapping[str, Any], source: str = "<config>") -> Config:
    """Validate a parsed TOML document (see :func:`load_config`).

    Every number must be finite and within its range of :data:`gcs.config.bounds.BOUNDS`.

    Raises
    ------
    ConfigError
        Naming ``source``, the key and the reason (for a number, the allowed range and unit).
    """
    top = Reader(raw, source, "")
    for section in ("experiment", "vehicle", "mission", "loc", "nlsoc", "pd"):
        if not top.has(section):
            raise ConfigError(source, section, "missing section")
    experiment = _experiment(top.sub("experiment"))
    ts, mode = experiment.ts_s, experiment.matrices
    v = top.sub("vehicle")
    vehicle = _vehicle(v)
    mission = _phases(top.sub("mission"), ts)
    loc = matrix_group(top.sub("loc"), LOC_SUBSYSTEMS, mode, allow_mirror=False)
    nlsoc = matrix_group(top.sub("nlsoc"), NLSOC_SUBSYSTEMS, mode, allow_mirror=True)
    p = top.sub("pd")
    pd = PdGains(**{g: p.number(g) for g in PD_GAINS}, source=p.string("source", ""), note=p.string("note", ""))
    p.done()
    sim = _sim(top.sub("sim"), ts) if top.has("sim") else SimConfig()
    tau = vehicle.mass_kg / vehicle.drag_n_per_m_s if vehicle.drag_n_per_m_s > 0 else float("inf")
    if tau < sim.plant_substep_s:
        raise v.error("drag_n_per_m_s", f"the drag time constant mass / drag = {tau:.3g} s is shorter than "
                                        f"sim.plant_substep_s = {sim.plant_substep_s:g} s: the plant would not "
                                        f"integrate stably")
    vehicle = dataclasses.replace(vehicle, max_substep_s=sim.plant_substep_s)
    estimator = EstimatorConfig()
    if top.has("estimator"):
        est = top.sub("estimator")
        d = EstimatorConfig()
        estimator = EstimatorConfig(
            accel_noise_std_m_s2=est.number("accel_noise_std_m_s2", d.accel_noise_std_m_s2),
            disturbance=est.string("disturbance", d.disturbance, choices=DISTURBANCE_MODES),
            disturbance_time_constant_s=est.number("disturbance_time_constant_s", d.disturbance_time_constant_s))
        est.done()
    flight = _flight(top.sub("flight")) if top.has("flight") else FlightConfig()
    top_z = max(ph.z_m for ph in mission if ph.z_m is not None)
    if flight.ceiling_m <= top_z:
        raise ConfigError(source, "flight.ceiling_m", f"{flight.ceiling_m:g} m is not above the mission's "
                                                       f"highest set point ({top_z:g} m)")
    top.done()
    return Config(source=source, experiment=experiment, vehicle=vehicle, mission=mission, loc=loc,
                  nlsoc=nlsoc, pd=pd, sim=sim, estimator=estimator, flight=flight, raw=raw)


def _experiment(e: Reader) -> ExperimentConfig:
    name = e.string("name")
    description = e.string("description", "")
    ts = e.number("ts_s")
    horizon = e.number("horizon_s")
    if horizon < ts:
        raise e.error("horizon_s", f"horizon {horizon:g} s is shorter than one step (ts_s = {ts:g} s)")
    steps = horizon / ts
    if abs(steps - round(steps)) > 1e-6 * max(1.0, steps):
        raise e.error("horizon_s", f"{horizon:g} s is not a whole number of steps of ts_s = {ts:g} s")
    if round(steps) > MAX_HORIZON_STEPS:
        raise e.error("horizon_s", f"{round(steps):.3g} steps; at most {MAX_HORIZON_STEPS:.0e} are supported")
    duration = e.number("duration_s")
    if duration < ts:
        raise e.error("duration_s", f"{duration:g} s is shorter than one step (ts_s = {ts:g} s)")
    after = e.string("after_horizon", "pd", choices=AFTER_HORIZON)
    mode = e.string("matrices", "corrected", choices=MATRIX_MODES)
    zero_vel = e.boolean("zero_velocity_reference", False)
    accel_ref = e.boolean("acceleration_reference", True)
    axes = e.raw("error_axes", ["z"])
    if (not isinstance(axes, list) or not axes or any(not isinstance(a, str) or a not in ("x", "y", "z") for a in axes)
            or len(set(axes)) != len(axes)):
        raise e.error("error_axes", f"must be a non-empty list of distinct 'x', 'y', 'z'; got {short_repr(axes)}")
    e.done()
    return ExperimentConfig(name=name, description=description, ts_s=ts, horizon_s=horizon, duration_s=duration,
                            after_horizon=after, matrices=mode, zero_velocity_reference=zero_vel,
                            acceleration_reference=accel_ref, error_axes=tuple(axes))


def _vehicle(v: Reader) -> ReducedParams:
    d = ReducedParams()
    vehicle = ReducedParams(
        mass_kg=v.number("mass_kg"),
        gravity_m_s2=v.number("gravity_m_s2", 9.81),
        max_thrust_n=v.number("max_thrust_n", d.max_thrust_n),
        max_angular_accel_rad_s2=v.number("max_angular_accel_rad_s2", d.max_angular_accel_rad_s2),
        drag_n_per_m_s=v.number("drag_n_per_m_s", d.drag_n_per_m_s),
    )
    if vehicle.max_thrust_n <= vehicle.mass_kg * vehicle.gravity_m_s2:
        raise v.error("max_thrust_n", f"{vehicle.max_thrust_n:g} N cannot lift {vehicle.mass_kg:g} kg "
                                      f"(hover needs {vehicle.mass_kg * vehicle.gravity_m_s2:g} N)")
    v.done()
    return vehicle


def _phases(reader: Reader, ts: float) -> tuple[PhaseConfig, ...]:
    raw = reader.raw("phases")
    if not isinstance(raw, list) or not raw:
        raise reader.error("phases", "must be a non-empty array of tables ([[mission.phases]])")
    phases = []
    have_z = False
    for i, t in enumerate(raw):
        r = Reader(t, reader.source, f"{reader.key('phases')}[{i}]")
        kind = r.string("kind", choices=PHASE_KINDS)
        duration = r.number("duration_s")
        if duration < ts * (1 - 1e-9):
            raise r.error("duration_s", f"{duration:g} s is shorter than one control period (ts_s = {ts:g} s)")
        z = radius = period = None
        center = None
        if kind == "takeoff":
            z = r.number("z_m")
            have_z = True
        elif kind == "circle":
            radius = r.number("radius_m")
            period = r.number("period_s")
            if r.has("center_m"):
                cx, cy = r.vector("center_m", (0.0, 0.0), "x, y in metres")
                center = (cx, cy)
        if kind in ("hold", "circle", "land") and not have_z:
            raise r.error("kind", f"a {kind!r} phase needs a takeoff phase before it")
        r.done()
        phases.append(PhaseConfig(kind, duration, z, radius, period, center))
    reader.done()
    return tuple(phases)


def _sim(s: Reader, ts: float) -> SimConfig:
    d = SimConfig()
    substep = s.number("plant_substep_s", d.plant_substep_s)
    if substep > ts:
        raise s.error("plant_substep_s", f"{substep:g} s is longer than the control period ts_s = {ts:g} s")
    if ts / substep > MAX_SUBSTEPS_PER_TICK * (1 + 1e-9):
        raise s.error("plant_substep_s", f"{substep:g} s makes {ts / substep:.3g} sub-steps per control period "
                                         f"(ts_s = {ts:g} s): at most {MAX_SUBSTEPS_PER_TICK}, "
                                         f"i.e. plant_substep_s >= {ts / MAX_SUBSTEPS_PER_TICK:g} s")
    runs = s.integer("runs", d.runs)
    seed = s.integer("seed", d.seed)
    wind, wind_enabled = WindParams(), False
    if s.has("wind"):
        w = s.sub("wind")
        wind_enabled = w.boolean("enabled", True)
        wind = WindParams(mean_speed_m_s=w.number("mean_speed_m_s", 0.0), direction_deg=w.number("direction_deg", None),
                          vertical_m_s=w.number("vertical_m_s", 0.0), gust_std_m_s=w.number("gust_std_m_s", 0.0),
                          gust_tau_s=w.number("gust_tau_s", 2.0))
        w.done()
    sensors = SensorParams()
    if s.has("sensors"):
        n = s.sub("sensors")
        sensors = SensorParams(
            altitude=n.string("altitude", "ideal", choices=ALTITUDE_KINDS),
            **{k: n.number(k, 0.0) for k in ("altitude_noise_std_m", "altitude_resolution_m", "position_noise_std_m",
                                             "attitude_noise_std_rad", "rate_noise_std_rad_s")})
        n.done()
    s.done()
    return SimConfig(plant_substep_s=substep, runs=runs, seed=seed, wind_enabled=wind_enabled, wind=wind,
                     sensors=sensors)


def _flight(f: Reader) -> FlightConfig:
    d = FlightConfig()
    rpy = "roll, pitch, yaw"
    out = FlightConfig(
        output=f.string("output", d.output, choices=("attitude", "rates", "actuator")),
        rate_gain_1_s=f.vector("rate_gain_1_s", d.rate_gain_1_s, rpy),  # type: ignore[arg-type]
        rate_integral_max_rad=f.vector("rate_integral_max_rad", d.rate_integral_max_rad, rpy),  # type: ignore[arg-type]
        inertia_kg_m2=f.vector("inertia_kg_m2", d.inertia_kg_m2, rpy),  # type: ignore[arg-type]
        max_torque_nm=f.vector("max_torque_nm", d.max_torque_nm, rpy),  # type: ignore[arg-type]
        **{k: f.number(k, getattr(d, k)) for k in (
            "telemetry_rate_hz", "telemetry_stale_s", "rate_response_s", "tracking_lost_m", "tracking_lost_s",
            "max_tilt_deg", "fence_half_width_m", "ceiling_m", "position_std_m", "velocity_std_m_s",
            "landing_speed_m_s", "min_battery_v", "land_timeout_s")},
    )
    messages = out.telemetry_rate_hz * out.telemetry_stale_s
    if messages < MIN_STALE_MESSAGES * (1 - 1e-9):
        raise f.error("telemetry_rate_hz", f"{out.telemetry_rate_hz:g} Hz is too slow for telemetry_stale_s = "
                                           f"{out.telemetry_stale_s:g} s: the stale timeout must allow at least "
                                           f"{MIN_STALE_MESSAGES} messages (telemetry_rate_hz >= "
                                           f"{MIN_STALE_MESSAGES / out.telemetry_stale_s:g} Hz, or telemetry_stale_s "
                                           f">= {MIN_STALE_MESSAGES / out.telemetry_rate_hz:g} s)")
    f.done()
    return out
