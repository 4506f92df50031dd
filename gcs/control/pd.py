"""PD baseline (eq. 26 gains), with the LOC structure and gravity feed-forward (erratum 9).

Per subsystem, in error coordinates (attitude references 0)::

    u         = m (g - kp_z e_z - kd_z e_vz) / (cos(theta) cos(phi))
    tau_psi   = -kp_psi e_yaw - kd_psi e_yaw_rate
    tau_phi   = -kp_y e_y - kd_y e_vy - kp_phi phi - kd_phi phi_rate
    tau_theta = +kp_x e_x + kd_x e_vx - kp_theta theta - kd_theta theta_rate   (x-theta sign mirrored)

A disturbance acceleration ``d`` enters the inversions as for LOC: ``g - d_z`` in the thrust, and
phi, theta measured from the tilt that balances it (:func:`gcs.model.disturbance_tilt`).
"""

from __future__ import annotations

from gcs.config import PdGains
from gcs.control.base import NO_DISTURBANCE, Controller, Disturbance, Limits, wrap_angle
from quadrotor.state import Command, State
from gcs.model import ModelParams, disturbance_tilt, tilt_cos

__all__ = ["PdController"]


class PdController(Controller):
    """The PD baseline; needs no design step beyond its gains."""

    name = "pd"

    def __init__(self, gains: PdGains, model: ModelParams, limits: Limits) -> None:
        self.gains = gains
        self.model = model
        self.limits = limits

    def step(self, k: int, state: State, ref: State, disturbance_m_s2: Disturbance = NO_DISTURBANCE) -> Command:
        g = self.gains
        dx, dy, dz = disturbance_m_s2
        m, grav = self.model.mass_kg, self.model.gravity_m_s2
        az = -g.kp_z * (state[2] - ref[2]) - g.kd_z * (state[5] - ref[5])
        thrust = m * ((grav - dz) + az) / tilt_cos(state[6], state[7])
        phi_d, th_d = disturbance_tilt(thrust, m, grav, dx, dy)
        phi, th = state[6] - phi_d, state[7] - th_d
        t_yaw = -g.kp_psi * wrap_angle(state[8] - ref[8]) - g.kd_psi * (state[11] - ref[11])
        t_roll = -g.kp_y * (state[1] - ref[1]) - g.kd_y * (state[4] - ref[4]) - g.kp_phi * phi - g.kd_phi * state[9]
        t_pitch = g.kp_x * (state[0] - ref[0]) + g.kd_x * (state[3] - ref[3]) - g.kp_theta * th - g.kd_theta * state[10]
        return self.limits.saturate(thrust, t_roll, t_pitch, t_yaw)
