"""``[estimator]``: the disturbance observer's switch and time constant are validated like every key."""

import copy

import pytest

from gcs.config import DISTURBANCE_MODES, load_config, parse_config
from quadrotor.errors import ConfigError


@pytest.fixture(scope="module")
def raw():
    return copy.deepcopy(dict(load_config("outdoor-circle").raw))


def with_estimator(raw, **keys):
    doc = copy.deepcopy(raw)
    doc["estimator"] = dict(doc.get("estimator", {}), **keys)
    return doc


def test_the_default_is_auto(raw):
    est = parse_config(raw, "t").estimator
    assert est.disturbance == "auto" and est.disturbance_time_constant_s == 0.15
    assert DISTURBANCE_MODES == ("auto", "on", "off")


@pytest.mark.parametrize("mode", ["auto", "on", "off"])
def test_each_mode_loads(raw, mode):
    assert parse_config(with_estimator(raw, disturbance=mode), "t").estimator.disturbance == mode


@pytest.mark.parametrize("value, reason", [("sometimes", "must be one of auto, on, off"), (1, "must be a string"),
                                           (True, "must be a string")])
def test_unknown_values_are_rejected_naming_the_key(raw, value, reason):
    with pytest.raises(ConfigError, match=reason) as exc:
        parse_config(with_estimator(raw, disturbance=value), "t")
    assert "estimator.disturbance" in str(exc.value)


@pytest.mark.parametrize("value", [0.0, -1.0, 1e9, float("nan")])
def test_the_time_constant_is_bounded(raw, value):
    with pytest.raises(ConfigError) as exc:
        parse_config(with_estimator(raw, disturbance_time_constant_s=value), "t")
    assert "estimator.disturbance_time_constant_s" in str(exc.value)


def test_unknown_estimator_keys_are_rejected(raw):
    with pytest.raises(ConfigError, match="unknown key"):
        parse_config(with_estimator(raw, disturbance_gain=3.0), "t")
