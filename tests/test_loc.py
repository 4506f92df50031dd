import dataclasses

import numpy as np
import pytest
import scipy.linalg

from gcs.control import make_controller
from gcs.control.base import steps_to_go
from gcs.control.loc import design_loc, design_loc_from_config, finite_horizon_lqr, loc_models
from gcs.errors import DesignError
from quadrotor.state import State
from gcs.model import linear_psi, linear_x_theta, linear_y_phi, linear_z


def dare_gain(a, b, q, r):
    p = scipy.linalg.solve_discrete_are(a, b, q, r)
    return np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a)


@pytest.mark.parametrize("name,system", [("z", linear_z), ("psi", linear_psi), ("y_phi", linear_y_phi),
                                         ("x_theta", linear_x_theta)])
def test_long_horizon_gain_converges_to_dare(outdoor, name, system):
    a, b = system(0.01)
    q, r, h = outdoor.loc[name].resolved("corrected")
    F, _ = finite_horizon_lqr(a, b, q, r, h, 20000)
    np.testing.assert_allclose(F[-1], dare_gain(a, b, q, r), rtol=1e-6)
    # The gain with one step to go comes from H alone.
    np.testing.assert_allclose(F[0], np.linalg.solve(r + b.T @ h @ b, b.T @ h @ a))


def test_indoor_z_gain_converges_to_dare(indoor):
    # Q/R is small indoors (eq. 21): the recursion needs a longer horizon than the paper's 40 s.
    a, b = linear_z(0.01)
    q, r, h = indoor.loc["z"].resolved("corrected")
    F, _ = finite_horizon_lqr(a, b, q, r, h, 40000)
    np.testing.assert_allclose(F[-1], dare_gain(a, b, q, r), rtol=1e-6)
    F40, _ = finite_horizon_lqr(a, b, q, r, h, 4000)
    np.testing.assert_allclose(F40[-1], dare_gain(a, b, q, r), rtol=1e-4)


def test_riccati_cost_equals_the_rollout_cost_and_beats_perturbations():
    rng = np.random.default_rng(1)
    a, b = linear_y_phi(0.01)
    q, r, h = np.diag([1.0, 2.0, 3.0, 0.5]), np.array([[0.7]]), np.diag([5.0, 1.0, 1.0, 1.0])
    n = 50
    F, P = finite_horizon_lqr(a, b, q, r, h, n)
    x0 = rng.normal(size=4)

    def rollout(extra):
        x, j = x0.copy(), 0.0
        for k in range(n):
            u = -F[n - k - 1] @ x + extra[k]
            j += x @ q @ x + u @ r @ u
            x = a @ x + b @ u
        return 0.5 * (j + x @ h @ x)

    best = rollout(np.zeros((n, 1)))
    assert best == pytest.approx(0.5 * x0 @ P[n] @ x0, rel=1e-9)
    for _ in range(5):
        assert rollout(rng.normal(scale=0.1, size=(n, 1))) > best


def test_design_rejects_bad_matrices():
    a, b = linear_z(0.01)
    with pytest.raises(DesignError, match="Q matrix is the wrong shape"):
        finite_horizon_lqr(a, b, np.eye(3), [[1.0]], np.eye(2), 10)
    with pytest.raises(DesignError, match="R matrix is not symmetric positive definite"):
        finite_horizon_lqr(a, b, np.eye(2), [[0.0]], np.eye(2), 10)
    with pytest.raises(DesignError, match="not positive semidefinite"):
        finite_horizon_lqr(a, b, np.diag([1.0, -1.0]), [[1.0]], np.eye(2), 10)
    with pytest.raises(DesignError, match="horizon"):
        finite_horizon_lqr(a, b, np.eye(2), [[1.0]], np.eye(2), 0)


def test_design_tables_have_the_horizon_length(outdoor):
    d = design_loc_from_config(outdoor)
    assert d.F_z.shape == (60000, 1, 2) and d.F_y_phi.shape == (60000, 1, 4)


def test_design_takes_matrices_and_the_adapter_reads_the_config(outdoor):
    weights = {n: outdoor.loc[n].resolved("corrected") for n in ("z", "psi", "y_phi", "x_theta")}
    d = design_loc(0.01, 9.81, weights, 500)
    assert d.horizon_steps == 500 and d.F_x_theta.shape == (500, 1, 4)
    for name, (a, b) in loc_models(0.01, 9.81).items():
        F, _ = finite_horizon_lqr(a, b, *weights[name], 500)
        np.testing.assert_array_equal(getattr(d, f"F_{name}"), F)
    bad = dict(weights, psi=(np.eye(3), [[1.0]], np.eye(2)))
    with pytest.raises(DesignError, match=r"^loc\.psi: Q matrix is the wrong shape"):
        design_loc(0.01, 9.81, bad, 10)
    with pytest.raises(DesignError, match=r": loc\.z: horizon N must be an integer"):
        design_loc_from_config(dataclasses.replace(outdoor, experiment=dataclasses.replace(
            outdoor.experiment, horizon_s=0.0)))


def test_policy_uses_exact_linearisation_and_the_table(outdoor):
    ctl = make_controller("loc", outdoor)
    d = design_loc_from_config(outdoor)
    s = State(z=1.9, vz=0.1, roll=0.05, pitch=-0.04)
    ref = State(z=2.0)
    k = 100
    cmd = ctl.step(k, s, ref)
    u1 = -(d.F_z[60000 - k - 1, 0] @ np.array([-0.1, 0.1]))
    assert cmd.thrust_n == pytest.approx((u1 + 9.81) / (np.cos(-0.04) * np.cos(0.05)))
    assert cmd.roll_accel_rad_s2 == pytest.approx(-(d.F_y_phi[60000 - k - 1, 0] @ np.array([0, 0, 0.05, 0])))


def test_steps_to_go_and_after_horizon():
    assert [steps_to_go(k, 3, "pd") for k in range(5)] == [3, 2, 1, None, None]
    assert [steps_to_go(k, 3, "terminal") for k in range(5)] == [3, 2, 1, 1, 1]
    assert [steps_to_go(k, 3, "restart") for k in range(7)] == [3, 2, 1, 3, 2, 1, 3]
    with pytest.raises(ValueError):
        steps_to_go(-1, 3, "pd")


# --------------------------------------------------------------------------- one recursion (gcs.control.riccati)

def _loc_recursion_before_riccati_py(a, b, q, r, h, N, rtol=1e-14):
    """finite_horizon_lqr as it was before the recursion moved to gcs.control.riccati (frozen copy)."""
    n, m = b.shape
    F, P = np.empty((N, m, n)), np.empty((N + 1, n, n))
    P[0] = h
    p = h
    for j in range(1, N + 1):
        f = np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a)
        acl = a - b @ f
        p_new = acl.T @ p @ acl + f.T @ r @ f + q
        p_new = 0.5 * (p_new + p_new.T)
        F[j - 1], P[j] = f, p_new
        if np.max(np.abs(p_new - p)) <= rtol * np.max(np.abs(p_new)):
            F[j:], P[j + 1:] = f, p_new
            break
        p = p_new
    return F, P


@pytest.mark.parametrize("name", ["indoor-4dof", "outdoor-altitude", "outdoor-circle"])
def test_loc_gain_tables_are_bit_for_bit_those_of_before(name):
    # Lockstep flights are compared to the last digit: the tables must not move by one ulp.
    from gcs.config import load_config

    cfg = load_config(name)
    d = design_loc_from_config(cfg)
    for sub, (a, b) in loc_models(cfg.experiment.ts_s, cfg.vehicle.gravity_m_s2).items():
        q, r, h = cfg.loc[sub].resolved(cfg.experiment.matrices)
        F, P = _loc_recursion_before_riccati_py(a, b, q, r, h, cfg.experiment.horizon_steps)
        assert np.array_equal(getattr(d, f"F_{sub}"), F), sub
        F2, P2 = finite_horizon_lqr(a, b, q, r, h, cfg.experiment.horizon_steps)
        assert np.array_equal(F2, F) and np.array_equal(P2, P), sub


def test_one_recursion_for_loc_and_the_affine_optimum():
    from gcs.control.riccati import affine_lqr, check_lq_problem, riccati_recursion

    a, b = linear_y_phi(0.01)
    q, r, h = np.diag([1.0, 2.0, 3.0, 0.5]), np.array([[0.7]]), np.diag([5.0, 1.0, 1.0, 1.0])
    F, P = finite_horizon_lqr(a, b, q, r, h, 300, rtol=0.0)  # rtol 0: never stops early
    K, kff, P2, p, s = affine_lqr(a, b, None, q, r, h, 300)
    assert np.array_equal(F, K) and np.array_equal(P, P2)  # c = 0: the same arithmetic
    assert not kff.any() and not p.any() and not s.any()
    args = check_lq_problem(a, b, q, r, h, 5)
    with pytest.raises(ValueError, match="rtol"):
        riccati_recursion(*args[:6], np.zeros((5, 4)), rtol=1e-14)
    with pytest.raises(DesignError, match=r"horizon N must be an integer >= 1, got 2\.5"):
        finite_horizon_lqr(a, b, q, r, h, 2.5)
    with pytest.raises(DesignError, match="Q has non-finite entries"):
        finite_horizon_lqr(a, b, np.full((4, 4), np.nan), r, h, 5)
