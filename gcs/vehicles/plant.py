"""The in-process plant as a vehicle session: ``gcs sim`` flies the same mission loop as ``gcs fly``.

The vehicle is the paper's reduced plant (:mod:`quadrotor.plant`: eq. 1 with drag, wind and
the ground, RK4 at ``plant_substep_s`` with the command held over the control period), its
sensors (:mod:`quadrotor.sensors`) and the estimator; with ideal sensors the true state is
fed back.  Time is simulated (:class:`gcs.flight.clock.SimClock`): there is no link, no
preflight and no landing.  Randomness is seeded per run: the wind of run ``i`` comes from
``default_rng([seed, i, 1])`` and the sensor noise from ``default_rng([seed, i, 2])``, so every
controller meets the same wind and noise in run ``i``.
"""

from __future__ import annotations

import math

import numpy as np

from gcs.config import Config
from gcs.control import model_params
from gcs.estimate import StateEstimator
from gcs.flight.clock import SimClock
from gcs.flight.context import FlightContext
from quadrotor import plant
from quadrotor.sensors import Sensors
from quadrotor.state import Command, State
from quadrotor.wind import Wind

__all__ = ["PlantSession"]

_CALM = (0.0, 0.0, 0.0)


class PlantSession:
    """The reduced plant of ``config`` for run ``run`` of ``seed``.

    Parameters
    ----------
    config : Config
    run, seed : int
        Select the random streams (see the module docstring).
    wind : bool
        Blow the config's ``[sim.wind]``.
    noise : bool
        Use the config's sensor model (False: ideal sensors, the true state fed back).
    """

    lands_itself = True
    control_name = "the simulation"
    #: Nothing to supervise: no link, no mode, no streams (the loop skips those checks).
    supervised = False

    def __init__(self, config: Config, *, run: int, seed: int, wind: bool, noise: bool) -> None:
        self.ts = config.experiment.ts_s
        self.vehicle = config.vehicle
        self.wind = Wind(config.sim.wind, np.random.default_rng([seed, run, 1])) if wind else None
        sp = config.sim.sensors
        self.sensors = self.estimator = None
        if noise and not sp.is_ideal:
            self.sensors = Sensors(sp, np.random.default_rng([seed, run, 2]))
            pos_std = sp.position_noise_std_m
            alt_std = math.sqrt(sp.altitude_noise_std_m ** 2 + sp.altitude_resolution_m ** 2 / 12.0)
            self.estimator = StateEstimator(self.ts, model_params(config), (pos_std, pos_std, alt_std),
                                            config.estimator.accel_noise_std_m_s2)
        self.state = State()
        self._estimate = State()

    def attach(self, ctx: FlightContext) -> None:
        if ctx.clock is None:
            ctx.clock = SimClock()

    def preflight(self) -> None:
        """Nothing: the plant rests on the ground, ready."""

    def pump(self) -> int:
        return 0

    def estimate(self, dt_s: float, last_command: Command | None) -> State:
        if dt_s > 0:
            if self.sensors is not None:
                self._estimate = self.estimator.update(self.sensors.measure(self.state), last_command)
            else:
                self._estimate = State(*self.state)
        return self._estimate

    def truth(self) -> State:
        return self.state

    def disturbance_m_s2(self) -> tuple[float, float, float]:
        """None estimated: the simulation flies the paper's laws as they are."""
        return _CALM

    def observer_log(self) -> None:
        return None

    def fresh(self, now_ns: int, stale_s: float) -> bool:
        return True

    def fault(self) -> tuple[str, str] | None:
        return None

    def health(self, now_ns: int) -> tuple[str, str] | None:
        return None

    def control_lost(self) -> str | None:
        return None

    def mission_origin(self, state: State) -> tuple[float, float, float]:
        return (0.0, 0.0, 0.0)

    def send(self, state: State, command: Command) -> None:
        self.state = plant.step(self.state, command, self.ts, self.vehicle,
                                self.wind.sample(self.ts) if self.wind is not None else _CALM)

    def housekeeping(self) -> None:
        """Nothing to keep alive."""

    def landed(self) -> bool:
        return self.state.z <= 0.0

    def finish(self, reason: str) -> None:
        """The simulated flight just stops."""

    def abandon(self) -> None:
        """Nothing to abandon."""

    def restore(self) -> None:
        """Nothing was changed."""

    def disarm_on_ground(self) -> None:
        """Never armed."""

    def summary(self) -> dict:
        return {}

    def loop_summary(self) -> dict:
        return {}
