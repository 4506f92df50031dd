import numpy as np
import pytest
import scipy.linalg

from gcs.control import make_controller
from gcs.control.base import steps_to_go
from gcs.control.loc import design_loc, finite_horizon_lqr
from gcs.errors import DesignError
from quadrotor.state import State
from gcs.model import linear_psi, linear_x_theta, linear_y_phi, linear_z


def dare_gain(a, b, q, r):
    p = scipy.linalg.solve_discrete_are(a, b, q, r)
    return np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a)


@pytest.mark.parametrize("name,system", [("z", linear_z), ("psi", linear_psi), ("y_phi", linear_y_phi), ("x_theta", linear_x_theta)])
def test_long_horizon_gain_converges_to_dare(outdoor, name, system):
    a, b = system(0.01)
    q, r, h = outdoor.loc[name].resolved("corrected")
    F, P = finite_horizon_lqr(a, b, q, r, h, 20000)
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
    d = design_loc(outdoor)
    assert d.F_z.shape == (60000, 1, 2) and d.F_y_phi.shape == (60000, 1, 4)


def test_policy_uses_exact_linearisation_and_the_table(outdoor):
    ctl = make_controller("loc", outdoor)
    d = design_loc(outdoor)
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
