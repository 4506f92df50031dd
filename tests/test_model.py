import math

import numpy as np
import pytest

from gcs.model import (
    SUBSYSTEMS, AffineContext, ModelParams, XThetaModel, YPhiModel, ZPsiModel, continuous_dynamics, euler_step,
    linear_x_theta, linear_y_phi, linear_z, subsystem_state, tilt_cos, z_psi_affine_model,
)
from quadrotor.state import STATE_FIELDS, State


def test_state_layout_matches_the_plant():
    assert State._fields == STATE_FIELDS


def test_continuous_dynamics_is_eq1():
    p = ModelParams(mass_kg=1.3, gravity_m_s2=9.81)
    s = State(vx=1.0, vy=2.0, vz=3.0, roll=0.2, pitch=-0.1, roll_rate=4.0, pitch_rate=5.0, yaw_rate=6.0)
    u = (12.0, 0.5, -0.25, 0.125)
    d = continuous_dynamics(s, u, p)
    assert d[:3].tolist() == [1.0, 2.0, 3.0]
    assert d[3] == pytest.approx(-12.0 * math.sin(-0.1) / 1.3)
    assert d[4] == pytest.approx(12.0 * math.cos(-0.1) * math.sin(0.2) / 1.3)
    assert d[5] == pytest.approx(12.0 * math.cos(-0.1) * math.cos(0.2) / 1.3 - 9.81)
    assert d[6:9].tolist() == [4.0, 5.0, 6.0]
    assert d[9:].tolist() == [0.5, -0.25, 0.125]


def test_euler_step_matches_the_papers_discrete_z_equation():
    p = ModelParams()
    s = State(z=1.0, vz=0.5, roll=0.1, pitch=0.2)
    u = 11.0
    n = euler_step(s, (u, 0, 0, 0), 0.01, p)
    assert n[2] == pytest.approx(1.0 + 0.01 * 0.5)
    assert n[5] == pytest.approx(0.5 - 0.01 * 9.81 + 0.01 * math.cos(0.2) * math.cos(0.1) * u)  # eq. 2


def test_subsystem_splits():
    s = State(*range(12))
    assert subsystem_state(s, "z_psi").tolist() == [2, 5, 8, 11]
    assert subsystem_state(s, "y_phi").tolist() == [1, 4, 6, 9]
    assert subsystem_state(s, "x_theta").tolist() == [0, 3, 7, 10]
    assert set(SUBSYSTEMS) == {"z", "psi", "z_psi", "y_phi", "x_theta"}
    with pytest.raises(ValueError, match="unknown subsystem"):
        subsystem_state(s, "q")


def test_linear_matrices_erratum_2_and_x_sign():
    a, b = linear_y_phi(0.01)
    assert a[3, 3] == 1.0 and a[1, 2] == pytest.approx(9.81 * 0.01)
    ax, bx = linear_x_theta(0.01)
    assert ax[1, 2] == pytest.approx(-9.81 * 0.01)
    np.testing.assert_array_equal(b, bx)
    az, bz = linear_z(0.01)
    np.testing.assert_array_equal(az, [[1, 0.01], [0, 1]])
    np.testing.assert_array_equal(bz, [[0], [0.01]])


def test_linearisations_match_the_nonlinear_model_for_small_angles():
    p = ModelParams()
    s = np.array(State(y=0.1, vy=0.2, roll=1e-4, roll_rate=0.01, x=0.3, vx=-0.1, pitch=-1e-4, pitch_rate=0.02))
    u = (p.hover_thrust_n, 0.3, -0.2, 0.0)
    n = euler_step(s, u, 0.01, p)
    a, b = linear_y_phi(0.01)
    np.testing.assert_allclose(a @ s[[1, 4, 6, 9]] + b[:, 0] * 0.3, n[[1, 4, 6, 9]], rtol=1e-6, atol=1e-10)
    a, b = linear_x_theta(0.01)
    np.testing.assert_allclose(a @ s[[0, 3, 7, 10]] + b[:, 0] * -0.2, n[[0, 3, 7, 10]], rtol=1e-6, atol=1e-10)


def test_tilt_cos_is_floored():
    assert tilt_cos(0.0, 0.0) == 1.0
    assert tilt_cos(1.5, 1.5) == 0.2


def test_model_params_are_checked():
    with pytest.raises(ValueError, match="mass_kg"):
        ModelParams(mass_kg=0.0)


# --------------------------------------------------------------------------- eq. 16 and eq. 20, once

def test_eq16_is_the_euler_step_of_eq1():
    p = ModelParams(mass_kg=1.3)
    s = State(z=1.0, vz=0.5, roll=0.1, pitch=-0.2, yaw=0.3, yaw_rate=0.4)
    u, tau = 11.0, 0.7
    n = euler_step(s, (u, 0.0, 0.0, tau), 0.01, p)
    zp = ZPsiModel(0.01, 1.3, 9.81)
    ctx = AffineContext()
    ctx.set_attitude(s.roll, s.pitch)
    x = [s.z, s.vz, s.yaw, s.yaw_rate]
    nxt = np.array(zp.f0(x, ctx)) + np.array(zp.f1(x, ctx)) @ [u, tau]
    np.testing.assert_allclose(nxt, n[[2, 5, 8, 11]], rtol=1e-12)
    # without gravity in f0 the input is the thrust beyond hover (erratum 8)
    comp = ZPsiModel(0.01, 1.3, 9.81, gravity_in_f0=False)
    assert comp.f0(x)[1] == s.vz and zp.f0(x)[1] == s.vz - 9.81 * 0.01


@pytest.mark.parametrize("model,idx,acc", [(YPhiModel, [1, 4, 6, 9], 4), (XThetaModel, [0, 3, 7, 10], 3)])
def test_eq20_is_the_euler_step_of_eq1_with_the_applied_thrust(model, idx, acc):
    p = ModelParams(mass_kg=1.3)
    s = State(x=0.2, y=-0.1, vx=0.3, vy=0.4, roll=0.15, pitch=-0.25, roll_rate=0.5, pitch_rate=-0.6)
    u, tau = 12.0, 0.9
    cmd = (u, tau, 0.0, 0.0) if model is YPhiModel else (u, 0.0, tau, 0.0)
    n = euler_step(s, cmd, 0.01, p)
    ctx = AffineContext(thrust_n=u)
    ctx.set_attitude(s.roll, s.pitch)
    m = model(0.01, 1.3)
    x = [s[i] for i in idx]
    nxt = np.array(m.f0(x, ctx)) + np.array(m.f1(x, ctx))[:, 0] * tau
    np.testing.assert_allclose(nxt, n[idx], rtol=1e-12)
    assert m.n == 4 and m.m == 1


def test_eq16_matrices_are_the_model_at_level_attitude():
    for comp in (True, False):
        a, b, d = z_psi_affine_model(0.01, 1.3, 9.81, gravity_compensated=comp)
        zp = ZPsiModel(0.01, 1.3, 9.81, gravity_in_f0=not comp)
        x = [0.3, -0.2, 0.1, 0.05]
        np.testing.assert_allclose(a @ x + d, zp.f0(x), rtol=1e-15, atol=1e-15)
        np.testing.assert_array_equal(b, zp.f1(x, AffineContext()))
        np.testing.assert_array_equal(a, [[1, 0.01, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.01], [0, 0, 0, 1]])
        np.testing.assert_array_equal(b, [[0, 0], [0.01 / 1.3, 0], [0, 0], [0, 0.01]])
        np.testing.assert_array_equal(d, [0.0, 0.0, 0.0, 0.0] if comp else [0.0, -9.81 * 0.01, 0.0, 0.0])
    with pytest.raises(ValueError, match="mass_kg must be a finite number > 0"):
        z_psi_affine_model(0.01, -1.0, 9.81, gravity_compensated=True)
