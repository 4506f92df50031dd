"""The campaign's plan: experiments, seeded disturbances, and one job per flight.

Everything here is a pure function of its arguments: :func:`draw_disturbances` of
``(campaign seed, experiment, run index)`` only (never of the controller, so every
controller meets the same wind, sensor noise and initial attitude in run ``i``, as in
``gcs sim``), and :func:`plan_campaign` of the options and of what ``gcs fly`` offers
.

The disturbances of an outdoor run (the built-in MAVLink SITL):

* the SITL's ``--seed`` (sensor noise, gusts), drawn as a 31-bit integer;
* wind ``--wind SPEED,DIR,GUST,TAU``: speed ``wind_scale x [sim.wind] mean_speed_m_s x
  U(0.5, 1.5)``, direction ``U(0, 360)`` deg, gust standard deviation
  ``wind_scale x gust_std_m_s``, correlation time ``gust_tau_s`` (the config's
  ``[sim.wind]``, which describes the paper's cross wind);
* initial attitude ``--start-attitude ROLL,PITCH,YAW``: roll and pitch ``U(-tilt, tilt)``,
  yaw ``U(-yaw, yaw)`` deg (resting on a slight slope, pointing a little off north).

The indoor rig (``sitl --rig 4dof``) has no wind and starts level on its stand: its
runs vary the seed (ultrasonic and IMU noise) only.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from gcs.api import FlightSpec
from gcs.campaign.errors import CampaignError
from gcs.control import CONTROLLERS

__all__ = ["ExperimentSpec", "EXPERIMENTS", "EXPERIMENT_CHOICES", "Disturbances", "DisturbanceModel",
           "draw_disturbances", "Job", "Plan", "CampaignOptions", "plan_campaign", "resolve_experiments",
           "parse_durations", "default_timeout_s"]


@dataclass(frozen=True)
class ExperimentSpec:
    """One of the paper's experiments as the campaign flies it.

    Attributes
    ----------
    name : str
        The campaign's name for it (also the bundled config's name).
    config : str
        ``gcs fly --config`` argument.
    tables : tuple of int
        The paper's tables it reproduces.
    rig : str or None
        ``gcs fly --rig`` kind (the indoor 4-DOF rig), None for the MAVLink SITL.
    campaign_duration_s : float or None
        Mission cut (``gcs fly --duration``) in a full campaign; None = the whole mission.
    optimality : bool
        Whether the campaign writes the altitude optimality gap
        (:func:`gcs.optimal_affine.optimality_table`) for it.
    """

    name: str
    config: str
    tables: tuple[int, ...]
    rig: str | None = None
    campaign_duration_s: float | None = None
    optimality: bool = False


#: The experiments, in the paper's order.
EXPERIMENTS: dict[str, ExperimentSpec] = {
    "indoor-4dof": ExperimentSpec("indoor-4dof", "indoor-4dof", (1,), rig="4dof", optimality=True),
    "outdoor-altitude": ExperimentSpec("outdoor-altitude", "outdoor-altitude", (2, 3), campaign_duration_s=120.0,
                                       optimality=True),
    "outdoor-circle": ExperimentSpec("outdoor-circle", "outdoor-circle", (4, 5)),
}

#: ``--experiment`` choices.
EXPERIMENT_CHOICES = tuple(EXPERIMENTS) + ("all",)


def resolve_experiments(names: str | Sequence[str]) -> list[ExperimentSpec]:
    """The specs of ``names`` ("all", one name, a comma-separated list or a sequence), in the paper's order.

    Raises
    ------
    CampaignError
        For an unknown name or an empty list.
    """
    items = names.split(",") if isinstance(names, str) else list(names)
    items = [n.strip() for n in items if n.strip()]
    if not items:
        raise CampaignError("--experiment", "", f"expected one of {', '.join(EXPERIMENT_CHOICES)}")
    if "all" in items:
        return list(EXPERIMENTS.values())
    for n in items:
        if n not in EXPERIMENTS:
            raise CampaignError("--experiment", "", f"unknown experiment {n!r} (choose from {', '.join(EXPERIMENT_CHOICES)})")
    return [spec for name, spec in EXPERIMENTS.items() if name in items]


@dataclass(frozen=True)
class DisturbanceModel:
    """How large the drawn disturbances are (see the module docstring).

    Attributes
    ----------
    wind_scale : float
        Multiplies the config's ``[sim.wind]`` speed and gusts; 0 = calm air (the
        paper's simulations had no disturbances).
    tilt_deg : float
        Bound of the initial roll and pitch [deg].
    yaw_deg : float
        Bound of the initial yaw [deg].
    """

    wind_scale: float = 1.0
    tilt_deg: float = 2.0
    yaw_deg: float = 10.0


@dataclass(frozen=True)
class Disturbances:
    """The seed-dependent conditions of one run (the same for every controller).

    Attributes
    ----------
    seed : int
        The SITL's ``--seed`` (``gcs fly --seed``): sensor noise and gusts.
    wind : tuple of 4 float or None
        ``(speed m/s, direction deg, gust std m/s, gust tau s)``; None = calm.
    start_attitude_deg : tuple of 3 float or None
        ``(roll, pitch, yaw)``; None = level, pointing north.
    """

    seed: int
    wind: tuple[float, float, float, float] | None = None
    start_attitude_deg: tuple[float, float, float] | None = None

    def sitl_args(self) -> tuple[str, ...]:
        """The ``sitl`` options (without ``--seed``, which ``gcs fly --seed`` passes)."""
        out = []
        if self.wind is not None:
            out.append("--wind=" + ",".join(_num(v) for v in self.wind))
        if self.start_attitude_deg is not None:
            out.append("--start-attitude=" + ",".join(_num(v) for v in self.start_attitude_deg))
        return tuple(out)

    def to_json(self) -> dict:
        return {"seed": self.seed, "wind": list(self.wind) if self.wind else None,
                "start_attitude_deg": list(self.start_attitude_deg) if self.start_attitude_deg else None}


def _num(v: float) -> str:
    return f"{v:g}" if float(v).is_integer() else repr(float(v))


def _stream(name: str) -> int:
    """A stable integer for a name (``hash`` changes between interpreters)."""
    return zlib.crc32(name.encode())


def draw_disturbances(seed: int, experiment: str, run: int, *, mavlink: bool = True,
                      wind: tuple[float, float, float] = (0.0, 0.0, 2.0),
                      model: DisturbanceModel = DisturbanceModel()) -> Disturbances:
    """The disturbances of run ``run`` of ``experiment`` in a campaign seeded ``seed``.

    Parameters
    ----------
    seed : int
        Campaign seed (>= 0).
    experiment : str
    run : int
        Run index (>= 0).
    mavlink : bool
        The MAVLink SITL (wind and initial attitude apply); False for the indoor rig.
    wind : (mean speed m/s, gust std m/s, gust tau s)
        The config's ``[sim.wind]``.
    model : DisturbanceModel

    Returns
    -------
    Disturbances
        A pure function of the arguments; values are rounded (4 decimals) so that the
        command line carries them exactly.
    """
    if seed < 0 or run < 0:
        raise CampaignError("--seed", "", f"seed and run must be >= 0, got {seed}, {run}")
    rng = np.random.default_rng([seed, _stream(experiment), run])
    sitl_seed = int(rng.integers(0, 2**31 - 1))
    u = rng.uniform(size=5)  # always drawn, so the seed stream does not depend on the options
    if not mavlink:
        return Disturbances(sitl_seed)
    mean, gust, tau = wind
    speed = round(model.wind_scale * mean * (0.5 + u[0]), 4)
    blow = None
    if speed > 0 or model.wind_scale * gust > 0:
        blow = (speed, round(360.0 * u[1], 4), round(model.wind_scale * gust, 4), round(tau, 4))
    att = (round(model.tilt_deg * (2 * u[2] - 1), 4), round(model.tilt_deg * (2 * u[3] - 1), 4),
           round(model.yaw_deg * (2 * u[4] - 1), 4))
    return Disturbances(sitl_seed, blow, None if not any(att) else att)


@dataclass(frozen=True)
class Job:
    """One flight of the campaign: its :class:`gcs.api.FlightSpec` and where its files go.

    Attributes
    ----------
    experiment, controller : str
    run : int
    disturbances : Disturbances
    spec : FlightSpec
        What :func:`gcs.api.fly` flies (lockstep, the run's seed and disturbances, the log path).
    output_path : str
        The flight's stdout and stderr.
    summary_path : str
        The end-of-flight summary (what ``gcs fly --summary`` writes).
    log_path : str or None
        The MCAP flight log.
    duration_s : float
        Mission seconds planned.
    timeout_s : float
        Wall seconds after which the run is stopped and reported as hung.
    entry : str
        ``module:function`` called with the spec (:func:`gcs.api.fly`; tests inject others).
    """

    experiment: str
    controller: str
    run: int
    disturbances: Disturbances
    spec: FlightSpec
    output_path: str
    summary_path: str
    log_path: str | None
    duration_s: float
    timeout_s: float
    entry: str = "gcs.api:fly"

    @property
    def key(self) -> str:
        """``experiment/controller/runNN``: unique in a campaign."""
        return f"{self.experiment}/{self.controller}/run{self.run:02d}"

    @property
    def argv(self) -> tuple[str, ...]:
        """The equivalent ``gcs fly`` command line (without the program name)."""
        return tuple(self.spec.command_line(self.summary_path)[1:])

    def to_json(self) -> dict:
        return {"key": self.key, "experiment": self.experiment, "controller": self.controller, "run": self.run,
                "disturbances": self.disturbances.to_json(), "argv": ["gcs", *self.argv], "spec": self.spec.to_json(),
                "output": self.output_path, "summary": self.summary_path, "log": self.log_path,
                "duration_s": self.duration_s, "timeout_s": self.timeout_s}


@dataclass(frozen=True)
class CampaignOptions:
    """What ``gcs campaign`` was asked for (see :mod:`gcs.cli.campaign`).

    Attributes
    ----------
    experiments : tuple of str
    runs : int
    seed : int
    out : str
        Output folder.
    controllers : tuple of str
    durations : dict or None
        Mission cut per experiment [s] (``{"*": s}`` for all); missing = the experiment's
        campaign default (120 s for outdoor-altitude, the whole mission otherwise).
    duration_scale : float
        Multiplies every duration (after ``durations``).
    disturbances : DisturbanceModel
    timeout_s : float or None
        Per-run wall timeout; None = :func:`default_timeout_s`.
    fly_overrides : dict
        :class:`gcs.api.FlightSpec` fields set for every flight (``--fly-arg`` options).
    """

    experiments: tuple[str, ...]
    runs: int
    seed: int
    out: str
    controllers: tuple[str, ...] = CONTROLLERS
    durations: dict | None = None
    duration_scale: float = 1.0
    disturbances: DisturbanceModel = DisturbanceModel()
    timeout_s: float | None = None
    fly_overrides: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Plan:
    """The jobs of a campaign and what could not be planned.

    Attributes
    ----------
    options : CampaignOptions
    experiments : tuple of ExperimentSpec
        The experiments flown.
    jobs : tuple of Job
        Ordered by experiment, run, controller.
    durations_s : dict
        Mission seconds per experiment flown.
    skipped : dict
        Experiment name -> reason (none are skipped today; kept for the report's format).
    notes : tuple of str
        Workarounds taken (no ``--log``: no figures; no ``--duration``: whole missions).
    """

    options: CampaignOptions
    experiments: tuple[ExperimentSpec, ...]
    jobs: tuple[Job, ...]
    durations_s: dict
    skipped: dict = field(default_factory=dict)
    notes: tuple[str, ...] = ()

    def to_json(self) -> dict:
        o = self.options
        return {"experiments": [e.name for e in self.experiments], "skipped": self.skipped, "runs": o.runs,
                "seed": o.seed, "controllers": list(o.controllers), "durations_s": self.durations_s,
                "disturbance_model": {"wind_scale": o.disturbances.wind_scale, "tilt_deg": o.disturbances.tilt_deg,
                                      "yaw_deg": o.disturbances.yaw_deg},
                "notes": list(self.notes), "jobs": [j.to_json() for j in self.jobs]}


def parse_durations(items: Sequence[str]) -> dict:
    """``--duration`` values: ``SECONDS`` (every experiment) or ``EXPERIMENT=SECONDS``.

    Raises
    ------
    CampaignError
        For a malformed item, an unknown experiment or a duration that is not > 0.
    """
    out: dict = {}
    for item in items:
        name, sep, value = item.rpartition("=")
        name = name.strip() if sep else "*"
        if name != "*" and name not in EXPERIMENTS:
            raise CampaignError("--duration", "", f"unknown experiment {name!r} in {item!r}")
        try:
            v = float(value)
        except ValueError:
            raise CampaignError("--duration", "", f"expected SECONDS or EXPERIMENT=SECONDS, got {item!r}") from None
        if not (v > 0 and math.isfinite(v)):
            raise CampaignError("--duration", "", f"must be a finite number > 0, got {item!r}")
        out[name] = v
    return out


def default_timeout_s(duration_s: float) -> float:
    """Per-run wall timeout: lockstep runs about ten times faster than real time, so a
    run that takes longer than the mission in real time plus two minutes (preflight,
    landing, a busy machine) is hung."""
    return 120.0 + 1.5 * duration_s


def _mission_duration(config_name: str) -> tuple[float, tuple[float, float, float]]:
    from gcs.config import load_config
    from gcs.mission import Mission

    cfg = load_config(config_name)
    w = cfg.sim.wind
    return Mission(cfg.mission).duration_s, (w.mean_speed_m_s, w.gust_std_m_s, w.gust_tau_s)


def plan_campaign(options: CampaignOptions) -> Plan:
    """The jobs of a campaign (pure: reads the bundled configs, writes nothing).

    Parameters
    ----------
    options : CampaignOptions

    Returns
    -------
    Plan

    Raises
    ------
    CampaignError
        ``runs < 1``, a negative seed, an unknown controller or experiment.
    """
    if options.runs < 1:
        raise CampaignError("--runs", "", f"must be >= 1, got {options.runs}")
    if options.seed < 0:
        raise CampaignError("--seed", "", f"must be >= 0, got {options.seed}")
    if not options.controllers:
        raise CampaignError("--controllers", "", "no controller given")
    for c in options.controllers:
        if c not in CONTROLLERS:
            raise CampaignError("--controllers", "", f"unknown controller {c!r} (choose from {', '.join(CONTROLLERS)})")
    if not options.duration_scale > 0:
        raise CampaignError("--duration-scale", "", f"must be > 0, got {options.duration_scale:g}")
    specs = resolve_experiments(options.experiments)
    skipped: dict[str, str] = {}
    notes: list[str] = []
    flown: list[ExperimentSpec] = list(specs)
    out = Path(options.out)
    durations = dict(options.durations or {})
    jobs: list[Job] = []
    planned: dict[str, float] = {}
    for spec in flown:
        mission_s, wind = _mission_duration(spec.config)
        d = durations.get(spec.name, durations.get("*", spec.campaign_duration_s))
        d = (mission_s if d is None else min(d, mission_s)) * options.duration_scale
        d = min(d, mission_s)
        cut = d < mission_s
        planned[spec.name] = d
        timeout = options.timeout_s if options.timeout_s is not None else default_timeout_s(d)
        for run in range(options.runs):
            dist = draw_disturbances(options.seed, spec.name, run, mavlink=spec.rig is None, wind=wind,
                                     model=options.disturbances)
            for ctl in options.controllers:
                base = out / "runs" / spec.name / ctl / f"run{run:02d}"
                log = str(base) + ".mcap"
                extra = dict(options.fly_overrides)
                sitl_args = dist.sitl_args() + tuple(extra.pop("sitl_args", ()))
                fspec = FlightSpec(controller=ctl, config=spec.config, vehicle="rig" if spec.rig else "mavlink",
                                   lockstep=True, seed=dist.seed, sitl_args=sitl_args,
                                   duration_s=d if cut else None, log_path=log, **extra)
                jobs.append(Job(spec.name, ctl, run, dist, fspec, str(base) + ".out", str(base) + ".json",
                                log, d, timeout))
    return Plan(options, tuple(flown), tuple(jobs), planned, skipped, tuple(notes))
