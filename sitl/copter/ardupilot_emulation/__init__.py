"""ArduCopter's firmware, emulated in the built-in SITL (``sitl --emulate arducopter``).

The aim is that a flight of the built-in SITL predicts the same flight on ArduPilot's own
ArduCopter SITL (``gcs fly --sitl arducopter``): same inner loop, motor model, arming delay and
spool-up, EKF start-up, GUID_TIMEOUT behaviour, HEARTBEAT and AUTOPILOT_VERSION, on the firmware
SITL's airframe.  ``benchmarks/bench_fidelity.py`` measures how well it does (docs/FIDELITY.md).

=================  ==============================================================================
``shaping``        AP_Math's square-root controller and jerk-limited command model
``filters``        the gyro's two-pole low-pass and AC_PID
``attitude``       AC_AttitudeControl(_Multi): input_quaternion, input_rate_bf, angle and rate loops
``motors``         AP_MotorsMulticopter/Matrix: spool states, arming delay, mixer, thrust curve
``ekf``            the EKF's estimate: height 0.035 s late and 6 mm low, attitude tilted ~0.1-0.2 deg,
                   horizontal position/velocity pulled off by that tilt
``ground``         ArduPilot SITL's sticky ground contact and smoothed sensors (the liftoff)
``status``         EKF readiness, PreArm texts, HEARTBEAT base_mode/system_status, AUTOPILOT_VERSION
``vehicle``        ArduPilot SITL's X quad and the firmware SITL's parameter defaults
``autopilot``      :class:`ArduCopterAutopilot`, the built-in autopilot with these pieces
=================  ==============================================================================
"""

from __future__ import annotations

__all__ = ["EMULATIONS"]

#: Names ``sitl --emulate`` takes.
EMULATIONS = ("arducopter",)
