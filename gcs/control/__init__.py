"""The paper's controllers behind one interface: ``make_controller(name, config)``.

``name`` is one of :data:`CONTROLLERS`: ``nlsoc`` (gravity-compensated NLSOC,
erratum 8), ``nlsoc-literal`` (the printed law), ``loc`` and ``pd``; each is described by
its :class:`ControllerSpec` in :mod:`gcs.control.registry`.
"""

from __future__ import annotations

from gcs.control.base import NO_DISTURBANCE, Controller, FiniteHorizonController, Limits, steps_to_go
from gcs.control.registry import (
    CONTROLLERS, REGISTRY, ControllerSpec, controller_spec, limits_of, make_controller, model_params,
)

__all__ = ["CONTROLLERS", "REGISTRY", "Controller", "ControllerSpec", "FiniteHorizonController", "Limits",
           "controller_spec", "make_controller", "model_params", "limits_of", "steps_to_go", "NO_DISTURBANCE"]
