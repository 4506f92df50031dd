import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from gcs.control import make_controller
from gcs.control.nlsoc import MIRROR, AffineSubsystem, design_nlsoc, lateral_subsystem, one_step_control, z_psi_subsystem
from gcs.model import ModelParams
from quadrotor.state import State
from gcs.control.nlsoc import _Ctx

TS = 0.01
M = ModelParams(mass_kg=1.3)


def block_diag_psd(rng, n_blocks=2):
    blocks = []
    for _ in range(n_blocks):
        a = rng.normal(size=(2, 2))
        blocks.append(a @ a.T + 0.1 * np.eye(2))
    out = np.zeros((4, 4))
    out[:2, :2], out[2:, 2:] = blocks
    return out


def test_z_psi_law_equals_closed_forms_F1_F2_G1():
    rng = np.random.default_rng(7)
    for _ in range(50):
        E = block_diag_psd(rng) * rng.uniform(1, 1e4)
        r11, r22 = rng.uniform(0.1, 2.0, size=2)
        sub = z_psi_subsystem(TS, M, E, np.diag([r11, r22]), E, gravity_in_f0=True)
        phi, th = rng.uniform(-0.5, 0.5, size=2)
        ctx = _Ctx(math.cos(phi), math.sin(phi), math.cos(th), math.sin(th), 0.0)
        x = rng.normal(size=4)
        u, tau = sub.control(2, x, ctx)
        m, cc = M.mass_kg, math.cos(th) * math.cos(phi)
        factor = m * TS * cc / (r11 * m ** 2 + E[1, 1] * TS ** 2 * cc ** 2)
        F1 = factor * np.array([E[1, 0], E[1, 0] * TS + E[1, 1]])
        F2 = factor * E[1, 1] * M.gravity_m_s2 * TS
        G1 = TS / (E[3, 3] * TS ** 2 + r22) * np.array([E[3, 2], E[3, 2] * TS + E[3, 3]])
        assert u == pytest.approx(-F1 @ x[:2] + F2, rel=1e-9, abs=1e-9)
        assert tau == pytest.approx(-G1 @ x[2:], rel=1e-9, abs=1e-9)


@pytest.mark.parametrize("axis", ["y_phi", "x_theta"])
def test_lateral_law_equals_closed_form_when_E42_is_zero(axis):
    rng = np.random.default_rng(11)
    for _ in range(50):
        e = np.zeros((4, 4))
        e[0, 0], e[1, 1], e[2, 2], e[3, 3] = rng.uniform(1, 100, size=4)
        e[0, 3] = e[3, 0] = rng.uniform(-1, 1)
        e[2, 3] = e[3, 2] = rng.uniform(-1, 1)
        r = rng.uniform(0.1, 2.0)
        sub = lateral_subsystem(axis, TS, M, e, [[r]], e)
        ctx = _Ctx(math.cos(0.1), math.sin(0.1), math.cos(-0.2), math.sin(-0.2), rng.uniform(5, 15))
        x = rng.normal(size=4)
        (tau,) = sub.control(5, x, ctx)
        F = np.array([e[3, 0] * TS, e[3, 0] * TS ** 2, e[3, 2] * TS, e[3, 3] * TS + e[3, 2] * TS ** 2]) / (e[3, 3] * TS ** 2 + r)
        assert tau == pytest.approx(-F @ x, rel=1e-9, abs=1e-12)


def test_terminal_step_uses_H():
    Q, H = np.diag([1.0, 2.0, 3.0, 4.0]), np.diag([10.0, 20.0, 30.0, 40.0])
    sub = z_psi_subsystem(TS, M, Q, np.eye(2), H, gravity_in_f0=True)
    ctx, x = _Ctx(), [0.1, 0.2, 0.3, 0.4]
    f0 = [x[0] + TS * x[1], x[1] - 9.81 * TS, x[2] + TS * x[3], x[3]]
    f1 = sub.f1_dense(x, ctx)
    np.testing.assert_allclose(sub.control(1, x, ctx), one_step_control(f0, f1, H, np.eye(2)))
    np.testing.assert_allclose(sub.control(2, x, ctx), one_step_control(f0, f1, Q, np.eye(2)))


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2**31), st.integers(1, 3), st.integers(2, 6), st.floats(0.0, 1.0))
def test_fast_law_equals_the_matrix_form_for_any_affine_system(seed, m, n, density):
    rng = np.random.default_rng(seed)
    E = rng.normal(size=(n, n)) * 10  # need not be symmetric
    R = rng.normal(size=(m, m))
    R = R @ R.T + np.eye(m)
    pattern = tuple((i, a) for i in range(n) for a in range(m) if rng.uniform() < density or i == a)
    vals = rng.normal(size=len(pattern)).tolist()
    f0v = rng.normal(size=n).tolist()
    sub = AffineSubsystem("t", n, m, lambda x, c: f0v, pattern, lambda x, c: vals, E, R, E)
    f1 = sub.f1_dense(None, None)
    expected = one_step_control(f0v, f1, E, R)
    np.testing.assert_allclose(sub.control(3, None, None), expected, rtol=1e-8, atol=1e-10)


def test_one_step_control_checks_shapes():
    with pytest.raises(ValueError, match="E matrix is the wrong shape"):
        one_step_control([1, 2], [[1], [0]], np.eye(3), [[1]])
    with pytest.raises(ValueError, match="R matrix is the wrong shape"):
        one_step_control([1, 2], [[1], [0]], np.eye(2), np.eye(2))


def test_x_theta_matrices_are_mirrored(outdoor):
    d = design_nlsoc(outdoor, ModelParams())
    np.testing.assert_allclose(d.x_theta.Q, MIRROR @ d.y_phi.Q @ MIRROR)
    assert d.x_theta.Q[3, 1] == -8000.0
    printed = design_nlsoc(outdoor.with_matrices("printed"), ModelParams())
    np.testing.assert_allclose(printed.x_theta.Q, printed.y_phi.Q)


def test_literal_law_settles_0_118_m_low_outdoors(outdoor):
    # Fixed point of the printed law at hover: -F1 e_z + F2 = m g (erratum 8).
    E = np.array(outdoor.nlsoc["z_psi"].Q)
    r11 = outdoor.nlsoc["z_psi"].R[0][0]
    factor = TS / (r11 + E[1, 1] * TS ** 2)
    e_z = (factor * E[1, 1] * 9.81 * TS - 9.81) / (factor * E[1, 0])
    assert e_z == pytest.approx(-0.118, abs=0.002)
    ctl = make_controller("nlsoc-literal", outdoor)
    cmd = ctl.step(0, State(z=2.0 + e_z), State(z=2.0))
    assert cmd.thrust_n == pytest.approx(9.81, rel=1e-6)


def test_gravity_compensated_law_hovers_at_zero_error(indoor):
    ctl = make_controller("nlsoc", indoor)
    cmd = ctl.step(0, State(z=0.3, roll=0.1), State(z=0.3))
    assert cmd.thrust_n == pytest.approx(9.81 / math.cos(0.1))
