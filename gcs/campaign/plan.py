"""The campaign's plan: the experiments and one job (a :class:`gcs.api.FlightSpec`) per flight.

:func:`plan_campaign` is a pure function of the options: every controller of run ``i`` meets
the same disturbances (:mod:`gcs.campaign.disturbances`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Sequence

from gcs.api import FlightSpec
from gcs.campaign.disturbances import DisturbanceModel, Disturbances, draw_disturbances
from gcs.campaign.errors import CampaignError
from gcs.config import load_config
from gcs.control import CONTROLLERS
from gcs.mission import Mission

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
            raise CampaignError("--experiment", "",
                                f"unknown experiment {n!r} (choose from {', '.join(EXPERIMENT_CHOICES)})")
    return [spec for name, spec in EXPERIMENTS.items() if name in items]


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
    disturbances: DisturbanceModel = DisturbanceModel()  # noqa: RUF009  frozen dataclass: immutable, safe to share
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
