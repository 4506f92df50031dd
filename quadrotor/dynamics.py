"""The paper's reduced quadrotor model, eq. 1 — the one place it is written.

Paper frame (z up), SI units::

    m x'' = -u sin(theta)
    m y'' =  u cos(theta) sin(phi)
    m z'' =  u cos(theta) cos(phi) - m g
    phi'' = tau_phi,  theta'' = tau_theta,  psi'' = tau_psi

with the collective thrust ``u`` [N] and the angular accelerations ``tau`` [rad/s^2].  The
plant (:mod:`quadrotor.plant`, with drag, wind and the ground), the ground station's model and
estimator (``gcs``) all take their accelerations from :func:`eq1_acceleration`.
"""

from __future__ import annotations

import math

__all__ = ["eq1_acceleration"]


def eq1_acceleration(thrust_per_mass: float, roll: float, pitch: float,
                     gravity_m_s2: float) -> tuple[float, float, float]:
    """Translational acceleration of eq. 1 [m/s^2] for ``u / m`` [m/s^2] at attitude (roll, pitch) [rad]."""
    cp = math.cos(pitch)
    return (-thrust_per_mass * math.sin(pitch), thrust_per_mass * cp * math.sin(roll),
            thrust_per_mass * cp * math.cos(roll) - gravity_m_s2)
