"""The controllers, one :class:`ControllerSpec` each: what they are, in one place.

Everything that depends on which controller flies (its design, which cost J it minimises,
how it handles gravity, whether it has a horizon) is read from its spec, never re-derived
from its name: ``make_controller`` and :func:`gcs.control.cost.controller_cost` look it up.

==============  ================================  =========  ===================  =======
name            design                            cost J     gravity              horizon
==============  ================================  =========  ===================  =======
nlsoc           NLSOC, eqs. 16 and 20             eq. 17     compensated (err. 8) yes
nlsoc-literal   NLSOC, the printed law            eq. 17     in f0 (printed)      yes
loc             LOC, eqs. 3-8                     eq. 5      exact linearisation  yes
pd              PD, eq. 26                        none       feed-forward         no
==============  ================================  =========  ===================  =======
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from gcs.config import Config
from gcs.control.base import Controller, Limits
from gcs.control.loc import make_loc
from gcs.control.nlsoc import make_nlsoc
from gcs.control.pd import PdController
from gcs.model import ModelParams
from quadrotor.errors import ConfigError

__all__ = ["ControllerSpec", "REGISTRY", "CONTROLLERS", "controller_spec", "model_params", "limits_of",
           "make_controller"]

#: ``build(spec, config, model, limits, pd)``: the designed controller (``pd`` is the PD fallback).
Builder = Callable[["ControllerSpec", Config, ModelParams, Limits, PdController], Controller]


@dataclass(frozen=True)
class ControllerSpec:
    """One controller of the project.

    Attributes
    ----------
    name : str
        The name on the command line, in logs and in tables.
    build : callable
        ``build(spec, config, model, limits, pd) -> Controller``; ``pd`` is the PD controller
        designed for the same config (the fallback after the horizon).
    cost : {"loc", "nlsoc"} or None
        The cost J it minimises (:mod:`gcs.control.cost`): ``"loc"`` eq. 5, ``"nlsoc"`` eq. 17,
        None when it minimises none (PD).
    gravity_compensated : bool
        Whether its thrust law carries the hover thrust ``m g / (cos(theta) cos(phi))``
        (the NLSOC input, and eq. 17's u, are then the thrust beyond it; erratum 8).  False only
        for the printed NLSOC law, whose model keeps ``-g Ts`` in f0.
    has_horizon : bool
        A finite-horizon law (:class:`gcs.control.base.FiniteHorizonController`).
    summary : str
    """

    name: str
    build: Builder
    cost: str | None
    gravity_compensated: bool
    has_horizon: bool
    summary: str


def _build_nlsoc(spec: ControllerSpec, config: Config, model: ModelParams, limits: Limits,
                 pd: PdController) -> Controller:
    return make_nlsoc(config, model, limits, pd, name=spec.name, gravity_compensated=spec.gravity_compensated)


def _build_loc(spec: ControllerSpec, config: Config, model: ModelParams, limits: Limits,
               pd: PdController) -> Controller:
    return make_loc(config, model, limits, pd)


def _build_pd(spec: ControllerSpec, config: Config, model: ModelParams, limits: Limits,
              pd: PdController) -> Controller:
    return pd


#: The specs by name, in the order of the tables.
REGISTRY: dict[str, ControllerSpec] = {s.name: s for s in (
    ControllerSpec("nlsoc", _build_nlsoc, "nlsoc", True, True,
                   "NLSOC, gravity-compensated thrust (erratum 8)"),
    ControllerSpec("nlsoc-literal", _build_nlsoc, "nlsoc", False, True,
                   "NLSOC, the printed law (does not compensate gravity)"),
    ControllerSpec("loc", _build_loc, "loc", True, True, "LOC, finite-horizon LQR on the exact linearisation"),
    ControllerSpec("pd", _build_pd, None, True, False, "PD, eq. 26 gains with gravity feed-forward"),
)}

#: Controller names, in table order.
CONTROLLERS = tuple(REGISTRY)


def controller_spec(name: str) -> ControllerSpec:
    """The spec of controller ``name``.

    Raises
    ------
    ConfigError
        For an unknown controller name.
    """
    try:
        return REGISTRY[name]
    except KeyError:
        raise ConfigError("--controller", "", f"unknown controller {name!r}; expected one of "
                                              f"{', '.join(CONTROLLERS)}") from None


def model_params(config: Config) -> ModelParams:
    """The controllers' model of the vehicle (mass, gravity)."""
    return ModelParams(config.vehicle.mass_kg, config.vehicle.gravity_m_s2)


def limits_of(config: Config) -> Limits:
    """Actuator limits from the vehicle section."""
    return Limits(config.vehicle.max_thrust_n, config.vehicle.max_angular_accel_rad_s2)


def make_controller(name: str, config: Config) -> Controller:
    """Design and return controller ``name`` for ``config``.

    Raises
    ------
    ConfigError
        For an unknown controller name.
    """
    spec = controller_spec(name)
    model, limits = model_params(config), limits_of(config)
    return spec.build(spec, config, model, limits, PdController(config.pd, model, limits))
