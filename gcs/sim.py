"""In-process closed-loop simulation: plant, sensors, estimator, controller, one loop.

The pieces are separate and swappable (rotorpy style): the plant step
(:func:`quadrotor.plant.step`), the sensors and wind (:mod:`quadrotor`), the estimator
(:mod:`gcs.estimate`), the reference (:mod:`gcs.mission`) and the controller
(:mod:`gcs.control`).  :func:`simulate` joins them in one loop; the plant is
integrated by RK4 at ``plant_substep_s`` (1 ms) with the command held over the
control period (zero-order hold).

Randomness is seeded per run: the wind of run ``i`` comes from
``default_rng([seed, i, 1])`` and the sensor noise from ``default_rng([seed, i, 2])``,
so every controller meets the same wind and noise in run ``i`` (common random
numbers) and a run is reproducible from ``(seed, i)``.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from gcs.config import Config
from gcs.config.bounds import MAX_RUNS, WEEK_S
from gcs.errors import GcsError
from gcs.control import CONTROLLERS, Controller, FiniteHorizonController, make_controller, model_params
from gcs.estimate import StateEstimator
from gcs.metrics import FlightRecord, controller_cost, flight_metrics, summarize
from gcs.mission import Mission
from quadrotor.state import State
from quadrotor import plant
from quadrotor.sensors import Sensors
from quadrotor.bounds import short_repr
from quadrotor.wind import Wind, WindParams

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
    log : gcs.log.FlightLog, gcs.log.simlog.BackgroundSimLog or None
        Log every control tick of this flight (estimate, reference, error, command,
        horizon, cost, truth, phase events; see :mod:`gcs.log.simlog`), appended after
        what the log already holds.  None: no logging.

    Returns
    -------
    SimRun
    """
    e = config.experiment
    seed = config.sim.seed if seed is None else seed
    ts = e.ts_s
    _, duration = check_run(config, 1, options)
    steps = int(round(duration / ts))
    if designed is None:
        ctl = make_controller(controller, config)
    else:
        ctl = designed
        ctl.reset()
    model = model_params(config)
    mission = Mission(config.mission, zero_velocity=e.zero_velocity_reference)
    vehicle = config.vehicle

    blow = config.sim.wind_enabled if options.wind is None else options.wind
    if blow and options.wind and config.sim.wind == WindParams():
        raise SimError(f"{config.source}: --wind asked for, but the config describes no wind ([sim.wind])")
    wind = Wind(config.sim.wind, np.random.default_rng([seed, run, 1])) if blow else None
    sp = config.sim.sensors
    sensors = estimator = None
    if options.noise and not sp.is_ideal:
        sensors = Sensors(sp, np.random.default_rng([seed, run, 2]))
        pos_std = sp.position_noise_std_m
        alt_std = math.sqrt(sp.altitude_noise_std_m ** 2 + sp.altitude_resolution_m ** 2 / 12.0)
        estimator = StateEstimator(ts, model, (pos_std, pos_std, alt_std), config.estimator.accel_noise_std_m_s2)

    horizon = ctl if isinstance(ctl, FiniteHorizonController) else None
    plant_step = plant.step
    state = State()
    states = [state]
    refs = []
    cmds = []
    j_log = []
    last = None
    calm = (0.0, 0.0, 0.0)
    cost = controller_cost(controller, config)
    recorder = None
    if log is not None:
        from gcs.log.simlog import SimRecorder
        recorder = SimRecorder(log, config, ctl, controller, run=run, seed=seed, mission=mission, steps=steps,
                               cost=cost, states=states, refs=refs, cmds=cmds, j_log=j_log)
    for k in range(steps):
        ref = mission.reference(k * ts)
        if sensors is not None:
            est = estimator.update(sensors.measure(state), last)  # type: ignore[union-attr]
        else:
            est = State(*state)
        cmd = ctl.step(k, est, ref)
        state = plant_step(state, cmd, ts, vehicle, wind.sample(ts) if wind is not None else calm)
        states.append(state)
        refs.append(ref)
        cmds.append(cmd)
        j_log.append((horizon.last_steps_to_go or 0) if horizon is not None else 0)
        last = cmd
        if recorder is not None:
            recorder.tick(est)
    refs.append(mission.reference(steps * ts))
    rec = FlightRecord(ts, np.array(states, float), np.array(refs, float), np.array(cmds, float),
                       np.array(j_log, dtype=np.int64))
    metrics = flight_metrics(rec, config, mission, cost)
    if recorder is not None:
        recorder.finish(metrics)
    return SimRun(controller, run, seed, rec, metrics)


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
