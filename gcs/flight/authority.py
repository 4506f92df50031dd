"""When a fault is past the vehicle's authority: a flight that cannot be flown well is landed, not flown badly.

Two signs, each in the setpoints we send (so they hold whatever the autopilot and the airframe):

* **thrust saturated**: the thrust field at its top (normalised 1.0) for :data:`THRUST_SATURATED_S`
  in the air: the vehicle cannot carry itself and manoeuvre (a motor far too weak, a payload too heavy,
  a battery sagging);
* **rate shortfall pinned**: the attitude output's rate-error integral
  (:class:`~gcs.vehicles.output.RateErrorIntegral`) at its bound on an axis for
  :data:`INTEGRAL_PINNED_S`: the autopilot's rate loop keeps falling short of the demand by more than the
  output can make up (a motor too weak for the yaw or roll authority left; gains far too low).

* **not following** (:class:`TrackingWatch`, any session): the estimate farther than
  :data:`TRACKING_LOST_M` from the reference for :data:`TRACKING_LOST_S` (``[flight] tracking_lost_m``,
  ``tracking_lost_s``; the missions are ramps and
  circles, never steps: a nominal flight stays within 0.1 m): a vehicle that did not leave the ground, or
  that the controller cannot hold.

Short saturations (a take-off, a gust) are normal; only sustained ones count.  The first reported
ends the flight as ``out_of_authority`` (exit 13): it lands.
"""

from __future__ import annotations

import math

from gcs.config.sections import FlightConfig

__all__ = ["AuthorityWatch", "TrackingWatch", "THRUST_SATURATED_S", "INTEGRAL_PINNED_S", "PINNED_FRACTION",
           "TRACKING_LOST_M", "TRACKING_LOST_S"]

#: How long the thrust field may stay at its top in the air [s].
THRUST_SATURATED_S = 1.0
#: How long the rate-error integral may stay at its bound on one axis [s].
INTEGRAL_PINNED_S = 2.0
#: Distance from the reference that counts as not following [m], and for how long [s]: the defaults
#: of ``[flight] tracking_lost_m`` / ``tracking_lost_s``.
TRACKING_LOST_M, TRACKING_LOST_S = FlightConfig.tracking_lost_m, FlightConfig.tracking_lost_s
#: Fraction of the bound that counts as pinned.
PINNED_FRACTION = 0.98
_AXES = ("roll", "pitch", "yaw")


class AuthorityWatch:
    """Counts how long the setpoints sat at their limits (one :meth:`update` per control period).

    Parameters
    ----------
    ts_s : float
        The control period [s].
    thrust_saturated_s, integral_pinned_s : float
        How long each may last before :meth:`failure` says so [s].
    """

    def __init__(self, ts_s: float, thrust_saturated_s: float = THRUST_SATURATED_S,
                 integral_pinned_s: float = INTEGRAL_PINNED_S) -> None:
        if not (ts_s > 0.0 and thrust_saturated_s > 0.0 and integral_pinned_s > 0.0):
            raise ValueError(f"need positive periods, got {ts_s!r}, {thrust_saturated_s!r}, {integral_pinned_s!r}")
        self.ts_s = ts_s
        self._thrust_n = max(1, round(thrust_saturated_s / ts_s))
        self._pinned_n = max(1, round(integral_pinned_s / ts_s))
        self.saturated_ticks = 0
        self.pinned_ticks = [0, 0, 0]
        self._failure: str | None = None

    def update(self, fields: dict, airborne: bool, delta_rad=None, max_rad=None) -> None:
        """One period: the setpoint's ``fields`` (:meth:`OutputAdapter.fields`), and the rate-error
        integral ``delta_rad`` with its bounds ``max_rad`` (None: no integral)."""
        if self._failure is not None:
            return
        if not airborne:
            self.saturated_ticks = 0
            self.pinned_ticks = [0, 0, 0]
            return
        thrust = fields["controls"][4] if fields["message"] == "SET_ACTUATOR_CONTROL_TARGET" else fields["thrust"]
        self.saturated_ticks = self.saturated_ticks + 1 if thrust >= 1.0 - 1e-9 else 0
        if self.saturated_ticks >= self._thrust_n:
            self._failure = (f"thrust at its top for {self.saturated_ticks * self.ts_s:.1f} s: the vehicle cannot "
                             "carry itself and manoeuvre (a weak motor, a payload?)")
            return
        if delta_rad is None:
            return
        for i in range(3):
            lim = max_rad[i]
            pinned = lim > 0.0 and abs(delta_rad[i]) >= PINNED_FRACTION * lim
            self.pinned_ticks[i] = self.pinned_ticks[i] + 1 if pinned else 0
            if self.pinned_ticks[i] >= self._pinned_n:
                self._failure = (f"the autopilot's {_AXES[i]} rate fell short of the demand for "
                                 f"{self.pinned_ticks[i] * self.ts_s:.1f} s with the attitude output's correction at "
                                 f"its bound ({lim:g} rad): past the vehicle's authority (a weak motor?)")
                return

    def failure(self) -> str | None:
        """What is past the vehicle's authority, once it has lasted (None: nothing)."""
        return self._failure


class TrackingWatch:
    """Says when the vehicle has not followed the reference (one :meth:`update` per control period).

    Parameters
    ----------
    ts_s : float
        The control period [s].
    lost_m, lost_s : float
        Farther than ``lost_m`` [m] for ``lost_s`` [s] is not following; ``lost_m = 0``: never reported.
    """

    def __init__(self, ts_s: float, lost_m: float = TRACKING_LOST_M, lost_s: float = TRACKING_LOST_S) -> None:
        if not (ts_s > 0.0 and lost_m >= 0.0 and lost_s > 0.0):
            raise ValueError(f"need positive values, got {ts_s!r}, {lost_m!r}, {lost_s!r}")
        self.ts_s, self.lost_m = ts_s, lost_m
        self._n = max(1, round(lost_s / ts_s))
        self.ticks = 0

    def update(self, state, ref) -> str | None:
        """One period with the estimate ``state`` and the reference ``ref`` (x, y, z [m]); the failure or None."""
        if self.lost_m == 0.0:
            return None
        e = math.sqrt((state.x - ref.x) ** 2 + (state.y - ref.y) ** 2 + (state.z - ref.z) ** 2)
        self.ticks = self.ticks + 1 if e > self.lost_m else 0
        if self.ticks < self._n:
            return None
        return (f"{e:.2f} m from the reference, farther than {self.lost_m:g} m for {self.ticks * self.ts_s:.1f} s: "
                "the vehicle does not follow (past its authority?)")
