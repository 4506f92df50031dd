import math
import operator

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from gcs.control import make_controller
from gcs.control.nlsoc import (
    MIRROR, design_nlsoc, design_nlsoc_from_config, lateral_subsystem, nlsoc_weights, one_step_control,
    one_step_law, z_psi_subsystem,
)
from gcs.errors import DesignError
from gcs.model import AffineContext as _Ctx
from gcs.model import ModelParams
from quadrotor.state import State

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
        F = (np.array([e[3, 0] * TS, e[3, 0] * TS ** 2, e[3, 2] * TS, e[3, 3] * TS + e[3, 2] * TS ** 2])
             / (e[3, 3] * TS ** 2 + r))
        assert tau == pytest.approx(-F @ x, rel=1e-9, abs=1e-12)


def test_terminal_step_uses_H():
    Q, H = np.diag([1.0, 2.0, 3.0, 4.0]), np.diag([10.0, 20.0, 30.0, 40.0])
    sub = z_psi_subsystem(TS, M, Q, np.eye(2), H, gravity_in_f0=True)
    ctx, x = _Ctx(), [0.1, 0.2, 0.3, 0.4]
    f0 = [x[0] + TS * x[1], x[1] - 9.81 * TS, x[2] + TS * x[3], x[3]]
    f1 = sub.f1_dense(x, ctx)
    np.testing.assert_allclose(sub.control(1, x, ctx), one_step_control(f0, f1, H, np.eye(2)))
    np.testing.assert_allclose(sub.control(2, x, ctx), one_step_control(f0, f1, Q, np.eye(2)))


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**31), st.integers(1, 2), st.floats(0.0, 1.0))
def test_plain_python_law_equals_the_matrix_form(seed, m, density):
    # Any f0, any f1 (dense or sparse), any E (need not be symmetric), n = 4 and m <= 2: the law that
    # flies is the matrix form, evaluated in plain Python.
    rng = np.random.default_rng(seed)
    E = rng.normal(size=(4, 4)) * 10
    R = rng.normal(size=(m, m))
    R = R @ R.T + np.eye(m)
    f1 = rng.normal(size=(4, m)) * (rng.uniform(size=(4, m)) < density)
    f0 = rng.normal(size=4)
    expected = one_step_control(f0, f1, E, R)
    got = one_step_law(f0.tolist(), f1.tolist(), E.tolist(), R.tolist())
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-9 * max(1.0, np.abs(expected).max()))


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31), st.integers(1, 3), st.integers(2, 6))
def test_plain_python_law_falls_back_to_numpy_for_other_sizes(seed, m, n):
    rng = np.random.default_rng(seed)
    E, R = rng.normal(size=(n, n)), np.eye(m) * 2.0
    f0, f1 = rng.normal(size=n), rng.normal(size=(n, m))
    np.testing.assert_allclose(one_step_law(f0.tolist(), f1.tolist(), E.tolist(), R.tolist()),
                               one_step_control(f0, f1, E, R), rtol=1e-12)


@pytest.mark.parametrize("name", ["nlsoc", "nlsoc-literal"])
def test_flying_law_is_the_matrix_form_at_every_step(outdoor, name):
    # The controller's commands over a short flight equal the numpy law evaluated on f0(x), f1(x) of
    # the models (before saturation, which these states do not reach).
    ctl = make_controller(name, outdoor)
    d = ctl.law.design
    rng = np.random.default_rng(3)
    for k in (0, 59_998, 59_999):
        s = State(*(rng.normal(scale=0.05, size=12) + np.r_[0, 0, 2.0, np.zeros(9)]).tolist())
        ref = State(z=2.0, vz=0.1)
        cmd = ctl.step(k, s, ref)
        last = k == outdoor.experiment.horizon_steps - 1
        ctx = _Ctx()
        ctx.set_attitude(s.roll, s.pitch)
        ez = [s.z - 2.0, s.vz - 0.1, s.yaw, s.yaw_rate]
        zp = d.z_psi
        du, tau_psi = one_step_control(zp.model.f0(ez, ctx), zp.f1_dense(ez, ctx), zp.H if last else zp.Q, zp.R)
        hover = 9.81 / (math.cos(s.roll) * math.cos(s.pitch)) if name == "nlsoc" else 0.0
        assert cmd.thrust_n == pytest.approx(hover + du, rel=1e-12)
        assert cmd.yaw_accel_rad_s2 == pytest.approx(tau_psi, rel=1e-12)
        ctx.thrust_n = cmd.thrust_n
        ey = [s.y, s.vy, s.roll, s.roll_rate]
        yp = d.y_phi
        (t_roll,) = one_step_control(yp.model.f0(ey, ctx), yp.f1_dense(ey, ctx), yp.H if last else yp.Q, yp.R)
        assert cmd.roll_accel_rad_s2 == pytest.approx(t_roll, rel=1e-12)


def test_flown_commands_are_those_of_the_hand_optimised_law_before_the_refactor(outdoor):
    # The sparse loop that flew before this law: the same products, in the same order.
    ctl = make_controller("nlsoc", outdoor)
    d = ctl.law.design
    rng = np.random.default_rng(5)
    for _ in range(200):
        x = rng.normal(size=4).tolist()
        ctx = _Ctx(thrust_n=rng.uniform(5.0, 15.0))
        ctx.set_attitude(*rng.normal(scale=0.2, size=2))
        for sub, pattern in ((d.z_psi, ((1, 0), (3, 1))), (d.y_phi, ((3, 0),)), (d.x_theta, ((3, 0),))):
            for j in (1, 2):
                assert sub.control(j, x, ctx) == _old_sparse_law(sub, pattern, j, x, ctx)


def _old_sparse_law(sub, pattern, j, x, ctx):
    E = (sub.H if j == 1 else sub.Q).tolist()
    f0 = sub.model.f0(x, ctx)
    f1 = sub.model.f1(x, ctx)
    vals = [f1[i][a] for i, a in pattern]
    m = sub.m
    b = [0.0] * m
    M = [row[:] for row in sub.R.tolist()]
    for (i, a), v in zip(pattern, vals, strict=True):
        b[a] += v * sum(map(operator.mul, E[i], f0))
        for (i2, a2), v2 in zip(pattern, vals, strict=True):
            M[a][a2] += v * E[i][i2] * v2
    if m == 1:
        return [-b[0] / M[0][0]]
    (p, q), (r, s) = M
    det = p * s - q * r
    return [-(s * b[0] - q * b[1]) / det, -(p * b[1] - r * b[0]) / det]


def test_one_step_control_checks_shapes():
    with pytest.raises(ValueError, match="E matrix is the wrong shape"):
        one_step_control([1, 2], [[1], [0]], np.eye(3), [[1]])
    with pytest.raises(ValueError, match="R matrix is the wrong shape"):
        one_step_control([1, 2], [[1], [0]], np.eye(2), np.eye(2))


def test_x_theta_matrices_are_mirrored(outdoor):
    d = design_nlsoc_from_config(outdoor)
    np.testing.assert_allclose(d.x_theta.Q, MIRROR @ d.y_phi.Q @ MIRROR)
    assert d.x_theta.Q[3, 1] == -8000.0
    printed = design_nlsoc_from_config(outdoor.with_matrices("printed"))
    np.testing.assert_allclose(printed.x_theta.Q, printed.y_phi.Q)


def test_design_takes_matrices_and_the_adapter_reads_the_config(outdoor):
    w = nlsoc_weights(outdoor)
    assert set(w) == {"z_psi", "y_phi", "x_theta"}
    d = design_nlsoc(0.01, 1.0, 9.81, w, 6000, gravity_compensated=False)
    assert not d.gravity_compensated and d.z_psi.model.gravity_in_f0
    np.testing.assert_array_equal(d.z_psi.Q, w["z_psi"][0])
    ref = design_nlsoc_from_config(outdoor, gravity_compensated=False)
    for name in ("z_psi", "y_phi", "x_theta"):
        for mat in ("Q", "R", "H"):
            np.testing.assert_array_equal(getattr(getattr(d, name), mat), getattr(getattr(ref, name), mat))
    bad = dict(w, y_phi=(w["y_phi"][0], np.eye(2), w["y_phi"][2]))
    with pytest.raises(DesignError, match=r"nlsoc\.y_phi: R matrix is the wrong shape"):
        design_nlsoc(0.01, 1.0, 9.81, bad, 10)


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
