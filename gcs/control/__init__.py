"""The paper's controllers behind one interface: ``make_controller(name, config)``.

``name`` is one of :data:`CONTROLLERS`: ``nlsoc`` (gravity-compensated NLSOC,
erratum 8), ``nlsoc-literal`` (the printed law), ``loc`` and ``pd``.
"""

from __future__ import annotations

from gcs.config import Config
from gcs.control.base import Controller, FiniteHorizonController, Limits, steps_to_go
from gcs.control.loc import make_loc
from gcs.control.nlsoc import make_nlsoc
from gcs.control.pd import PdController
from quadrotor.errors import ConfigError
from gcs.model import ModelParams

__all__ = ["CONTROLLERS", "Controller", "FiniteHorizonController", "Limits", "make_controller",
           "model_params", "limits_of", "steps_to_go"]

CONTROLLERS = ("nlsoc", "nlsoc-literal", "loc", "pd")


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
    model, limits = model_params(config), limits_of(config)
    pd = PdController(config.pd, model, limits)
    if name == "pd":
        return pd
    if name == "loc":
        return make_loc(config, model, limits, pd)
    if name in ("nlsoc", "nlsoc-literal"):
        return make_nlsoc(config, model, limits, pd, gravity_compensated=(name == "nlsoc"))
    raise ConfigError("--controller", "", f"unknown controller {name!r}; expected one of {', '.join(CONTROLLERS)}")
