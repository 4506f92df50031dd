"""State estimation in the paper's frame from noisy, quantised, possibly late telemetry.

Each position axis runs a two-state Kalman filter (position, velocity) of a
constant-velocity model driven by the acceleration the model predicts from
the last command (thrust along the tilted body axis, minus gravity)::

    predict  p- = p + dt v + dt^2/2 a,   v- = v + dt a,   P- = F P F' + G G' sigma_a^2
    correct  with a position reading (variance noise^2 + resolution^2 / 12)
             and/or a velocity reading

``sigma_a`` (``accel_noise_std_m_s2``) covers what the model does not know
(wind, drag, thrust error).  Predictions run every control tick; corrections
whenever a reading arrives, so telemetry slower than the loop (or a late
frame) is handled.  Altitude is never estimated below the ground (z >= 0).
Attitude and Euler-angle rates are taken from the latest IMU reading.

The acceleration eq. 1 misses can be estimated by a :class:`DisturbanceObserver` attached to
the estimator: the vehicle's linear drag ``-c v`` (known: ``c`` = the config's
``vehicle.drag_n_per_m_s`` / mass) plus a steady remainder ``d`` (a hover throttle that is not
the vehicle's, a trim, a steady wind).  Each correction moves the velocity by ``dv``; summed
over a second the corrections are the acceleration the prediction missed, so the observer
integrates them, and the prediction adds the estimate::

    d <- clip(d + dv / tau_d, -d_max, d_max)       on every velocity correction dv
    predict with a = eq. 1 + (d - c v)

which converges as ``dd/dt = (d_true - d) / tau_d`` and leaves the filters unbiased once it
has.  ``tau_d`` (seconds) keeps it slow next to the controllers.  It learns only while airborne
(thrust above half of the hover thrust and the altitude estimate ``min_height_m`` above the
lowest seen): on the ground the ground's reaction is not a disturbance.

The same observer removes a slow offset ``b`` between the velocity readings and the
derivative of the position readings (an autopilot's EKF reports both; ArduCopter's differ by
1-2 cm/s for a whole flight, which a law with a weak position gain such as NLSOC's turns
into half a metre of drift).  With ``H(s) = 1 / (tau_b s + 1)`` low-passing both readings::

    b = H v_read - d/dt (H p_read) = H v_read - (p_read - H p_read) / tau_b = H (v_read - dp/dt)

(discretely, ``H p_read`` of the step before: exact for a constant velocity, see :meth:`advance`)

and the velocity readings are fused as ``v_read - b``: their slow part then follows the
positions, their fast part stays.  Without an observer nothing changes.

Both estimates assume readings that arrive steadily.  Across a gap (a radio drop-out: no reading
for more than ``reading_gap_s``; a stalled ground station: :meth:`DisturbanceObserver.restart`,
whose backlog then arrives at once) the position jumps by everything the vehicle did meanwhile,
which the low-passes would take for a velocity offset of up to ``jump / tau_b`` and the learning
for a disturbance.  So the offset ``b`` is held while no reading comes, the low-passes step
over the gap as if it had taken one step (the position low-pass moved by the jump), and the
corrections that close the gap are not learnt from.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.linalg

from quadrotor.state import Command, State
from quadrotor.dynamics import eq1_acceleration
from gcs.model import ModelParams

__all__ = ["kalman_gain_cv", "AxisFilter", "DisturbanceObserver", "StateEstimator"]


def kalman_gain_cv(ts: float, accel_noise_std: float, meas_std: float) -> tuple[float, float]:
    """Steady-state Kalman gain (k_pos, k_vel) of a constant-velocity model measured in position."""
    if not ts > 0 or not accel_noise_std > 0 or not meas_std > 0:
        raise ValueError("ts, accel_noise_std and meas_std must be > 0")
    a = np.array([[1.0, ts], [0.0, 1.0]])
    c = np.array([[1.0, 0.0]])
    g = np.array([[0.5 * ts * ts], [ts]])
    p = scipy.linalg.solve_discrete_are(a.T, c.T, accel_noise_std ** 2 * (g @ g.T), np.array([[meas_std ** 2]]))
    k = p @ c.T / (c @ p @ c.T + meas_std ** 2)
    return float(k[0, 0]), float(k[1, 0])


class AxisFilter:
    """Kalman filter of one axis: state (position [m], velocity [m/s]), covariance kept explicitly."""

    def __init__(self, accel_noise_std_m_s2: float, position: float = 0.0, velocity: float = 0.0,
                 position_var: float = 1.0, velocity_var: float = 1.0) -> None:
        if not accel_noise_std_m_s2 > 0:
            raise ValueError("accel_noise_std_m_s2 must be > 0")
        self.q = accel_noise_std_m_s2 ** 2
        self.p, self.v = position, velocity
        self.ppp, self.ppv, self.pvv = position_var, 0.0, velocity_var

    def predict(self, dt: float, accel: float) -> None:
        """Advance by dt [s] with the known acceleration [m/s^2]."""
        h2 = 0.5 * dt * dt
        self.p += dt * self.v + h2 * accel
        self.v += dt * accel
        q = self.q
        ppp, ppv, pvv = self.ppp, self.ppv, self.pvv
        self.ppp = ppp + 2 * dt * ppv + dt * dt * pvv + q * h2 * h2
        self.ppv = ppv + dt * pvv + q * h2 * dt
        self.pvv = pvv + q * dt * dt

    def correct_position(self, z: float, var: float) -> None:
        """Fuse a position reading of variance ``var`` [m^2]."""
        s = self.ppp + var
        kp, kv = self.ppp / s, self.ppv / s
        innov = z - self.p
        self.p += kp * innov
        self.v += kv * innov
        ppp, ppv, pvv = self.ppp, self.ppv, self.pvv
        self.ppp = (1 - kp) * ppp
        self.ppv = (1 - kp) * ppv
        self.pvv = pvv - kv * ppv

    def correct_velocity(self, z: float, var: float) -> None:
        """Fuse a velocity reading of variance ``var`` [(m/s)^2]."""
        s = self.pvv + var
        kp, kv = self.ppv / s, self.pvv / s
        innov = z - self.v
        self.p += kp * innov
        self.v += kv * innov
        ppp, ppv, pvv = self.ppp, self.ppv, self.pvv
        self.ppp = ppp - kp * ppv
        self.ppv = ppv - kp * pvv
        self.pvv = (1 - kv) * pvv


def model_acceleration(model: ModelParams, command: Command | None, roll: float,
                       pitch: float) -> tuple[float, float, float]:
    """Acceleration [m/s^2] (paper frame) of the reduced model (eq. 1) under ``command`` (zero for None)."""
    if command is None:
        return (0.0, 0.0, 0.0)
    return eq1_acceleration(command[0] / model.mass_kg, roll, pitch, model.gravity_m_s2)


class DisturbanceObserver:
    """The acceleration eq. 1 misses [m/s^2] (paper frame, z up): linear drag plus a steady remainder
    estimated from a :class:`StateEstimator`'s velocity corrections (see the module docstring).

    Parameters
    ----------
    time_constant_s : float
        ``tau_d``: how slowly the estimate follows the mismatch (seconds, > 0).
    drag_1_s : float
        ``c``: linear drag per unit mass [1/s] (drag force per speed / mass), modelled, not estimated.
    max_m_s2 : float
        The estimated remainder is clipped to +-this per axis.
    min_height_m : float
        Learns only this far above the lowest altitude estimate seen (off the ground).
    min_thrust_fraction : float
        ... and only while the thrust commanded is at least this share of the hover thrust.
    velocity_bias_time_constant_s : float
        ``tau_b``: the low-pass of the velocity-reading offset (seconds, > 0).
    max_velocity_bias_m_s : float
        The offset is clipped to +-this per axis.
    reading_gap_s : float
        No position reading for longer than this [s] is a gap (see the module docstring).
    """

    def __init__(self, time_constant_s: float, *, drag_1_s: float = 0.0, max_m_s2: float = 3.0,
                 min_height_m: float = 0.3, min_thrust_fraction: float = 0.5,
                 velocity_bias_time_constant_s: float = 10.0, max_velocity_bias_m_s: float = 0.5,
                 reading_gap_s: float = 0.2) -> None:
        if not time_constant_s > 0 or not max_m_s2 > 0 or not drag_1_s >= 0 or not velocity_bias_time_constant_s > 0 \
                or not reading_gap_s > 0:
            raise ValueError("time_constant_s, max_m_s2, velocity_bias_time_constant_s and reading_gap_s must be > 0, "
                             "drag_1_s >= 0")
        self.time_constant_s = time_constant_s
        self.drag_1_s = drag_1_s
        self.max_m_s2 = max_m_s2
        self.min_height_m = min_height_m
        self.min_thrust_fraction = min_thrust_fraction
        self.velocity_bias_time_constant_s = velocity_bias_time_constant_s
        self.max_velocity_bias_m_s = max_velocity_bias_m_s
        self.reading_gap_s = reading_gap_s
        self.value = [0.0, 0.0, 0.0]
        self.velocity_bias = [0.0, 0.0, 0.0]
        self.learning = False
        self.ground_z_m: float | None = None
        self._read: list[list[float | None]] = [[None, None] for _ in range(3)]  # latest (position, velocity)
        self._low: list[list[float] | None] = [None, None, None]                 # H p_read, H v_read
        self._since = [0.0, 0.0, 0.0]      # time since the last position reading [s] (advanced by advance())
        self._new = [False, False, False]  # a position reading came since the last advance()
        self._hold = [False, False, False]  # closing a gap: no learning from this step's corrections
        self._gap = [False, False, False]   # closing a gap: the next step moves the position low-pass by the jump
        self._used = [0.0, 0.0, 0.0]        # the position reading of the last step [m]

    def restart(self) -> None:
        """After a gap in the readings the caller knows of (the loop stalled: its backlog comes at once):
        the next :meth:`advance` steps the low-passes over it as one step, and nothing is learnt from the
        corrections before it; ``b`` and ``d`` are kept."""
        self._gap = [True, True, True]
        self._hold = [True, True, True]

    def position_reading(self, axis: int, z: float) -> None:
        """A position reading [m] of ``axis`` (for the velocity-reading offset); the first after a gap
        of more than ``reading_gap_s`` closes a gap on that axis (see :meth:`restart`)."""
        if self._since[axis] > self.reading_gap_s:
            self._gap[axis] = True
            self._hold[axis] = True
        self._new[axis] = True
        self._read[axis][0] = z

    def velocity_reading(self, axis: int, z: float) -> float:
        """A velocity reading [m/s] of ``axis``: the reading less its estimated offset ``b``."""
        self._read[axis][1] = z
        return z - self.velocity_bias[axis]

    def advance(self, dt_s: float) -> None:
        """Run the low-passes of the readings over the ``dt_s`` [s] since the last call: per axis, once a
        new position reading has come, over the time since the one before; update ``b``."""
        tau, lim = self.velocity_bias_time_constant_s, self.max_velocity_bias_m_s
        hold = self._hold  # in place: no list per tick on the 100 Hz path
        hold[0] = hold[1] = hold[2] = False
        for i, (p, v) in enumerate(self._read):
            if not self._new[i]:  # nothing new: the offset held, the time counted
                self._since[i] += dt_s
                continue
            step_s = self._since[i] + dt_s
            self._new[i], self._since[i] = False, 0.0
            if p is None or v is None:
                continue
            low = self._low[i]
            if low is None:
                self._low[i] = [p, v]
                self._used[i] = p
                continue
            if self._gap[i]:  # as if the jump had been one step: the lag of the low-pass kept
                low[0] += p - self._used[i]
                step_s, self._gap[i] = dt_s, False
            self._used[i] = p
            a = min(1.0, step_s / tau)
            # d/dt (H p) from the low-pass *before* this step: with Euler's a = dt / tau, the updated one
            # gives (1 - a) dp/dt for a constant velocity, a false offset of a v (6.7 % of every
            # velocity at tau_b = 0.15 s, 10 ms steps); the previous one gives dp/dt exactly.
            b = low[1] + a * (v - low[1]) - (p - low[0]) / tau
            low[0] += a * (p - low[0])
            low[1] += a * (v - low[1])
            self.velocity_bias[i] = lim if b > lim else -lim if b < -lim else b

    def gate(self, z_m: float, thrust_n: float, hover_thrust_n: float) -> None:
        """Learn from the next corrections only while airborne (altitude and thrust)."""
        g = self.ground_z_m
        if g is None or z_m < g:
            self.ground_z_m = g = z_m
        self.learning = z_m - g >= self.min_height_m and thrust_n >= self.min_thrust_fraction * hover_thrust_n

    def absorb(self, axis: int, dv_m_s: float) -> None:
        """A velocity correction ``dv_m_s`` of ``axis`` (0 x, 1 y, 2 z) (not learnt from across a gap)."""
        if self.learning and not self._hold[axis]:
            lim = self.max_m_s2
            v = self.value[axis] + dv_m_s / self.time_constant_s
            self.value[axis] = lim if v > lim else -lim if v < -lim else v

    def acceleration(self, velocity_m_s) -> tuple[float, float, float]:
        """The acceleration eq. 1 misses at ``velocity_m_s`` (x, y, z) [m/s^2]: ``d - c v``."""
        c = self.drag_1_s
        x, y, z = self.value
        return (x - c * velocity_m_s[0], y - c * velocity_m_s[1], z - c * velocity_m_s[2])


class StateEstimator:
    """Position/velocity filters on x, y, z plus attitude from the IMU.

    Two ways to drive it:

    * :meth:`update` with one full reading per control period (the in-process simulation);
    * :meth:`predict` every tick, :meth:`correct_position`, :meth:`correct_velocity` and
      :meth:`set_attitude` whenever telemetry arrives, then :meth:`state` (the flight loop).

    Parameters
    ----------
    ts : float
        Control period [s].
    model : ModelParams
    position_std_m : (float, float, float)
        Measurement noise of x, y, z [m] used by :meth:`update` (include quantisation).
    accel_noise_std_m_s2 : float
        Process noise: unmodelled acceleration.
    ground_z_m : float or None
        Altitude of the ground (the estimate never goes below it); None = no ground
        constraint (a real vehicle's local origin need not be on the ground).

    Attributes
    ----------
    disturbance : DisturbanceObserver or None
        Attach one to estimate a steady disturbance (None: none, the filters as they were).
    """

    def __init__(self, ts: float, model: ModelParams, position_std_m: Sequence[float], accel_noise_std_m_s2: float,
                 *, ground_z_m: float | None = 0.0) -> None:
        self.ts = ts
        self.ground_z_m = ground_z_m
        self.model = model
        self.position_var = [max(float(s), 1e-4) ** 2 for s in position_std_m]
        self.accel_noise_std_m_s2 = accel_noise_std_m_s2
        self.disturbance: DisturbanceObserver | None = None
        self.reset()

    def reset(self) -> None:
        """Forget the estimate; the next position reading initialises it."""
        self.axes: list[AxisFilter] | None = None
        self.attitude = (0.0,) * 6

    def predict(self, dt: float, last_command: Command | None) -> None:
        """Advance the filters by dt [s] under the command applied meanwhile."""
        if self.axes is None:
            return
        acc = model_acceleration(self.model, last_command, self.attitude[0], self.attitude[1])
        obs = self.disturbance
        if obs is not None:
            obs.advance(dt)
            obs.gate(self.axes[2].p, last_command[0] if last_command is not None else 0.0, self.model.hover_thrust_n)
            acc = tuple(a + d for a, d in zip(acc, obs.acceleration([f.v for f in self.axes])))
        for f, a in zip(self.axes, acc):
            f.predict(dt, a)
        self._clamp_ground()

    def correct_position(self, pos: Sequence[float], var: Sequence[float] | None = None) -> None:
        """Fuse a position reading (x, y, z up) [m]; the first one initialises the filters."""
        var = self.position_var if var is None else var
        if self.axes is None:
            self.axes = [AxisFilter(self.accel_noise_std_m_s2, p, 0.0, v, 1.0) for p, v in zip(pos, var)]
            self._clamp_ground()
            return
        obs = self.disturbance
        for i, (f, z, v) in enumerate(zip(self.axes, pos, var)):
            v0 = f.v
            f.correct_position(z, v)
            if obs is not None:
                obs.position_reading(i, z)
                obs.absorb(i, f.v - v0)
        self._clamp_ground()

    def correct_velocity(self, vel: Sequence[float], var: Sequence[float]) -> None:
        """Fuse a velocity reading (paper frame) [m/s]."""
        if self.axes is None:
            return
        obs = self.disturbance
        for i, (f, z, v) in enumerate(zip(self.axes, vel, var)):
            v0 = f.v
            f.correct_velocity(z if obs is None else obs.velocity_reading(i, z), v)
            if obs is not None:
                obs.absorb(i, f.v - v0)
        self._clamp_ground()

    def set_attitude(self, roll: float, pitch: float, yaw: float,
                     roll_rate: float, pitch_rate: float, yaw_rate: float) -> None:
        """Latest attitude [rad] and Euler-angle rates [rad/s]."""
        self.attitude = (roll, pitch, yaw, roll_rate, pitch_rate, yaw_rate)

    def _clamp_ground(self) -> None:
        g = self.ground_z_m
        if g is None:
            return
        fz = self.axes[2]  # type: ignore[index]
        if fz.p < g:
            fz.p = g
            if fz.v < 0.0:
                fz.v = 0.0

    def disturbance_m_s2(self) -> tuple[float, float, float]:
        """The acceleration eq. 1 misses (x, y, z up) [m/s^2] at the estimated velocity; zeros without an
        observer (or before the first reading)."""
        if self.disturbance is None or self.axes is None:
            return (0.0, 0.0, 0.0)
        return self.disturbance.acceleration([f.v for f in self.axes])

    @property
    def initialised(self) -> bool:
        return self.axes is not None

    def state(self) -> State:
        """The current estimate (zeros before the first position reading)."""
        if self.axes is None:
            return State(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, *self.attitude)
        x, y, z = self.axes
        return State(x.p, y.p, z.p, x.v, y.v, z.v, *self.attitude)

    def update(self, reading: Sequence[float], last_command: Command | None) -> State:
        """One control period: reading ``(x, y, z, roll, pitch, yaw, roll_rate, pitch_rate, yaw_rate)``.

        ``last_command`` is the command applied since the previous reading (None at the start).
        """
        if self.axes is not None:
            self.predict(self.ts, last_command)
        self.correct_position((reading[0], reading[1], reading[2]))
        self.set_attitude(*reading[3:9])
        return self.state()
