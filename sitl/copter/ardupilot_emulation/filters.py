"""The filters of ArduCopter's rate loop: AP_Filter's LowPassFilter2p and AC_PID (P, I, D, FLTT/FLTE/FLTD).

``LowPass2p`` is the two-pole Butterworth biquad the IMU applies to the gyro (``INS_GYRO_FILTER``
[Hz]) at the loop rate; ``RatePid`` is ``AC_PID::update_all`` without notch filters, slew limiter
or feed-forward (their parameters are 0 in ArduCopter's SITL defaults).  The PID's output is a
normalised motor command (roll, pitch, yaw in -1..1), not a torque.
"""

from __future__ import annotations

import math

__all__ = ["LowPass2p", "RatePid", "lowpass_alpha"]


def lowpass_alpha(cutoff_hz: float, dt: float) -> float:
    """First-order low-pass coefficient ``dt / (dt + 1 / (2 pi f))`` (1 = no filter when ``cutoff_hz <= 0``)."""
    if cutoff_hz <= 0.0 or dt <= 0.0:
        return 1.0
    return dt / (dt + 1.0 / (2.0 * math.pi * cutoff_hz))


class LowPass2p:
    """Two-pole Butterworth low-pass (ArduPilot's DigitalBiquadFilter), one channel.

    Parameters
    ----------
    sample_hz : float
        Sample rate [Hz].
    cutoff_hz : float
        Cut-off [Hz]; <= 0 passes the input through.
    """

    def __init__(self, sample_hz: float, cutoff_hz: float) -> None:
        self.enabled = cutoff_hz > 0.0 and sample_hz > 2.0 * cutoff_hz
        self.d1 = self.d2 = 0.0
        self._primed = False
        if not self.enabled:
            self.b0 = 1.0
            self.b1 = self.b2 = self.a1 = self.a2 = 0.0
            return
        fr = sample_hz / cutoff_hz
        ohm = math.tan(math.pi / fr)
        c = 1.0 + 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm
        self.b0 = ohm * ohm / c
        self.b1 = 2.0 * self.b0
        self.b2 = self.b0
        self.a1 = 2.0 * (ohm * ohm - 1.0) / c
        self.a2 = (1.0 - 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm) / c

    def apply(self, x: float) -> float:
        """Filter one sample (the first one initialises the state, as ArduPilot's reset does)."""
        if not self.enabled:
            return x
        if not self._primed:
            self._primed = True
            self.d1 = self.d2 = x / (1.0 + self.a1 + self.a2)
        d0 = x - self.d1 * self.a1 - self.d2 * self.a2
        y = d0 * self.b0 + self.d1 * self.b1 + self.d2 * self.b2
        self.d2 = self.d1
        self.d1 = d0
        return y


class RatePid:
    """``AC_PID::update_all`` for one body axis.

    Parameters
    ----------
    kp, ki, kd : float
        ``ATC_RAT_*_P`` [1/(rad/s)], ``_I`` [1/rad], ``_D`` [s/rad]: normalised output per rate error.
    imax : float
        ``ATC_RAT_*_IMAX``.
    fltt_hz, flte_hz, fltd_hz : float
        Target, error and derivative filter cut-offs [Hz] (0 = none).
    """

    def __init__(self, kp: float, ki: float, kd: float, imax: float, fltt_hz: float, flte_hz: float,
                 fltd_hz: float) -> None:
        self.kp, self.ki, self.kd, self.imax = kp, ki, kd, imax
        self.fltt_hz, self.flte_hz, self.fltd_hz = fltt_hz, flte_hz, fltd_hz
        self.integrator = 0.0
        self._target = self._error = self._derivative = 0.0
        self._reset = True

    def reset_filter(self) -> None:
        """The next update starts the filters at its inputs (ArduPilot's ``reset_filter``)."""
        self._reset = True

    def reset_i(self) -> None:
        """Zero the integrator."""
        self.integrator = 0.0

    def relax_i(self, dt: float, time_constant_s: float) -> None:
        """Move the integrator towards 0 with ``time_constant_s`` (``AC_PID::relax_integrator(0, dt, tc)``)."""
        self.integrator -= self.integrator * (dt / (dt + time_constant_s))

    def update(self, target: float, measurement: float, dt: float, limit: bool) -> float:
        """Output for rate ``target`` and gyro ``measurement`` [rad/s]; ``limit``: the motors saturate (I frozen)."""
        if self._reset:
            self._reset = False
            self._target = target
            self._error = target - measurement
            self._derivative = 0.0
        else:
            self._target += lowpass_alpha(self.fltt_hz, dt) * (target - self._target)
            last = self._error
            self._error += lowpass_alpha(self.flte_hz, dt) * (self._target - measurement - self._error)
            if dt > 0.0:
                self._derivative += lowpass_alpha(self.fltd_hz, dt) * ((self._error - last) / dt - self._derivative)
        e = self._error
        if self.ki != 0.0 and dt > 0.0:
            i = self.integrator
            if not limit or (i > 0.0 and e < 0.0) or (i < 0.0 and e > 0.0):
                i += e * self.ki * dt
                self.integrator = max(-self.imax, min(self.imax, i))
        else:
            self.integrator = 0.0
        return e * self.kp + self._derivative * self.kd + self.integrator
