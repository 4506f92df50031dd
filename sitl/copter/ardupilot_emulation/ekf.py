"""The emulated EKF's estimate: its height late and a few millimetres low, its attitude tilted by a
tenth of a degree and its horizontal position and velocity pulled off by that tilt, as ArduCopter's
EKF3 in the firmware's SITL.

**Height** (:class:`EkfHeight`).  Measured on the firmware's SITL (4.8.0-dev at 64a9c787, ``gcs fly``
with its dataflash log).  On the ground the estimate sits 6 mm below what the simulator's sensors read
(``SIM.Alt``, its smoothed altitude: :mod:`.ground`).  Against the truth (``SIM2.PD``, 400 Hz) it is
late by 0.03-0.04 s where the motion changes smoothly (the stop at the top of the climb and the
landing, three logs, 1.5-3.8 mm RMS left: ``benchmarks/ekf_dataflash_fit.py``); the 0.1 s an earlier
stop measured was against ``SIM.Alt`` over the whole climb, whose first seconds hold the EKF's
liftoff transient (2.4 cm below the truth 1 s after the release, then 1-2 cm above it), which is not
emulated.  So the estimate is a first-order lag of the sensed down position (time constant
:data:`HEIGHT_LAG_S`, 0.035 s) plus :data:`GROUND_OFFSET_M`, the velocity left as measured.

**Tilt** (:class:`EkfTilt`).  The firmware's AHRS (``ATT.Roll/Pitch``) reads more roll and pitch
than its simulator's truth (``SIM.Roll/Pitch``): 0.094 and 0.081 deg on the ground, rising to 0.19
and 0.15 deg 8 s after arming, then falling to 0.08 and 0.05 deg by 28 s (:data:`TILT_PROFILE`). The
same within 0.006 deg in three flights (nlsoc/attitude, loc/attitude, nlsoc/rates of the
outdoor-circle), so it is a function of the time since arming, not of the flight.  The simulated IMU
has no noise and no bias (SIM_ACC*/SIM_GYR* are 0), but the AHRS reads 0.019/0.016 deg/s of roll/pitch
rate at rest (:data:`RATE_OFFSET_RAD_S`) and the error grows at about that rate after arming: likely
EKF3's gyro bias estimate, integrated until its velocity innovations stop it; not derived further.  ArduCopter
holds its *estimated* attitude at the target, so the true vehicle flies tilted by minus the error.
Emulated as an earth-frame rotation of the true attitude in what the inner loop and ATTITUDE read.

**Horizontal position and velocity** (:class:`EkfHorizontal`).  The tilted attitude rotates the
hover specific force into a false horizontal acceleration (``N: -g e_E``, ``E: +g e_N`` for the
earth-frame tilt ``e``), which the velocity integrates until the GPS corrects it, and the velocity
error moves the position.  Fitted on the same three dataflash logs (``XKF1.PN/PE/VN/VE`` against
``SIM2``) from the liftoff on: ``de_v/dt = a_false - k_v e_v``, ``de_p/dt = e_v - k_p e_p`` with k_v
1.32 1/s and k_p 1.21 1/s, and the position a first-order lag of 0.047 s behind the truth (the
velocity not lagged); 4.4-6.7 mm RMS of the position error left unexplained against 9-20 mm
measured (10 mm without the lag).  On the ground, armed or not, the firmware's position stays within
a few millimetres of the truth while its velocity reads ``a_false / k_g`` off (k_g 2.7 1/s): so the
emulation holds the position error at 0 until the vehicle first leaves the ground.  Until 5 December
(second session) the model ran from arming (k_v 1.42, k_p 0.87, no lag): the emulated estimate then
drifted 1-1.5 cm on the ground before the mission, where the firmware's stays, and nlsoc/attitude's
RMS and J_e were 0.78 of the firmware's.
"""

from __future__ import annotations

import itertools
import math

from quadrotor.frames import quat_multiply, quaternion_to_euler
from sitl.copter.sensors import ImuReading, NavReading

__all__ = ["EkfHeight", "EkfHorizontal", "EkfTilt", "GROUND_OFFSET_M", "HEIGHT_LAG_S", "RATE_OFFSET_RAD_S",
           "TILT_PROFILE"]

HEIGHT_LAG_S = 0.035
GROUND_OFFSET_M = 0.006  # the estimate's down position minus the truth's [m] (+ = estimate lower)


class EkfHeight:
    """First-order lag of the down position, with the firmware's ground offset.

    Parameters
    ----------
    d0_m : float
        True down position at boot [m].
    lag_s : float
        Time constant [s]; 0 = no lag.
    offset_m : float
        Added to the down position [m].
    """

    def __init__(self, d0_m: float, lag_s: float = HEIGHT_LAG_S, offset_m: float = GROUND_OFFSET_M) -> None:
        if not (math.isfinite(lag_s) and lag_s >= 0.0 and math.isfinite(offset_m)):
            raise ValueError(f"lag_s must be >= 0 and offset_m finite, got {lag_s!r}, {offset_m!r}")
        self.lag_s = lag_s
        self.offset_m = offset_m
        self._d = d0_m

    def apply(self, nav: NavReading, true_d_m: float, dt_s: float) -> NavReading:
        """``nav`` (measured at the true down position ``true_d_m``) with its down position late and offset.

        The lag is advanced by ``dt_s`` [s]; ``nav.d - true_d_m`` (the sensor noise) is kept.
        """
        if self.lag_s > 0.0:
            self._d += (true_d_m - self._d) * (1.0 - math.exp(-dt_s / self.lag_s))
        else:
            self._d = true_d_m
        return nav._replace(d=self._d + self.offset_m + (nav.d - true_d_m))


#: The firmware's AHRS tilt error, (time since arming [s], roll, pitch [deg]): reported minus true Euler
#: angles, 2 s means of three flights at the firmware's heading of about -4.8 deg; the first row also
#: before arming, the last one after.
TILT_PROFILE: tuple[tuple[float, float, float], ...] = (
    (1.0, 0.094, 0.081), (3.0, 0.122, 0.108), (5.0, 0.158, 0.129), (7.0, 0.183, 0.146), (9.0, 0.189, 0.150),
    (11.0, 0.178, 0.141), (13.0, 0.165, 0.115), (15.0, 0.157, 0.106), (17.0, 0.144, 0.112),
    (19.0, 0.126, 0.106), (21.0, 0.101, 0.098), (23.0, 0.085, 0.090), (25.0, 0.078, 0.074),
    (27.0, 0.086, 0.056), (29.0, 0.082, 0.053))
TILT_PROFILE_YAW_DEG = -4.8  # the heading the profile's Euler angles were measured at
#: What the firmware's AHRS reads as body rates (ATTITUDE rollspeed/pitchspeed/yawspeed) of a vehicle at
#: rest on the ground, armed, before the mission [rad/s]: 0.019, 0.016, 0.21 deg/s (its gyro bias estimate is
#: off; with the simulator's own attitude, AHRS_EKF_TYPE 10, 0.019 deg/s on every axis).  Its rate loop
#: holds these readings at the demand, so the true vehicle turns the other way until the angle loop stops it.
RATE_OFFSET_RAD_S = (math.radians(0.019), math.radians(0.016), math.radians(0.21))


class EkfTilt:
    """The AHRS's tilt error: a small earth-frame rotation of the true attitude.

    Parameters
    ----------
    profile : sequence of (float, float, float)
        (time since arming [s], roll error, pitch error [deg]) rows, time increasing; linear between
        rows, held outside them.
    yaw_deg : float
        Heading [deg] at which the profile's Euler-angle errors were measured (they are turned into
        earth-frame north/east tilts there).
    """

    def __init__(self, profile=TILT_PROFILE, yaw_deg: float = TILT_PROFILE_YAW_DEG) -> None:
        rows = [tuple(float(v) for v in r) for r in profile]
        if not rows or any(len(r) != 3 or not all(map(math.isfinite, r)) for r in rows) or \
                any(b[0] <= a[0] for a, b in itertools.pairwise(rows)):
            raise ValueError("profile must be finite (time, roll, pitch) rows with increasing times")
        c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
        self._rows = [(t, math.radians(c * r - s * p), math.radians(s * r + c * p)) for t, r, p in rows]

    def error_rad(self, since_arm_s: float | None) -> tuple[float, float]:
        """Earth-frame tilt error (about north, about east) [rad] ``since_arm_s`` after arming (None: not yet)."""
        rows = self._rows
        if since_arm_s is None or since_arm_s <= rows[0][0]:
            return rows[0][1], rows[0][2]
        for (t0, n0, e0), (t1, n1, e1) in itertools.pairwise(rows):
            if since_arm_s <= t1:
                w = (since_arm_s - t0) / (t1 - t0)
                return n0 + w * (n1 - n0), e0 + w * (e1 - e0)
        return rows[-1][1], rows[-1][2]

    @staticmethod
    def apply(imu: ImuReading, error_rad: tuple[float, float],
              rate_offset_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> ImuReading:
        """``imu`` with its attitude rotated by the earth-frame tilt ``error_rad`` (north, east) [rad] and
        ``rate_offset_rad_s`` (FRD) added to its body rates."""
        # (1, e_N/2, e_E/2, 0) * q: the small rotation in the earth frame, after the body's
        w, x, y, z = quat_multiply((1.0, 0.5 * error_rad[0], 0.5 * error_rad[1], 0.0), (imu.qw, imu.qx, imu.qy, imu.qz))
        inv = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
        q = (w * inv, x * inv, y * inv, z * inv)
        roll, pitch, yaw = quaternion_to_euler(q)
        op, oq, orr = rate_offset_rad_s
        return imu._replace(roll=roll, pitch=pitch, yaw=yaw, qw=q[0], qx=q[1], qy=q[2], qz=q[3], p=imu.p + op,
                            q=imu.q + oq, r=imu.r + orr)


VELOCITY_GAIN_1_S = 1.32  # k_v: how fast the GPS pulls the velocity error back, in flight [1/s]
POSITION_GAIN_1_S = 1.21  # k_p: ... and the position error [1/s]
GROUND_VELOCITY_GAIN_1_S = 2.7  # k_g: on the ground before the liftoff the velocity error is a / k_g [1/s]
POSITION_LAG_S = 0.047  # the horizontal position estimate's lag behind the truth (first order) [s]


class EkfHorizontal:
    """The horizontal position/velocity error a tilted attitude gives the EKF (NED), and its position's lag.

    Parameters
    ----------
    gravity_m_s2 : float
    velocity_gain_1_s, position_gain_1_s : float
        ``k_v``, ``k_p`` (>= 0) of ``de_v/dt = a_false - k_v e_v``, ``de_p/dt = e_v - k_p e_p`` in flight.
    ground_velocity_gain_1_s : float
        ``k_g`` (> 0): before the first liftoff ``e_v = a_false / k_g`` and ``e_p = 0``.
    position_lag_s : float
        Time constant (>= 0) of the first-order lag of the north/east position behind the sensed one.
    """

    def __init__(self, gravity_m_s2: float, velocity_gain_1_s: float = VELOCITY_GAIN_1_S,
                 position_gain_1_s: float = POSITION_GAIN_1_S,
                 ground_velocity_gain_1_s: float = GROUND_VELOCITY_GAIN_1_S,
                 position_lag_s: float = POSITION_LAG_S) -> None:
        values = (gravity_m_s2, velocity_gain_1_s, position_gain_1_s, ground_velocity_gain_1_s, position_lag_s)
        if not all(math.isfinite(v) and v >= 0.0 for v in values) or not ground_velocity_gain_1_s > 0.0:
            raise ValueError("gravity, gains and lag must be finite and >= 0 (the ground gain > 0)")
        self.g = gravity_m_s2
        self.kv, self.kp, self.kg = velocity_gain_1_s, position_gain_1_s, ground_velocity_gain_1_s
        self.position_lag_s = position_lag_s
        self.velocity_error = [0.0, 0.0]  # N, E [m/s]
        self.position_error = [0.0, 0.0]  # N, E [m]
        self._lagged: list[float] | None = None  # the lagged sensed north/east position [m]

    def advance(self, tilt_rad: tuple[float, float], dt_s: float, lifted_off: bool = True) -> None:
        """Advance the errors by ``dt_s`` [s] under the earth-frame tilt error (north, east) [rad].

        Until the vehicle first leaves the ground (``lifted_off`` False) the velocity error sits at
        ``a / k_g`` and the position error at 0: the firmware's velocity reading is 4-10 mm/s off while
        it waits on the ground, armed or not, but its position stays within a few millimetres of the
        truth until the liftoff (``benchmarks/ekf_dataflash_fit.py``: the fit starts there).
        """
        for i, a in enumerate(self._false_acceleration(tilt_rad)):
            if not lifted_off:
                self.velocity_error[i] = a / self.kg
                self.position_error[i] = 0.0
                continue
            ev = self.velocity_error[i]
            self.position_error[i] += dt_s * (ev - self.kp * self.position_error[i])
            self.velocity_error[i] = ev + dt_s * (a - self.kv * ev)

    def _false_acceleration(self, tilt_rad: tuple[float, float]) -> tuple[float, float]:
        return (-self.g * tilt_rad[1], self.g * tilt_rad[0])

    def apply(self, nav: NavReading, dt_s: float) -> NavReading:
        """``nav`` with its north/east position lagged (advanced by ``dt_s`` [s]) and the errors added to its
        north/east position and velocity."""
        if self._lagged is None or self.position_lag_s == 0.0:
            self._lagged = [nav.n, nav.e]
        else:
            w = 1.0 - math.exp(-dt_s / self.position_lag_s)
            self._lagged = [x + w * (z - x) for x, z in zip(self._lagged, (nav.n, nav.e))]
        (pn, pe), (vn, ve) = self.position_error, self.velocity_error
        return nav._replace(n=self._lagged[0] + pn, e=self._lagged[1] + pe, vn=nav.vn + vn, ve=nav.ve + ve)
