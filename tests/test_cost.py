"""Eq. 5 / eq. 17 written once (gcs.control.cost): the vectorised and the per-tick forms agree with
each other and with the implementations they replace (frozen copies below)."""

import math
import pickle

import numpy as np
import pytest

from gcs.control.cost import (
    COST_EQUATION, COST_KINDS, CostSpec, StageCost, controller_cost, cost_input, cost_state, cost_variables,
    flight_cost, flight_stage_costs, quadratic_cost, stage_costs,
)
from gcs.control.registry import REGISTRY
from gcs.model import MIN_TILT_COS, SUBSYSTEMS

MASS, G = 1.3, 9.81


def flight(seed, k=400):
    """A random flight record: K + 1 states and references, K commands; large tilts (the floor of
    cos(phi) cos(theta) acts) and yaw errors beyond pi (the wrap acts)."""
    rng = np.random.default_rng(seed)
    state = rng.normal(size=(k + 1, 12))
    state[:, 6:8] = rng.uniform(-1.5, 1.5, size=(k + 1, 2))
    state[:, 8] = rng.uniform(-4.0, 4.0, size=k + 1)
    ref = rng.normal(size=(k + 1, 12))
    ref[:, 8] = rng.uniform(-4.0, 4.0, size=k + 1)
    command = np.column_stack([rng.uniform(0.0, 25.0, k), rng.normal(size=(k, 3))])
    return state, ref, command


def spec(kind, seed=0, compensated=True, horizon=250):
    rng = np.random.default_rng(seed)
    n, m = (2, 1) if kind == "loc" else (4, 2)
    a, b, c = rng.normal(size=(n, n)), rng.normal(size=(m, m)), rng.normal(size=(n, n))
    return CostSpec(kind, a @ a.T, b @ b.T + np.eye(m), c @ c.T, horizon, gravity_compensated=compensated)


# --------------------------------------------------------------------------- the implementations replaced

def old_metrics_J(state, ref, command, cost, mass_kg, g):
    """gcs.metrics._quadratic_cost before gcs.control.cost."""
    k = command.shape[0]
    m_steps = min(cost.horizon_steps, k)
    s, r = state, ref
    cc = np.maximum(np.cos(s[:, 6]) * np.cos(s[:, 7]), MIN_TILT_COS)
    if cost.kind == "loc":
        idx = list(SUBSYSTEMS["z"])
        x = s[:, idx] - r[:, idx]
        u = (command[:, 0] * cc[:-1] / mass_kg - g)[:, None]
    else:
        idx = list(SUBSYSTEMS["z_psi"])
        x = s[:, idx] - r[:, idx]
        x[:, 2] = (x[:, 2] + np.pi) % (2 * np.pi) - np.pi
        thrust = command[:, 0] - (mass_kg * g / cc[:-1] if cost.gravity_compensated else 0.0)
        u = np.column_stack([thrust, command[:, 3]])
    xs, us = x[:m_steps], u[:m_steps]
    stage = np.einsum("ki,ij,kj->", xs, cost.Q, xs) + np.einsum("ki,ij,kj->", us, cost.R, us)
    xf = x[m_steps]
    return float(0.5 * stage + 0.5 * xf @ cost.H @ xf)


def old_simlog_stage_costs(state, ref, command, cost, mass_kg, g):
    """gcs.log.simlog.stage_costs before gcs.control.cost."""
    k = command.shape[0]
    s, r = state[:k], ref[:k]
    cc = np.maximum(np.cos(s[:, 6]) * np.cos(s[:, 7]), MIN_TILT_COS)
    if cost.kind == "loc":
        idx = list(SUBSYSTEMS["z"])
        x = s[:, idx] - r[:, idx]
        u = (command[:, 0] * cc / mass_kg - g)[:, None]
    else:
        idx = list(SUBSYSTEMS["z_psi"])
        x = s[:, idx] - r[:, idx]
        x[:, 2] = (x[:, 2] + np.pi) % (2 * np.pi) - np.pi
        thrust = command[:, 0] - (mass_kg * g / cc if cost.gravity_compensated else 0.0)
        u = np.column_stack([thrust, command[:, 3]])
    xs = 0.5 * np.einsum("ki,ij,kj->k", x, cost.Q, x)
    us = 0.5 * np.einsum("ki,ij,kj->k", u, cost.R, u)
    return np.column_stack([xs, us, xs + us])


def old_flightlog_terms(spec_dict, state, ref, command):
    """gcs.log.flightlog.StageCost.terms before gcs.control.cost."""
    kind = spec_dict["kind"]
    idx = SUBSYSTEMS["z" if kind == "loc" else "z_psi"]
    Q, R = spec_dict["Q"], spec_dict["R"]
    mass, g = spec_dict["mass_kg"], spec_dict["gravity_m_s2"]

    def quad(v, m):
        n = len(v)
        return 0.5 * sum(v[i] * m[i][j] * v[j] for i in range(n) for j in range(n))

    cc = max(math.cos(state[6]) * math.cos(state[7]), MIN_TILT_COS)
    x = [state[i] - ref[i] for i in idx]
    if kind == "loc":
        u = [command[0] * cc / mass - g]
    else:
        x[2] = (x[2] + math.pi) % (2 * math.pi) - math.pi
        u = [command[0] - (mass * g / cc if spec_dict.get("gravity_compensated", True) else 0.0), command[3]]
    xs, us = quad(x, Q), quad(u, R)
    return xs, us, xs + us


KINDS = [("loc", True), ("nlsoc", True), ("nlsoc", False)]


@pytest.mark.parametrize("kind,compensated", KINDS)
@pytest.mark.parametrize("horizon", [1, 250, 10_000])
def test_flight_cost_is_the_old_metrics_J_bit_for_bit(kind, compensated, horizon):
    state, ref, command = flight(1)
    cost = spec(kind, 2, compensated, horizon)
    assert flight_cost(state, ref, command, cost, MASS, G) == old_metrics_J(state, ref, command, cost, MASS, G)


@pytest.mark.parametrize("kind,compensated", KINDS)
def test_vectorised_stage_costs_are_the_old_log_ones_bit_for_bit(kind, compensated):
    state, ref, command = flight(3)
    cost = spec(kind, 4, compensated)
    np.testing.assert_array_equal(flight_stage_costs(state, ref, command, cost, MASS, G),
                                  old_simlog_stage_costs(state, ref, command, cost, MASS, G))


@pytest.mark.parametrize("kind,compensated", KINDS)
def test_per_tick_form_equals_the_vectorised_form_and_the_old_flight_log(kind, compensated):
    state, ref, command = flight(5)
    cost = spec(kind, 6, compensated)
    vec = flight_stage_costs(state, ref, command, cost, MASS, G)
    d = cost.to_dict(MASS, G)
    tick = StageCost.from_dict(pickle.loads(pickle.dumps(d)))
    same = StageCost.from_spec(cost, MASS, G)
    for k in range(command.shape[0]):
        s, r, c = state[k].tolist(), ref[k].tolist(), command[k].tolist()
        got = tick.terms(s, r, c)
        assert got == same.terms(s, r, c)
        scale = max(1.0, abs(vec[k, 2]))
        np.testing.assert_allclose(got, vec[k], rtol=1e-12, atol=1e-12 * scale)
        np.testing.assert_allclose(got, old_flightlog_terms(d, s, r, c), rtol=1e-12, atol=1e-12 * scale)


def test_J_is_the_sum_of_the_stage_costs_plus_the_terminal_term():
    state, ref, command = flight(7, k=50)
    cost = spec("nlsoc", 8, True, horizon=30)
    st = flight_stage_costs(state, ref, command, cost, MASS, G)
    x, _ = cost_variables("nlsoc", state, ref, command, MASS, G)
    expected = st[:30, 2].sum() + 0.5 * x[30] @ cost.H @ x[30]
    assert flight_cost(state, ref, command, cost, MASS, G) == pytest.approx(expected, rel=1e-12)


def test_the_definitions_by_hand():
    s = [0.0] * 12
    s[2], s[5], s[6], s[7], s[8], s[11] = 1.0, 0.5, 0.3, -0.2, 3.0, 0.1
    r = [0.0] * 12
    r[2], r[8] = 1.5, -3.0
    assert cost_state("loc", s, r) == [-0.5, 0.5]
    x = cost_state("nlsoc", s, r)
    assert x[:2] == [-0.5, 0.5] and x[3] == 0.1
    assert x[2] == pytest.approx(6.0 - 2 * math.pi)
    cc = math.cos(0.3) * math.cos(-0.2)
    assert cost_input("loc", 12.0, 0.7, cc, MASS, G) == (12.0 * cc / MASS - G,)
    assert cost_input("nlsoc", 12.0, 0.7, cc, MASS, G, True) == (12.0 - MASS * G / cc, 0.7)
    assert cost_input("nlsoc", 12.0, 0.7, cc, MASS, G, False) == (12.0, 0.7)
    # the floor of cos(phi) cos(theta)
    s[6] = s[7] = 1.5
    t = StageCost("loc", [[0.0, 0.0], [0.0, 0.0]], [[2.0]], MASS, G)
    assert t.terms(s, r, [10.0, 0, 0, 0])[1] == pytest.approx(0.5 * 2.0 * (10.0 * MIN_TILT_COS / MASS - G) ** 2)


def test_quadratic_and_stage_forms():
    x = np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])
    u = np.array([[1.0], [2.0]])
    Q, R, H = np.eye(2), np.array([[2.0]]), 2 * np.eye(2)
    assert quadratic_cost(x, u, Q, R, H) == 0.5 * (1 + 4 + 9 + 16 + 2 + 8) + 0.5 * 2 * (25 + 36)
    np.testing.assert_array_equal(stage_costs(x, u, Q, R), [[2.5, 1.0, 3.5], [12.5, 4.0, 16.5]])


def test_controller_cost_comes_from_the_spec(outdoor):
    assert controller_cost("pd", outdoor) is None
    assert controller_cost("no-such-controller", outdoor) is None
    for name, s in REGISTRY.items():
        c = controller_cost(name, outdoor)
        if s.cost is None:
            assert c is None
            continue
        assert c.kind == s.cost in COST_KINDS and c.gravity_compensated == s.gravity_compensated
        assert c.horizon_steps == outdoor.experiment.horizon_steps
    loc = controller_cost("loc", outdoor)
    np.testing.assert_array_equal(loc.Q, outdoor.loc["z"].resolved("corrected")[0])
    lit = controller_cost("nlsoc-literal", outdoor)
    np.testing.assert_array_equal(lit.R, outdoor.nlsoc["z_psi"].resolved("corrected")[1])
    assert not lit.gravity_compensated and controller_cost("nlsoc", outdoor).gravity_compensated
    assert COST_EQUATION == {"loc": 5, "nlsoc": 17}


def test_stage_cost_rejects_an_unknown_kind():
    with pytest.raises(ValueError, match="kind must be one of loc, nlsoc"):
        StageCost("pd", [[1.0]], [[1.0]], 1.0, 9.81)
