"""The affine-LQ optimum of the altitude subproblem and the controllers' optimality gap."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from gcs.control import CONTROLLERS, controller_spec, make_controller
from gcs.control.loc import finite_horizon_lqr
from gcs.control.nlsoc import one_step_control
from gcs.errors import DesignError
from gcs.model import linear_y_phi, linear_z
from gcs.optimal_affine import (
    COST_CONVENTIONS, UNCONSTRAINED, OptimalAffinePolicy, affine_lqr, affine_lqr_cost, altitude_problem,
    eq17_cost, format_table, optimality_table, reference_offsets, simulate_policy, unconstrained_config,
    z_psi_affine_model,
)


def psd(rng, n, floor=0.0):
    a = rng.normal(size=(n, n))
    return a @ a.T + floor * np.eye(n)


def random_problem(rng, n, m, N):
    A = np.eye(n) + 0.3 * rng.normal(size=(n, n))
    B = rng.normal(size=(n, m))
    c = rng.normal(size=(N, n))
    return A, B, c, psd(rng, n), psd(rng, m, 0.5), psd(rng, n)


def brute_force(A, B, c, Q, R, H, N, x0):
    """Minimise the stacked cost over U = [u(0); ...; u(N-1)] exactly (one linear solve).

    X = [x(0); ...; x(N)] = Phi x0 + Gamma U + w, J = X' W X / 2 + U' Rbar U / 2.
    """
    n, m = B.shape
    c = np.broadcast_to(np.asarray(c, float), (N, n))
    Phi = np.zeros(((N + 1) * n, n))
    Gam = np.zeros(((N + 1) * n, N * m))
    w = np.zeros((N + 1) * n)
    Phi[:n] = np.eye(n)
    for k in range(N):
        rows, prev = slice((k + 1) * n, (k + 2) * n), slice(k * n, (k + 1) * n)
        Phi[rows] = A @ Phi[prev]
        Gam[rows] = A @ Gam[prev]
        Gam[rows, k * m:(k + 1) * m] = B
        w[rows] = A @ w[prev] + c[k]
    W = np.zeros(((N + 1) * n, (N + 1) * n))
    for k in range(N):
        W[k * n:(k + 1) * n, k * n:(k + 1) * n] = Q
    W[N * n:, N * n:] = H
    Rbar = np.kron(np.eye(N), R)
    U = np.linalg.solve(Gam.T @ W @ Gam + Rbar, -Gam.T @ W @ (Phi @ x0 + w))
    X = Phi @ x0 + Gam @ U + w
    return 0.5 * X @ W @ X + 0.5 * U @ Rbar @ U, U.reshape(N, m)


def rollout(A, B, c, Q, R, H, K, kff, x0):
    N = K.shape[0]
    c = np.broadcast_to(np.asarray(c, float), (N, A.shape[0]))
    x, J, us = np.asarray(x0, float), 0.0, []
    for k in range(N):
        u = -K[N - k - 1] @ x - kff[N - k - 1]
        us.append(u)
        J += x @ Q @ x + u @ R @ u
        x = A @ x + B @ u + c[k]
    return 0.5 * (J + x @ H @ x), np.array(us)


# --------------------------------------------------------------------------- (1) exact optimum

@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), N=st.integers(5, 8), n=st.integers(1, 4), m=st.integers(1, 3))
def test_affine_lqr_equals_the_stacked_least_squares_optimum(seed, N, n, m):
    rng = np.random.default_rng(seed)
    A, B, c, Q, R, H = random_problem(rng, n, m, N)
    x0 = rng.normal(size=n)
    K, kff, P, p, s = affine_lqr(A, B, c, Q, R, H, N)
    J_bf, U_bf = brute_force(A, B, c, Q, R, H, N, x0)
    J = affine_lqr_cost(P, p, s, x0)
    assert J == pytest.approx(J_bf, rel=1e-8)  # noqa: SIM300 - J is the cost, not a constant
    u0 = -K[N - 1] @ x0 - kff[N - 1]
    np.testing.assert_allclose(u0, U_bf[0], rtol=1e-8, atol=1e-8 * np.abs(U_bf).max())
    J_ro, U_ro = rollout(A, B, c, Q, R, H, K, kff, x0)
    assert J_ro == pytest.approx(J_bf, rel=1e-8)
    np.testing.assert_allclose(U_ro, U_bf, rtol=1e-7, atol=1e-8 * np.abs(U_bf).max())


@pytest.mark.parametrize("convention", COST_CONVENTIONS)
@pytest.mark.parametrize("N", [5, 8])
def test_z_psi_optimum_equals_brute_force_with_the_paper_weights(outdoor, indoor, convention, N):
    rng = np.random.default_rng(N)
    for cfg in (outdoor, indoor):
        q, r, h = cfg.nlsoc["z_psi"].resolved("corrected")
        A, B, d = z_psi_affine_model(0.01, 1.0, 9.81, gravity_compensated=(convention == "compensated"))
        c = d + 0.05 * rng.normal(size=(N, 4))  # a moving reference on top of gravity
        x0 = np.array([-0.3, 0.2, 0.1, -0.05])
        K, kff, P, p, s = affine_lqr(A, B, c, q, r, h, N)
        J_bf, U_bf = brute_force(A, B, c, q, r, h, N, x0)
        assert affine_lqr_cost(P, p, s, x0) == pytest.approx(J_bf, rel=1e-8)
        np.testing.assert_allclose(-K[N - 1] @ x0 - kff[N - 1], U_bf[0], rtol=1e-8)


def test_constant_c_equals_the_same_offset_on_every_row():
    rng = np.random.default_rng(3)
    A, B, _, Q, R, H = random_problem(rng, 3, 2, 6)
    c = rng.normal(size=3)
    for a, b in zip(affine_lqr(A, B, c, Q, R, H, 6), affine_lqr(A, B, np.tile(c, (6, 1)), Q, R, H, 6), strict=True):
        np.testing.assert_array_equal(a, b)


def test_c_is_in_time_order():
    # c[k] acts on the step k -> k + 1: an offset at the first step and one at the last step
    # are different problems, each equal to its brute-force optimum.
    A, B = linear_z(0.01)
    Q, R, H = np.diag([1.0, 1.0]), np.array([[1.0]]), np.diag([1.0, 1.0])
    N, x0 = 6, np.zeros(2)
    first = np.zeros((N, 2))
    first[0] = [1.0, 0.0]
    last = np.zeros((N, 2))
    last[-1] = [1.0, 0.0]
    costs = []
    for c in (first, last):
        _, _, P, p, s = affine_lqr(A, B, c, Q, R, H, N)
        costs.append(affine_lqr_cost(P, p, s, x0))
        assert costs[-1] == pytest.approx(brute_force(A, B, c, Q, R, H, N, x0)[0], rel=1e-10)
    assert costs[0] > costs[1]
    # The offset of the last step is anticipated: the optimum pays less than doing nothing
    # (x(N) = [1, 0], cost H[0,0] / 2), so it acts before the offset arrives.
    assert costs[1] < 0.5
    _, kff, *_ = affine_lqr(A, B, last, Q, R, H, N)
    assert np.all(kff[1:] != 0.0)  # kff[0] (one step to go) cannot move x(N) against c: B has no z row


def test_one_step_horizon_is_the_nlsoc_law_with_E_equal_H():
    # NLSOC is exactly optimal when one step is left: u = -(f1'Hf1 + R)^-1 f1'H f0(x), f0 = A x + c.
    rng = np.random.default_rng(5)
    A, B, d = z_psi_affine_model(0.01, 1.3, 9.81, gravity_compensated=False)
    Q, R, H = psd(rng, 4), psd(rng, 2, 0.5), psd(rng, 4) * 100
    x = rng.normal(size=4)
    K, kff, *_ = affine_lqr(A, B, d, Q, R, H, 1)
    np.testing.assert_allclose(-K[0] @ x - kff[0], one_step_control(A @ x + d, B, H, R), rtol=1e-12)


# --------------------------------------------------------------------------- (2) c = 0 is LOC

@pytest.mark.parametrize("system", ["z", "y_phi"])
def test_zero_offset_reduces_to_the_loc_riccati_recursion(outdoor, system):
    a, b = linear_z(0.01) if system == "z" else linear_y_phi(0.01)
    q, r, h = outdoor.loc[system].resolved("corrected")
    N = 400
    F, P_loc = finite_horizon_lqr(a, b, q, r, h, N)
    for c in (None, np.zeros(a.shape[0]), np.zeros((N, a.shape[0]))):
        K, kff, P, p, s = affine_lqr(a, b, c, q, r, h, N)
        np.testing.assert_allclose(K, F, rtol=1e-9, atol=1e-12 * np.abs(F).max())
        np.testing.assert_allclose(P, P_loc, rtol=1e-9, atol=1e-12 * np.abs(P_loc).max())
        assert not kff.any() and not p.any() and not s.any()


def test_zero_offset_z_psi_gains_are_the_riccati_gains(indoor):
    q, r, h = indoor.nlsoc["z_psi"].resolved("corrected")
    A, B, _ = z_psi_affine_model(0.01, 1.0, 9.81, gravity_compensated=True)
    F, _ = finite_horizon_lqr(A, B, q, r, h, 300)
    K, *_ = affine_lqr(A, B, None, q, r, h, 300)
    np.testing.assert_allclose(K, F, rtol=1e-9, atol=1e-12 * np.abs(F).max())


# --------------------------------------------------------------------------- the altitude problem

def test_reference_offsets_of_the_ramp_vanish_except_where_it_ends(outdoor):
    prob = altitude_problem(outdoor, 20.0, "compensated")
    assert prob.c.shape == (2000, 4) and prob.refs.shape == (2001, 12)
    climb = 2.0 / 10.0
    end = 999  # the ramp ends at 10 s = step 1000: vz_r(999) = climb, vz_r(1000) = 0
    np.testing.assert_allclose(prob.c[end], [0.0, climb, 0.0, 0.0], atol=1e-12)
    assert np.abs(np.delete(prob.c, end, axis=0)).max() < 1e-12
    lit = altitude_problem(outdoor, 20.0, "literal")
    np.testing.assert_allclose(lit.c - prob.c, np.tile([0.0, -9.81 * 0.01, 0.0, 0.0], (2000, 1)), atol=1e-15)
    np.testing.assert_allclose(prob.x0(), [0.0, -climb, 0.0, 0.0])


def test_reference_offsets_formula():
    A, _, d = z_psi_affine_model(0.1, 2.0, 9.81, gravity_compensated=False)
    refs = np.array([[0.0, 1.0, 0.0, 0.0], [0.1, 1.0, 0.0, 0.0], [0.3, 0.0, 0.5, 0.0]])
    c = reference_offsets(A, refs, d)
    np.testing.assert_allclose(c, [A @ refs[0] - refs[1] + d, A @ refs[1] - refs[2] + d])


@pytest.mark.parametrize("convention", COST_CONVENTIONS)
def test_optimal_policy_rollout_reproduces_the_optimal_cost(indoor, outdoor, convention):
    for cfg in (indoor, outdoor):
        prob = altitude_problem(cfg, 20.0, convention)
        K, kff, P, p, s = prob.solve()
        J = affine_lqr_cost(P, p, s, prob.x0())
        ro = simulate_policy(prob, OptimalAffinePolicy(prob, K, kff))
        assert ro.cost[convention] == pytest.approx(J, rel=1e-10)
        # ... and perturbing the optimal inputs only costs more
        rng = np.random.default_rng(0)
        for _ in range(3):
            thrust = ro.command[:, 0] + rng.normal(scale=0.05, size=prob.horizon_steps)
            x = np.empty_like(ro.x)
            x[0] = ro.x[0]
            for k in range(prob.horizon_steps):
                v = np.array([thrust[k] - prob.hover_offset_n, ro.command[k, 3]])
                x[k + 1] = prob.A @ x[k] + prob.B @ v + prob.c[k]
            assert eq17_cost(prob, x, thrust, ro.command[:, 3]) > J


def test_unconstrained_config_sets_horizon_and_lifts_limits(outdoor):
    cfg = unconstrained_config(outdoor, 5)
    assert cfg.experiment.horizon_steps == 500
    assert cfg.vehicle.max_thrust_n == UNCONSTRAINED
    assert cfg.vehicle.max_angular_accel_rad_s2 == UNCONSTRAINED
    assert outdoor.experiment.horizon_steps == 60000  # the original is untouched
    assert make_controller("loc", cfg).horizon_steps == 500


@pytest.mark.parametrize("name", ["nlsoc", "nlsoc-literal"])
def test_simulated_nlsoc_is_the_one_step_law_on_the_affine_model(outdoor, name):
    # The rollout feeds the controller the model's state: its inputs are the one-step law
    # u = -(B'EB + R)^-1 B'E f0(x), f0 = A x (+ d for the literal law), E = H on the last step.
    conv = "compensated" if controller_spec(name).gravity_compensated else "literal"
    prob = altitude_problem(outdoor, 0.5, conv)
    ro = simulate_policy(prob, make_controller(name, unconstrained_config(outdoor, 0.5)))
    N = prob.horizon_steps
    for k in range(N):
        E = prob.H if k == N - 1 else prob.Q
        u = one_step_control(prob.A @ ro.x[k] + prob.d, prob.B, E, prob.R)
        assert ro.command[k, 0] - prob.hover_offset_n == pytest.approx(u[0], rel=1e-9, abs=1e-9)
        assert ro.command[k, 3] == pytest.approx(u[1], abs=1e-9)


# --------------------------------------------------------------------------- (3) nobody beats the optimum

@pytest.fixture(scope="module")
def tables(outdoor, indoor):
    return {cfg.experiment.name: optimality_table(cfg, horizons_s=(1, 20)) for cfg in (outdoor, indoor)}


def test_every_controller_costs_at_least_the_optimum(tables):
    for rows in tables.values():
        assert len(rows) == 2 * len(COST_CONVENTIONS) * len(CONTROLLERS)
        for r in rows:
            assert r.ratio >= 1.0 - 1e-9, r
            assert r.ratio == pytest.approx(r.J_controller / r.J_optimal)
            assert r.excess == pytest.approx(r.J_controller - r.J_optimal)


def test_table_facts(tables):
    out = {(r.horizon_s, r.convention, r.controller): r for r in tables["outdoor-altitude"]}
    # The gravity-compensated controllers never hit the thrust floor; NLSOC is the closest
    # to the optimum of its own cost outdoors, and the printed law's sag is far from it.
    for r in out.values():
        assert r.thrust_floor_steps == 0
    for h in (1.0, 20.0):
        ratios = {n: out[(h, "compensated", n)].ratio for n in CONTROLLERS}
        assert min(ratios, key=ratios.get) == "nlsoc"
        assert ratios["nlsoc-literal"] > 10
    txt = format_table(tables["outdoor-altitude"])
    assert "outdoor-altitude: eq. 17 with u = thrust - m g (compensated)" in txt
    assert "u = thrust (literal)" in txt


# --------------------------------------------------------------------------- (4) argument errors

def _ok():
    A, B = linear_z(0.01)
    return A, B, np.zeros(2), np.eye(2), np.eye(1), np.eye(2)


@pytest.mark.parametrize("change,match", [
    (dict(A=np.eye(2)[:1]), r"A matrix must be square"),
    (dict(B=np.ones((3, 1))), r"B matrix is the wrong shape: \(3, 1\), expected \(2, m\)"),
    (dict(c=np.zeros(3)), r"c has shape \(3,\), expected \(2,\) \(constant\) or \(4, 2\)"),
    (dict(c=np.zeros((5, 2))), r"c has shape \(5, 2\)"),
    (dict(Q=np.eye(3)), r"Q matrix is the wrong shape: \(3, 3\), expected \(2, 2\)"),
    (dict(H=np.eye(1)), r"H matrix is the wrong shape"),
    (dict(R=np.eye(2)), r"R matrix is the wrong shape: \(2, 2\), expected \(1, 1\)"),
    (dict(Q=np.array([[1.0, 1.0], [0.0, 1.0]])), r"Q matrix is not symmetric"),
    (dict(H=-np.eye(2)), r"H matrix is not positive semidefinite"),
    (dict(R=np.zeros((1, 1))), r"R matrix is not symmetric positive definite"),
    (dict(c=np.array([np.nan, 0.0])), r"c has non-finite entries"),
    (dict(N=0), r"horizon N must be an integer >= 1, got 0"),
    (dict(N=2.0), r"horizon N must be an integer >= 1, got 2.0"),
    (dict(N=True), r"horizon N must be an integer >= 1"),
])
def test_affine_lqr_rejects_bad_arguments(change, match):
    A, B, c, Q, R, H = _ok()
    args = dict(A=A, B=B, c=c, Q=Q, R=R, H=H, N=4)
    args.update(change)
    with pytest.raises(DesignError, match=match):
        affine_lqr(**args)
    assert issubclass(DesignError, ValueError)


def test_affine_lqr_accepts_a_1d_B():
    A, B, c, Q, R, H = _ok()
    for a, b in zip(affine_lqr(A, B[:, 0], c, Q, R, H, 3), affine_lqr(A, B, c, Q, R, H, 3), strict=True):
        np.testing.assert_array_equal(a, b)


def test_cost_and_helpers_reject_bad_arguments(outdoor):
    A, B, c, Q, R, H = _ok()
    _, _, P, p, s = affine_lqr(A, B, c, Q, R, H, 4)
    with pytest.raises(ValueError, match=r"x0 has shape \(3,\), expected \(2,\)"):
        affine_lqr_cost(P, p, s, np.zeros(3))
    with pytest.raises(ValueError, match=r"steps must be an integer in 0 .. 4, got 5"):
        affine_lqr_cost(P, p, s, np.zeros(2), steps=5)
    with pytest.raises(ValueError, match=r"p has shape \(4, 2\), expected \(5, 2\)"):
        affine_lqr_cost(P, p[:-1], s, np.zeros(2))
    with pytest.raises(ValueError, match=r"s has shape"):
        affine_lqr_cost(P, p, s[:-1], np.zeros(2))
    assert affine_lqr_cost(P, p, s, np.ones(2), steps=0) == pytest.approx(0.5 * np.ones(2) @ H @ np.ones(2))
    with pytest.raises(ValueError, match=r"refs has shape \(3, 3\), expected \(N \+ 1, 2\)"):
        reference_offsets(A, np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"d has shape \(3,\), expected \(2,\)"):
        reference_offsets(A, np.zeros((3, 2)), np.zeros(3))
    with pytest.raises(ValueError, match=r"ts must be a finite number > 0, got 0"):
        z_psi_affine_model(0, 1.0, 9.81, gravity_compensated=True)
    with pytest.raises(ValueError, match=r"convention must be one of compensated, literal, got 'hover'"):
        altitude_problem(outdoor, 1.0, "hover")
    with pytest.raises(ValueError, match=r"horizon 1.005 s is not a whole number of steps"):
        altitude_problem(outdoor, 1.005)
    with pytest.raises(ValueError, match=r"horizon_s must be a number >= one step"):
        unconstrained_config(outdoor, 0.0)
    prob = altitude_problem(outdoor, 0.05)
    with pytest.raises(ValueError, match=r"trajectory shapes"):
        eq17_cost(prob, np.zeros((5, 4)), np.zeros(5), np.zeros(5))
    with pytest.raises(ValueError, match=r"start has shape \(2,\), expected \(4,\)"):
        simulate_policy(prob, make_controller("pd", outdoor), start=(0.0, 0.0))
