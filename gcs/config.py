"""Experiment configuration: TOML files loaded into validated, frozen dataclasses.

A config describes one of the paper's experiments: sampling, horizon, vehicle,
mission phases, the penalty matrices of LOC and NLSOC, the PD gains, and the
simulation's wind, sensors and estimator.  Loading rejects, naming the file,
the key and the reason: unknown keys, missing sections or keys, wrong types
and shapes, non-symmetric or indefinite Q/H, R not positive definite,
``ts_s <= 0`` and a horizon shorter than one step.

Matrices may be written as a number (1x1), a flat list (diagonal) or a list
of rows.  Where the paper's printed matrix is wrong (``../shared/paper/NOTES.md``,
erratum 7) the config gives the corrected matrix under its name (``Q``), the
literal printed one under ``<name>_printed`` and lists the name in
``corrected``.  ``[experiment] matrices = "printed"`` (or ``gcs sim
--matrices printed``) selects the printed ones; the symmetry and
definiteness checks of Q and H are then skipped, since the printed matrices
fail them by construction.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from gcs.errors import ConfigError
from sitl.reduced import ReducedParams
from sitl.sensors import ALTITUDE_KINDS, SensorParams
from sitl.wind import WindParams

__all__ = [
    "Config", "ExperimentConfig", "MatrixSet", "PhaseConfig", "PdGains", "SimConfig",
    "EstimatorConfig", "FlightConfig", "load_config", "parse_config", "resolve_config_path", "bundled_configs",
    "AFTER_HORIZON", "MATRIX_MODES", "PHASE_KINDS",
]

AFTER_HORIZON = ("pd", "terminal", "restart")
#: Longest horizon in steps (a LOC gain table row per step; 10^7 steps = 28 h at 10 ms).
MAX_HORIZON_STEPS = 10_000_000
MATRIX_MODES = ("corrected", "printed")
PHASE_KINDS = ("takeoff", "hold", "circle", "land")

Matrix = tuple[tuple[float, ...], ...]

# Subsystem dimensions: (state size n, input size m).
LOC_SUBSYSTEMS = {"z": (2, 1), "psi": (2, 1), "y_phi": (4, 1), "x_theta": (4, 1)}
NLSOC_SUBSYSTEMS = {"z_psi": (4, 2), "y_phi": (4, 1), "x_theta": (4, 1)}


# --------------------------------------------------------------------------- dataclasses

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
        Feed zero velocity references (the paper's literal circle setting).
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


@dataclass(frozen=True)
class EstimatorConfig:
    """``[estimator]``: process noise of the constant-velocity position filters."""

    accel_noise_std_m_s2: float = 2.0


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
        The autopilot's rate-loop gain (angular acceleration per rate error), roll/pitch/yaw.
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
    rate_gain_1_s: tuple[float, float, float] = (25.0, 25.0, 10.0)
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

    def with_matrices(self, mode: str) -> "Config":
        """A copy flying the ``corrected`` or the ``printed`` matrices (re-validated)."""
        if mode not in MATRIX_MODES:
            raise ConfigError(self.source, "experiment.matrices", f"must be one of {MATRIX_MODES}, got {mode!r}")
        return self.with_changes("experiment", matrices=mode)

    def with_changes(self, section: str, **values: Any) -> "Config":
        """A copy with keys of a top-level ``section`` set (re-validated; ``raw`` records them, so a
        log's ``config.json`` is the config flown).

        Raises
        ------
        ConfigError
            When a value is invalid, naming ``section.key``.
        """
        raw = {k: v for k, v in self.raw.items()}
        raw[section] = dict(raw.get(section, {}), **values)
        return parse_config(raw, self.source)

    def with_duration(self, duration_s: float) -> "Config":
        """A copy whose mission ends at ``duration_s`` [s]: later phases dropped, the last one cut.

        Raises
        ------
        ConfigError
            When ``duration_s`` is not positive.
        """
        if not (isinstance(duration_s, (int, float)) and math.isfinite(duration_s) and duration_s > 0):
            raise ConfigError(self.source, "--duration", f"must be a finite number > 0, got {duration_s!r}")
        phases, t = [], 0.0
        for ph in self.raw["mission"]["phases"]:
            if t >= duration_s - 1e-12:
                break
            d = float(ph["duration_s"])
            phases.append(dict(ph, duration_s=min(d, duration_s - t)))
            t += d
        raw = {k: v for k, v in self.raw.items()}
        raw["mission"] = dict(raw["mission"], phases=phases)
        return parse_config(raw, self.source)


# --------------------------------------------------------------------------- loading

def bundled_configs() -> list[str]:
    """Names of the configs shipped with the package (``configs/*.toml``)."""
    return sorted(p.name[:-5] for p in resources.files("gcs.configs").iterdir() if p.name.endswith(".toml"))


def resolve_config_path(name_or_path: str | Path) -> Path:
    """A path as given if it exists, else a bundled config by name (with or without ``.toml``)."""
    p = Path(name_or_path)
    if p.is_file():
        return p
    if p.parent != Path("."):
        raise ConfigError(str(name_or_path), "", "no such file")
    stem = p.name[:-5] if p.name.endswith(".toml") else p.name
    candidate = resources.files("gcs.configs") / f"{stem}.toml"
    if candidate.is_file():
        return Path(str(candidate))
    raise ConfigError(str(name_or_path), "", f"no such file, and not a bundled config (bundled: {', '.join(bundled_configs())})")


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
    except OSError as exc:
        raise ConfigError(source, "", f"cannot read: {exc.strerror or exc}") from None
    return parse_config(raw, source)


class _Reader:
    """Takes keys out of one TOML table, then complains about whatever is left."""

    def __init__(self, table: Any, source: str, where: str) -> None:
        if not isinstance(table, dict):
            raise ConfigError(source, where, f"must be a table, got {type(table).__name__}")
        self.table = dict(table)
        self.source = source
        self.where = where

    def key(self, name: str) -> str:
        return f"{self.where}.{name}" if self.where else name

    def error(self, name: str, reason: str) -> ConfigError:
        return ConfigError(self.source, self.key(name), reason)

    def has(self, name: str) -> bool:
        return name in self.table

    def raw(self, name: str, default: Any = ...) -> Any:
        if name in self.table:
            return self.table.pop(name)
        if default is ...:
            raise self.error(name, "missing")
        return default

    def number(self, name: str, default: Any = ..., *, positive: bool = False, nonneg: bool = False) -> float:
        v = self.raw(name, default)
        if v is None:
            return v
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.error(name, f"must be a number, got {v!r}")
        v = float(v)
        if not math.isfinite(v):
            raise self.error(name, f"must be finite, got {v!r}")
        if positive and not v > 0:
            raise self.error(name, f"must be > 0, got {v:g}")
        if nonneg and v < 0:
            raise self.error(name, f"must be >= 0, got {v:g}")
        return v

    def integer(self, name: str, default: Any = ..., *, minimum: int | None = None) -> int:
        v = self.raw(name, default)
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.error(name, f"must be an integer, got {v!r}")
        if minimum is not None and v < minimum:
            raise self.error(name, f"must be >= {minimum}, got {v}")
        return v

    def string(self, name: str, default: Any = ..., *, choices: tuple[str, ...] | None = None) -> str:
        v = self.raw(name, default)
        if not isinstance(v, str):
            raise self.error(name, f"must be a string, got {v!r}")
        if choices is not None and v not in choices:
            raise self.error(name, f"must be one of {', '.join(choices)}; got {v!r}")
        return v

    def boolean(self, name: str, default: Any = ...) -> bool:
        v = self.raw(name, default)
        if not isinstance(v, bool):
            raise self.error(name, f"must be true or false, got {v!r}")
        return v

    def sub(self, name: str, default: Any = ...) -> "_Reader":
        return _Reader(self.raw(name, default), self.source, self.key(name))

    def done(self) -> None:
        if self.table:
            names = ", ".join(sorted(self.table))
            first = sorted(self.table)[0]
            raise self.error(first, f"unknown key{'s' if len(self.table) > 1 else ''} ({names})")


def _matrix(reader: _Reader, name: str, n: int) -> Matrix:
    """A number (1x1), a flat list (diagonal) or n rows of n numbers."""
    v = reader.raw(name)

    def num(x: Any) -> float:
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(float(x)):
            raise reader.error(name, f"entries must be finite numbers, got {x!r}")
        return float(x)

    if isinstance(v, (int, float)) and not isinstance(v, bool):
        rows = [[num(v)]]
    elif isinstance(v, list) and v and all(not isinstance(r, list) for r in v):
        d = [num(x) for x in v]
        rows = [[d[i] if i == j else 0.0 for j in range(len(d))] for i in range(len(d))]
    elif isinstance(v, list) and v and all(isinstance(r, list) for r in v):
        rows = [[num(x) for x in r] for r in v]
    else:
        raise reader.error(name, f"must be a number, a list (diagonal) or a list of rows; got {v!r}")
    shape = (len(rows), {len(r) for r in rows})
    if shape[0] != n or shape[1] != {n}:
        cols = "/".join(str(c) for c in sorted(shape[1]))
        raise reader.error(name, f"wrong shape: expected {n}x{n}, got {shape[0]}x{cols}")
    return tuple(tuple(r) for r in rows)


def _check_symmetric(reader: _Reader, name: str, mat: Matrix, *, definite: bool) -> None:
    a = np.array(mat)
    n = a.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            if not math.isclose(a[i, j], a[j, i], rel_tol=1e-9, abs_tol=1e-12):
                raise reader.error(name, f"not symmetric ({name}[{i + 1},{j + 1}] = {a[i, j]:g} != "
                                         f"{name}[{j + 1},{i + 1}] = {a[j, i]:g})")
    eig = np.linalg.eigvalsh(0.5 * (a + a.T))
    scale = max(1.0, float(np.max(np.abs(eig))))
    if definite and eig.min() <= 1e-12 * scale:
        raise reader.error(name, f"not positive definite (smallest eigenvalue {eig.min():.6g})")
    if not definite and eig.min() < -1e-9 * scale:
        raise reader.error(name, f"indefinite (eigenvalue {eig.min():.6g} < 0); Q and H must be positive semidefinite")


def _matrix_set(reader: _Reader, n: int, m: int, mode: str, allow_same_as: tuple[str, ...],
                allow_mirror: bool) -> MatrixSet:
    source = reader.string("source", "")
    note = reader.string("note", "")
    if reader.has("same_as"):
        same_as = reader.string("same_as", choices=allow_same_as)
        if reader.has("mirror") and not allow_mirror:
            raise reader.error("mirror", "only NLSOC mirrors x-theta weights (LOC has the sign in A(2,3))")
        mirror = reader.boolean("mirror", False)
        reader.done()
        # Filled in by the caller from the referenced subsystem.
        return MatrixSet(Q=(), R=(), H=(), source=source, note=note, same_as=same_as, mirror=mirror)
    corrected = reader.raw("corrected", [])
    if not isinstance(corrected, list) or not all(isinstance(c, str) for c in corrected):
        raise reader.error("corrected", f"must be a list of matrix names, got {corrected!r}")
    dims = {"Q": n, "H": n, "R": m}
    mats = {k: _matrix(reader, k, d) for k, d in dims.items()}
    printed: dict[str, Matrix] = {}
    for k in corrected:
        if k not in dims:
            raise reader.error("corrected", f"unknown matrix {k!r} (expected Q, R or H)")
        if not reader.has(f"{k}_printed"):
            raise reader.error(f"{k}_printed", f"missing: {k} is listed in 'corrected', so the printed matrix must be given")
        printed[k] = _matrix(reader, f"{k}_printed", dims[k])
    for k in dims:
        if reader.has(f"{k}_printed"):
            raise reader.error(f"{k}_printed", f"given but {k!r} is not listed in 'corrected'")
    reader.done()
    # The printed matrices are flown as printed (erratum 7: they fail these checks by construction);
    # every other matrix is checked in both modes.
    for k in ("Q", "H"):
        if not (mode == "printed" and k in printed):
            _check_symmetric(reader, k, mats[k], definite=False)
    if mode == "printed" and "R" in printed:
        _check_symmetric(reader, "R_printed", printed["R"], definite=True)
    else:
        _check_symmetric(reader, "R", mats["R"], definite=True)
    return MatrixSet(Q=mats["Q"], R=mats["R"], H=mats["H"], source=source, note=note, printed=printed)


def _matrix_group(reader: _Reader, dims: dict[str, tuple[int, int]], mode: str, *,
                  allow_mirror: bool) -> dict[str, MatrixSet]:
    out: dict[str, MatrixSet] = {}
    for name, (n, m) in dims.items():
        others = tuple(k for k in dims if k != name and dims[k] == (n, m))
        out[name] = _matrix_set(reader.sub(name), n, m, mode, others, allow_mirror)
    reader.done()
    for name, ms in out.items():
        if ms.same_as:
            ref = out[ms.same_as]
            if ref.same_as:
                raise reader.error(f"{name}.same_as", f"{ms.same_as!r} is itself defined by same_as")
            out[name] = dataclasses.replace(ref, source=ms.source or ref.source, note=ms.note,
                                            same_as=ms.same_as, mirror=ms.mirror)
    return out


def _phases(reader: _Reader) -> tuple[PhaseConfig, ...]:
    raw = reader.raw("phases")
    if not isinstance(raw, list) or not raw:
        raise reader.error("phases", "must be a non-empty array of tables ([[mission.phases]])")
    phases = []
    have_z = False
    for i, t in enumerate(raw):
        r = _Reader(t, reader.source, f"{reader.key('phases')}[{i}]")
        kind = r.string("kind", choices=PHASE_KINDS)
        duration = r.number("duration_s", positive=True)
        z = radius = period = None
        center = None
        if kind == "takeoff":
            z = r.number("z_m", positive=True)
            have_z = True
        elif kind == "circle":
            radius = r.number("radius_m", positive=True)
            period = r.number("period_s", positive=True)
            if r.has("center_m"):
                c = r.raw("center_m")
                if not (isinstance(c, list) and len(c) == 2 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in c)):
                    raise r.error("center_m", f"must be [x, y] in metres, got {c!r}")
                center = (float(c[0]), float(c[1]))
        if kind in ("hold", "circle", "land") and not have_z:
            raise r.error("kind", f"a {kind!r} phase needs a takeoff phase before it")
        r.done()
        phases.append(PhaseConfig(kind, duration, z, radius, period, center))
    reader.done()
    return tuple(phases)


def parse_config(raw: Mapping[str, Any], source: str = "<config>") -> Config:
    """Validate a parsed TOML document (see :func:`load_config`)."""
    top = _Reader(raw, source, "")
    for section in ("experiment", "vehicle", "mission", "loc", "nlsoc", "pd"):
        if not top.has(section):
            raise ConfigError(source, section, "missing section")

    e = top.sub("experiment")
    name = e.string("name")
    description = e.string("description", "")
    ts = e.number("ts_s")
    if not ts > 0:
        raise e.error("ts_s", f"must be > 0, got {ts:g}")
    horizon = e.number("horizon_s")
    if horizon < ts:
        raise e.error("horizon_s", f"horizon {horizon:g} s is shorter than one step (ts_s = {ts:g} s)")
    steps = horizon / ts
    if abs(steps - round(steps)) > 1e-6 * max(1.0, steps):
        raise e.error("horizon_s", f"{horizon:g} s is not a whole number of steps of ts_s = {ts:g} s")
    if round(steps) > MAX_HORIZON_STEPS:
        raise e.error("horizon_s", f"{round(steps):.3g} steps; at most {MAX_HORIZON_STEPS:.0e} are supported")
    duration = e.number("duration_s", positive=True)
    if duration < ts:
        raise e.error("duration_s", f"{duration:g} s is shorter than one step (ts_s = {ts:g} s)")
    after = e.string("after_horizon", "pd", choices=AFTER_HORIZON)
    mode = e.string("matrices", "corrected", choices=MATRIX_MODES)
    zero_vel = e.boolean("zero_velocity_reference", False)
    axes = e.raw("error_axes", ["z"])
    if not isinstance(axes, list) or not axes or any(a not in ("x", "y", "z") for a in axes) or len(set(axes)) != len(axes):
        raise e.error("error_axes", f"must be a non-empty list of distinct 'x', 'y', 'z'; got {axes!r}")
    e.done()
    experiment = ExperimentConfig(name=name, description=description, ts_s=ts, horizon_s=horizon,
                                  duration_s=duration, after_horizon=after, matrices=mode,
                                  zero_velocity_reference=zero_vel, error_axes=tuple(axes))

    v = top.sub("vehicle")
    defaults = ReducedParams()
    vehicle = ReducedParams(
        mass_kg=v.number("mass_kg", positive=True),
        gravity_m_s2=v.number("gravity_m_s2", 9.81, positive=True),
        max_thrust_n=v.number("max_thrust_n", defaults.max_thrust_n, positive=True),
        max_angular_accel_rad_s2=v.number("max_angular_accel_rad_s2", defaults.max_angular_accel_rad_s2, positive=True),
        drag_n_per_m_s=v.number("drag_n_per_m_s", defaults.drag_n_per_m_s, nonneg=True),
    )
    if vehicle.max_thrust_n <= vehicle.mass_kg * vehicle.gravity_m_s2:
        raise v.error("max_thrust_n", f"{vehicle.max_thrust_n:g} N cannot lift {vehicle.mass_kg:g} kg "
                                      f"(hover needs {vehicle.mass_kg * vehicle.gravity_m_s2:g} N)")
    v.done()

    mr = top.sub("mission")
    mission = _phases(mr)

    loc = _matrix_group(top.sub("loc"), LOC_SUBSYSTEMS, mode, allow_mirror=False)
    nlsoc = _matrix_group(top.sub("nlsoc"), NLSOC_SUBSYSTEMS, mode, allow_mirror=True)

    p = top.sub("pd")
    gains = {f.name: p.number(f.name, nonneg=True) for f in dataclasses.fields(PdGains) if f.name not in ("source", "note")}
    pd = PdGains(**gains, source=p.string("source", ""), note=p.string("note", ""))
    p.done()

    sim = SimConfig()
    if top.has("sim"):
        s = top.sub("sim")
        substep = s.number("plant_substep_s", sim.plant_substep_s, positive=True)
        if substep > ts:
            raise s.error("plant_substep_s", f"{substep:g} s is longer than the control period ts_s = {ts:g} s")
        runs = s.integer("runs", 1, minimum=1)
        seed = s.integer("seed", 0, minimum=0)
        wind = WindParams()
        wind_enabled = False
        if s.has("wind"):
            w = s.sub("wind")
            wind_enabled = w.boolean("enabled", True)
            direction = w.number("direction_deg", None)
            wind = WindParams(mean_speed_m_s=w.number("mean_speed_m_s", 0.0, nonneg=True),
                              direction_deg=direction,
                              vertical_m_s=w.number("vertical_m_s", 0.0),
                              gust_std_m_s=w.number("gust_std_m_s", 0.0, nonneg=True),
                              gust_tau_s=w.number("gust_tau_s", 2.0, positive=True))
            w.done()
        sensors = SensorParams()
        if s.has("sensors"):
            n = s.sub("sensors")
            sensors = SensorParams(
                altitude=n.string("altitude", "ideal", choices=ALTITUDE_KINDS),
                altitude_noise_std_m=n.number("altitude_noise_std_m", 0.0, nonneg=True),
                altitude_resolution_m=n.number("altitude_resolution_m", 0.0, nonneg=True),
                position_noise_std_m=n.number("position_noise_std_m", 0.0, nonneg=True),
                attitude_noise_std_rad=n.number("attitude_noise_std_rad", 0.0, nonneg=True),
                rate_noise_std_rad_s=n.number("rate_noise_std_rad_s", 0.0, nonneg=True),
            )
            n.done()
        s.done()
        sim = SimConfig(plant_substep_s=substep, runs=runs, seed=seed, wind_enabled=wind_enabled,
                        wind=wind, sensors=sensors)
    vehicle = dataclasses.replace(vehicle, max_substep_s=sim.plant_substep_s)

    estimator = EstimatorConfig()
    if top.has("estimator"):
        est = top.sub("estimator")
        estimator = EstimatorConfig(accel_noise_std_m_s2=est.number("accel_noise_std_m_s2", 2.0, positive=True))
        est.done()

    flight = FlightConfig()
    if top.has("flight"):
        flight = _flight(top.sub("flight"), flight)
    top_z = max(ph.z_m for ph in mission if ph.z_m is not None)
    if flight.ceiling_m <= top_z:
        raise ConfigError(source, "flight.ceiling_m", f"{flight.ceiling_m:g} m is not above the mission's "
                                                       f"highest set point ({top_z:g} m)")

    top.done()
    return Config(source=source, experiment=experiment, vehicle=vehicle, mission=mission, loc=loc,
                  nlsoc=nlsoc, pd=pd, sim=sim, estimator=estimator, flight=flight, raw=raw)


def _vector3(reader: _Reader, name: str, default: tuple[float, float, float]) -> tuple[float, float, float]:
    v = reader.raw(name, list(default))
    if not (isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                        and math.isfinite(x) and x > 0 for x in v)):
        raise reader.error(name, f"must be three positive numbers (roll, pitch, yaw), got {v!r}")
    return (float(v[0]), float(v[1]), float(v[2]))


def _flight(f: _Reader, d: FlightConfig) -> FlightConfig:
    out = FlightConfig(
        output=f.string("output", d.output, choices=("attitude", "rates", "actuator")),
        telemetry_rate_hz=f.number("telemetry_rate_hz", d.telemetry_rate_hz, positive=True),
        telemetry_stale_s=f.number("telemetry_stale_s", d.telemetry_stale_s, positive=True),
        max_tilt_deg=f.number("max_tilt_deg", d.max_tilt_deg, positive=True),
        fence_half_width_m=f.number("fence_half_width_m", d.fence_half_width_m, positive=True),
        ceiling_m=f.number("ceiling_m", d.ceiling_m, positive=True),
        rate_gain_1_s=_vector3(f, "rate_gain_1_s", d.rate_gain_1_s),
        inertia_kg_m2=_vector3(f, "inertia_kg_m2", d.inertia_kg_m2),
        max_torque_nm=_vector3(f, "max_torque_nm", d.max_torque_nm),
        position_std_m=f.number("position_std_m", d.position_std_m, positive=True),
        velocity_std_m_s=f.number("velocity_std_m_s", d.velocity_std_m_s, positive=True),
        landing_speed_m_s=f.number("landing_speed_m_s", d.landing_speed_m_s, positive=True),
        min_battery_v=f.number("min_battery_v", d.min_battery_v, nonneg=True),
        land_timeout_s=f.number("land_timeout_s", d.land_timeout_s, positive=True),
    )
    if out.max_tilt_deg >= 90:
        raise f.error("max_tilt_deg", f"must be < 90, got {out.max_tilt_deg:g}")
    f.done()
    return out
