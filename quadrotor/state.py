"""The state vector and the command of the paper's reduced model, once for everyone.

Paper frame: x north, y east (as MAVLink LOCAL_POSITION_NED), z **up**; roll, pitch, yaw as
MAVLink ATTITUDE; *Euler-angle* rates.  The plant's truth, the ground station's estimate,
references and the log's ``/control/state`` all use :class:`State`'s field order.
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["State", "Command", "STATE_FIELDS", "COMMAND_FIELDS"]


class State(NamedTuple):
    """Full state of the reduced model: positions [m], velocities [m/s], Euler angles [rad],
    Euler-angle rates [rad/s]."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    vx: float = 0.0
    vy: float = 0.0
    vz: float = 0.0
    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0
    roll_rate: float = 0.0
    pitch_rate: float = 0.0
    yaw_rate: float = 0.0


class Command(NamedTuple):
    """The controllers' output: collective thrust [N] and Euler-angle accelerations [rad/s^2]
    (the model has unit inertia)."""

    thrust_n: float
    roll_accel_rad_s2: float
    pitch_accel_rad_s2: float
    yaw_accel_rad_s2: float


STATE_FIELDS = State._fields
COMMAND_FIELDS = Command._fields
