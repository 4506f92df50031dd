"""The controller registry: one spec per controller, and everything reads it."""

import pytest

from gcs.control import CONTROLLERS, REGISTRY, FiniteHorizonController, controller_spec, make_controller
from gcs.control.cost import COST_KINDS
from gcs.control.pd import PdController
from quadrotor.errors import ConfigError


def test_every_controller_has_one_spec_in_table_order():
    assert CONTROLLERS == ("nlsoc", "nlsoc-literal", "loc", "pd")
    assert all(REGISTRY[n].name == n for n in CONTROLLERS)
    assert all(s.cost is None or s.cost in COST_KINDS for s in REGISTRY.values())
    assert [n for n, s in REGISTRY.items() if not s.gravity_compensated] == ["nlsoc-literal"]


@pytest.mark.parametrize("name", ["nlsoc", "nlsoc-literal", "loc", "pd"])
def test_make_controller_follows_the_spec(outdoor, name):
    spec = controller_spec(name)
    ctl = make_controller(name, outdoor)
    assert ctl.name == name
    assert isinstance(ctl, FiniteHorizonController) == spec.has_horizon
    if spec.has_horizon:
        assert isinstance(ctl.fallback, PdController)
        assert ctl.horizon_steps == outdoor.experiment.horizon_steps
    if name.startswith("nlsoc"):
        assert ctl.law.design.gravity_compensated == spec.gravity_compensated


def test_unknown_controller_is_a_config_error(outdoor):
    with pytest.raises(ConfigError, match="unknown controller 'lqg'; expected one of nlsoc, nlsoc-literal, loc, pd"):
        make_controller("lqg", outdoor)
    with pytest.raises(ConfigError):
        controller_spec("lqg")
