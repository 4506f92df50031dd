"""Mission references: timed phases composed into a reference ``State`` at any time.

Phases (``[[mission.phases]]`` in a config), each starting where the previous
one's reference ends:

* ``takeoff``: ramp z linearly to ``z_m`` over ``duration_s`` (constant climb rate);
* ``hold``: hold the position;
* ``circle``: circle of ``radius_m`` in x-y at the held altitude, one lap per
  ``period_s``, turning from +x (north) towards +y (east) — clockwise seen from
  above, as the frame is north-east-up — centred on ``center_m`` (default:
  ``radius_m`` behind the start point along -x, so the circle starts where the
  vehicle is);
* ``land``: ramp z linearly to 0 over ``duration_s``.

After the last phase the final reference is held.  Reference velocities are
the derivatives of the reference positions; ``zero_velocity=True`` gives the
paper's literal circle setting with all velocity references zero (erratum 12).
Attitude references are 0 (yaw held at 0).  :meth:`Mission.acceleration` is the
reference's acceleration (centripetal on a circle, zero on the ramps and holds);
the flight feeds it forward (``[experiment] acceleration_reference``) as the drift
of the error dynamics: ``e'' = f(x, u) + d - a_ref``, so it enters the laws exactly
as a disturbance acceleration ``-a_ref`` does and the tilt a law holds is the one
that makes the vehicle turn with the reference (:func:`gcs.model.disturbance_tilt`).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from collections.abc import Sequence

from gcs.config import PhaseConfig
from quadrotor.state import State

__all__ = ["Mission", "Segment"]


@dataclass(frozen=True)
class Segment:
    """A phase placed on the time line, with its start reference position [m]."""

    phase: PhaseConfig
    index: int
    t_start_s: float
    t_end_s: float
    start: tuple[float, float, float]
    center: tuple[float, float] | None = None


class Mission:
    """A sequence of phases giving ``reference(t)``."""

    def __init__(self, phases: Sequence[PhaseConfig], *, zero_velocity: bool = False,
                 start: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        if not phases:
            raise ValueError("a mission needs at least one phase")
        self.zero_velocity = zero_velocity
        segments = []
        t = 0.0
        pos = tuple(float(v) for v in start)
        for i, ph in enumerate(phases):
            center = None
            if ph.kind == "circle":
                center = ph.center_m if ph.center_m is not None else (pos[0] - ph.radius_m, pos[1])
            seg = Segment(ph, i, t, t + ph.duration_s, pos, center)  # type: ignore[arg-type]
            segments.append(seg)
            t = seg.t_end_s
            pos = self._position(seg, seg.t_end_s)
        self.segments: tuple[Segment, ...] = tuple(segments)
        self._starts = [s.t_start_s for s in segments]
        self.duration_s = t
        self._final = State(*pos)

    @property
    def setpoint_z_m(self) -> float:
        """The highest altitude set point of the mission (the takeoff target)."""
        return max(s.phase.z_m for s in self.segments if s.phase.kind == "takeoff")

    def segment_at(self, t: float) -> Segment | None:
        """The segment flying at time t (None after the mission)."""
        if t >= self.duration_s:
            return None
        i = max(0, bisect.bisect_right(self._starts, t) - 1)
        return self.segments[i]

    @staticmethod
    def _position(seg: Segment, t: float) -> tuple[float, float, float]:
        ph = seg.phase
        tau = min(max(t - seg.t_start_s, 0.0), ph.duration_s)
        x0, y0, z0 = seg.start
        if ph.kind == "takeoff":
            return (x0, y0, z0 + (ph.z_m - z0) * tau / ph.duration_s)
        if ph.kind == "land":
            return (x0, y0, z0 * (1.0 - tau / ph.duration_s))
        if ph.kind == "circle":
            cx, cy = seg.center  # type: ignore[misc]
            a0 = math.atan2(y0 - cy, x0 - cx)
            a = a0 + 2.0 * math.pi * tau / ph.period_s
            return (cx + ph.radius_m * math.cos(a), cy + ph.radius_m * math.sin(a), z0)
        return (x0, y0, z0)

    def reference(self, t: float) -> State:
        """Reference state at time t [s] (paper frame)."""
        seg = self.segment_at(t)
        if seg is None:
            return self._final
        x, y, z = self._position(seg, t)
        if self.zero_velocity:
            return State(x, y, z)
        ph = seg.phase
        vx = vy = vz = 0.0
        if ph.kind == "takeoff":
            vz = (ph.z_m - seg.start[2]) / ph.duration_s
        elif ph.kind == "land":
            vz = -seg.start[2] / ph.duration_s
        elif ph.kind == "circle":
            w = 2.0 * math.pi / ph.period_s
            cx, cy = seg.center  # type: ignore[misc]
            vx, vy = -w * (y - cy), w * (x - cx)
        return State(x, y, z, vx, vy, vz)

    def acceleration(self, t: float) -> tuple[float, float, float]:
        """The reference's acceleration (x, y, z up) [m/s^2] at time t: centripetal on a circle,
        zero elsewhere (the ramps have constant velocity) and with zero velocity references."""
        seg = self.segment_at(t)
        if seg is None or self.zero_velocity or seg.phase.kind != "circle":
            return (0.0, 0.0, 0.0)
        x, y, _ = self._position(seg, t)
        cx, cy = seg.center  # type: ignore[misc]
        w2 = (2.0 * math.pi / seg.phase.period_s) ** 2
        return (-w2 * (x - cx), -w2 * (y - cy), 0.0)

    def hold_window(self, window_s: float = 1.0) -> tuple[float, float]:
        """Time interval of the last ``window_s`` of the last hold or circle phase (the steady state).

        Falls back to the last ``window_s`` of the mission when there is none.
        """
        holds = [s for s in self.segments if s.phase.kind in ("hold", "circle")]
        end = holds[-1].t_end_s if holds else self.duration_s
        start = holds[-1].t_start_s if holds else 0.0
        return (max(start, end - window_s), end)

    def flight_window(self) -> tuple[float, float]:
        """From the start to the end of the last takeoff/hold/circle phase (excludes landing)."""
        ends = [s.t_end_s for s in self.segments if s.phase.kind != "land"]
        return (0.0, max(ends) if ends else self.duration_s)
