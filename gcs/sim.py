"""``gcs sim``: the paper's experiments on the in-process plant, through the same mission loop as ``gcs fly``.

:func:`simulate` flies one controller once: the vehicle is a
:class:`gcs.vehicles.plant.PlantSession` (the reduced plant, its sensors, the estimator,
seeded wind and noise: run ``i`` of seed ``s`` draws from ``(s, i)``, so every controller
meets the same disturbances), the loop :class:`gcs.flight.loop.MissionLoop` on simulated
time, without envelope or timing statistics.  :func:`run_experiment` flies every controller
``runs`` times and collects the metrics.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field
from typing import Any
from collections.abc import Callable, Sequence

from gcs.config import Config
from gcs.config.bounds import MAX_RUNS, WEEK_S
from gcs.control import CONTROLLERS, Controller, make_controller
from gcs.errors import GcsError
from gcs.flight.context import FlightContext
from gcs.flight.loop import MissionLoop
from gcs.log.recorder import FlightRecorder
from gcs.log.simrecorder import SimRecorder
from gcs.metrics import FlightRecord, summarize
from gcs.vehicles.plant import PlantSession
from quadrotor.bounds import short_repr
from quadrotor.wind import WindParams

__all__ = ["SimOptions", "SimRun", "SimError", "simulate", "run_experiment", "ExperimentResult", "check_run",
           "MAX_STEPS", "MAX_RUNS"]

#: Longest simulated flight in control steps (a week at 10 ms).
MAX_STEPS = 60_480_000


class SimError(GcsError, ValueError):
    """A simulation cannot be run with the options given."""

    exit_code = 2


@dataclass(frozen=True)
class SimOptions:
    """Switches of one simulated flight.

    Attributes
    ----------
    duration_s : float or None
        Simulated time; None = the config's ``experiment.duration_s``.
    wind : bool or None
        Blow the config's wind; None = the config's ``[sim.wind] enabled``.
    noise : bool
        Use the config's sensor model (False = ideal sensors, true state fed back).
    """

    duration_s: float | None = None
    wind: bool | None = None
    noise: bool = True


@dataclass(frozen=True)
class SimRun:
    """One simulated flight and its metrics."""

    controller: str
    run: int
    seed: int
    record: FlightRecord
    metrics: dict[str, float]


def check_run(config: Config, runs: int | None = None, options: SimOptions = SimOptions()) -> tuple[int, float]:
    """The number of runs and the simulated duration [s] of an experiment, checked before anything flies.

    Parameters
    ----------
    config : Config
    runs : int or None
        Runs per controller; None = the config's ``sim.runs``.
    options : SimOptions
        ``duration_s`` None = the config's ``experiment.duration_s``.

    Returns
    -------
    (int, float)

    Raises
    ------
    SimError
        ``runs`` not an integer in 1..:data:`MAX_RUNS`, or a duration that is not a finite
        number from one control step to :data:`MAX_STEPS` steps (a week at 10 ms).
    """
    runs = config.sim.runs if runs is None else runs
    if isinstance(runs, bool) or not isinstance(runs, numbers.Integral) or not 1 <= runs <= MAX_RUNS:
        raise SimError(f"--runs: must be a whole number from 1 to {MAX_RUNS}, got {short_repr(runs)}")
    ts = config.experiment.ts_s
    duration = config.experiment.duration_s if options.duration_s is None else options.duration_s
    longest = min(MAX_STEPS * ts, WEEK_S)
    if (isinstance(duration, bool) or not isinstance(duration, (int, float))
            or not ts * (1 - 1e-9) <= duration <= longest):  # nan fails the comparison too
        shown = f"{duration:g}" if isinstance(duration, float) else short_repr(duration)
        raise SimError(f"--duration: must be a number of seconds from one control step ({ts:g} s) "
                       f"to {longest:g} s, got {shown}")
    return int(runs), float(duration)


def simulate(config: Config, controller: str, *, run: int = 0, seed: int | None = None,
             options: SimOptions = SimOptions(), designed: Controller | None = None,
             log: Any = None) -> SimRun:
    """Fly ``controller`` on the reduced plant for the config's mission.

    Parameters
    ----------
    config : Config
    controller : str
        One of :data:`gcs.control.CONTROLLERS`.
    run : int
        Run index (selects the random streams).
    seed : int or None
        Base seed; None = ``config.sim.seed``.
    options : SimOptions
    designed : Controller or None
        An already designed ``controller`` for this config to reuse (it is reset);
        None designs one.
    log : gcs.log.writer.FlightLog, a sink of gcs.log.sink (e.g. BackgroundSink) or None
        Log every control tick of this flight (estimate, reference, error, command,
        horizon, cost, truth, phase events; see :mod:`gcs.log.simrecorder`), appended after
        what the log already holds.  None: no logging.

    Returns
    -------
    SimRun
    """
    seed = config.sim.seed if seed is None else seed
    _, duration = check_run(config, 1, options)
    if designed is None:
        ctl = make_controller(controller, config)
    else:
        ctl = designed
        ctl.reset()
    blow = config.sim.wind_enabled if options.wind is None else options.wind
    if blow and options.wind and config.sim.wind == WindParams():
        raise SimError(f"{config.source}: --wind asked for, but the config describes no wind ([sim.wind])")
    session = PlantSession(config, run=run, seed=seed, wind=blow, noise=options.noise)
    ctx = FlightContext(config, None, FlightRecorder(None))
    session.attach(ctx)
    loop = MissionLoop(ctx, controller, ctl, session, stats=False, duration_s=duration, live_period_s=0.0,
                       close_at_end_time=True)
    tap = None
    if log is not None:
        def tap(track):
            return SimRecorder(log, config, ctl, controller, run=run, seed=seed, mission=loop.mission,
                               steps=loop.mission_steps, cost=loop.cost, states=track.truths, refs=track.refs,
                               cmds=track.cmds, j_log=track.js)
    result = loop.run(tap=tap)
    return SimRun(controller, run, seed, result.record, result.metrics)


@dataclass
class ExperimentResult:
    """Runs of several controllers on one experiment, with their summaries."""

    experiment: str
    runs: int
    duration_s: float
    per_run: dict[str, list[dict[str, float]]] = field(default_factory=dict)

    @property
    def summary(self) -> dict[str, dict[str, dict[str, float]]]:
        return {name: summarize(r) for name, r in self.per_run.items()}

    def to_json(self) -> dict:
        """``{"experiment", "runs", "duration_s", "results": {ctl: {metric: {"mean", "std"}}}}``."""
        return {"experiment": self.experiment, "runs": self.runs, "duration_s": self.duration_s,
                "results": self.summary}


def run_experiment(config: Config, controllers: Sequence[str], *, runs: int | None = None, seed: int | None = None,
                   options: SimOptions = SimOptions(),
                   progress: Callable[[str, int, int], None] | None = None,
                   log: Any = None) -> ExperimentResult:
    """Fly every controller ``runs`` times (seeds ``(seed, i)``) and collect metrics.

    ``log`` (see :func:`simulate`) receives every flight, one after the other.
    """
    for name in controllers:
        if name not in CONTROLLERS:
            raise SimError(f"unknown controller {name!r}")
    runs, duration = check_run(config, runs, options)
    result = ExperimentResult(config.experiment.name, runs, duration)
    for name in controllers:
        result.per_run[name] = []
        designed = make_controller(name, config)
        for i in range(runs):
            if progress is not None:
                progress(name, i, runs)
            run = simulate(config, name, run=i, seed=seed, options=options, designed=designed, log=log)
            result.per_run[name].append(run.metrics)
    return result
