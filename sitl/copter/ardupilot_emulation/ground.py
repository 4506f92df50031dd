"""ArduPilot SITL's ground contact and sensor smoothing (``libraries/SITL/SIM_Aircraft.cpp``).

Two things of the firmware's *simulator*, not of ArduCopter, that together make its liftoff late
(docs/FIDELITY.md, "The liftoff"):

* **Sticky ground** (:func:`sticky_ground_step`).  A multicopter uses GROUND_BEHAVIOR_NO_MOVEMENT
  (``SIM_Multicopter.cpp``).  While the height above ground is at most 1 mm (``on_ground()``) a
  downward acceleration is zeroed but an upward one still builds up the vertical velocity
  (``update_dynamics``), while the position is put back on the ground every physics step
  (``update_position``: only a downward velocity is zeroed).  At the physics rate of 1200 Hz the
  vehicle can only leave once it moves more than 1 mm in one step: at
  :data:`RELEASE_SPEED_M_S` (1.2 m/s) of hidden upward speed.  Measured on the firmware's dataflash
  log (``SIM2.PD``, the true position, 400 Hz; loc, 10 s): thrust above weight from the mission
  start, height 0 until 0.696 s, then it leaves at 1.23 m/s.
* **Smoothed sensors** (:class:`SmoothedSensors`).  The same ground behaviour switches on
  ``use_smoothing``, never off again for a multicopter: what the barometer and GPS read
  (``fill_fdm``) is ``smooth_sensors``' tracking filter of the truth, time constant
  :data:`SMOOTHING_TAU_S`, the true acceleration fed forward.  In free flight it follows the truth;
  while the vehicle is pinned it reports a steady climb of ``a tau`` (0.17-0.21 m/s in the log,
  ``SIM.Alt``, which is this smoothed altitude, not the truth).

The emulation's own plant (:mod:`sitl.copter.rigid_body`) releases the vehicle as soon as thrust
exceeds weight; with these two the emulated liftoff moved from 0.30 s to 0.39-0.41 s after the
mission start (firmware 0.37-0.38 s).
"""

from __future__ import annotations

from collections.abc import Sequence

from quadrotor.frames import Kinematics
from sitl.copter import rigid_body
from sitl.copter.rigid_body import RigidBodyModel, RigidBodyState

__all__ = ["sticky_ground_step", "SmoothedSensors", "RELEASE_SPEED_M_S", "SMOOTHING_TAU_S"]

#: ArduPilot SITL's physics rate [Hz] (``SIM_Aircraft.h`` rate_hz).
PHYSICS_RATE_HZ = 1200.0
#: ``on_ground()``: height above ground at most this [m].
GROUND_MARGIN_M = 0.001
#: The hidden upward speed [m/s] at which a pinned vehicle moves more than the margin in one step.
RELEASE_SPEED_M_S = GROUND_MARGIN_M * PHYSICS_RATE_HZ
#: ``smooth_sensors``' time constant [s].
SMOOTHING_TAU_S = 0.1

_CALM = (0.0, 0.0, 0.0)


def sticky_ground_step(state: RigidBodyState, rotor_cmd_n: Sequence[float], dt: float, model: RigidBodyModel,
                       wind_ned: Sequence[float] = _CALM) -> RigidBodyState:
    """:func:`sitl.copter.rigid_body.step` with ArduPilot SITL's ground contact (module docstring).

    On the ground the vehicle stays where it is (attitude, position, no horizontal motion, no rates)
    while its upward velocity ``-vd`` integrates the upward acceleration, until that reaches
    :data:`RELEASE_SPEED_M_S`; then it is released with that velocity.  In the air: the plain step.
    """
    if not state.on_ground:
        return rigid_body.step(state, rotor_cmd_n, dt, model, wind_ned)
    free = rigid_body.step(state._replace(on_ground=False), rotor_cmd_n, dt, model, wind_ned)
    # A free step that ends below the ground comes back landed (vd 0): that was a downward acceleration.
    vd = state.vd if free.on_ground or free.vd > state.vd else free.vd
    vd = min(vd, 0.0)
    if -vd < RELEASE_SPEED_M_S:
        return state._replace(vn=0.0, ve=0.0, vd=vd, p=0.0, q=0.0, r=0.0,
                              t1=free.t1, t2=free.t2, t3=free.t3, t4=free.t4)
    return free


class SmoothedSensors:
    """``smooth_sensors``: the position and velocity the sensors read (module docstring).

    Each step ``a_s = ((v - v_s) + (p - p_s) / tau) / tau + a``, with ``a`` the true acceleration
    over the step; ``v_s += a_s dt``, ``p_s += v_s dt``.  Attitude and rates are passed through.

    Parameters
    ----------
    initial : Kinematics
        The true state at boot (NED).
    tau_s : float
        Time constant [s], > 0.
    """

    def __init__(self, initial: Kinematics, tau_s: float = SMOOTHING_TAU_S) -> None:
        if not tau_s > 0.0:
            raise ValueError(f"tau_s must be > 0, got {tau_s!r}")
        self.tau_s = tau_s
        self._p = [initial.n, initial.e, initial.d]
        self._v = [initial.vn, initial.ve, initial.vd]
        self._last_v = tuple(self._v)

    def apply(self, k: Kinematics, dt_s: float) -> Kinematics:
        """The smoothed reading of the true state ``k``, ``dt_s`` [s] after the previous one."""
        if dt_s <= 0.0:
            return k._replace(n=self._p[0], e=self._p[1], d=self._p[2], vn=self._v[0], ve=self._v[1], vd=self._v[2])
        tau = self.tau_s
        p, v = (k.n, k.e, k.d), (k.vn, k.ve, k.vd)
        ps, vs, v0 = self._p, self._v, self._last_v
        for i in range(3):
            a = ((v[i] - vs[i]) + (p[i] - ps[i]) / tau) / tau + (v[i] - v0[i]) / dt_s
            vs[i] += a * dt_s
            ps[i] += vs[i] * dt_s
        self._last_v = v
        return k._replace(n=ps[0], e=ps[1], d=ps[2], vn=vs[0], ve=vs[1], vd=vs[2])
