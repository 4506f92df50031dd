"""The navigation glue of :class:`~sitl.copter.autopilot.Autopilot` (a part of it): when the navigator
(:mod:`sitl.copter.navigation`) flies, and its demand flown on the inner loop."""

from __future__ import annotations

from sitl.copter.modes import Mode
from sitl.copter.navigation import NAV_MODES
from sitl.copter.sensors import ImuReading, NavReading

__all__ = ["NavigationMixin"]


class NavigationMixin:
    """Navigation methods of the autopilot (which provides the attributes used)."""

    def _nav_enter(self, now_ns: int) -> None:
        imu, nav = self._last_imu, self._last_nav
        if self.navigator is not None and imu is not None and nav is not None:
            self.navigator.enter(self.mode, nav, imu.yaw, self.land_complete, now_ns)

    def position_control(self, now_ns: int) -> None:
        """GUIDED from now on flies the navigator's targets (an attitude target would take over again)."""
        self.target = None
        self._timer_ns = now_ns

    def _nav_refusal(self, mode: Mode) -> str:
        """Why a change to ``mode`` is refused ("" if it is not)."""
        if self.navigator is None:
            return f"Mode change to {mode.name} failed: unsupported" if mode in NAV_MODES else ""
        return self.navigator.refusal(mode, self.land_complete)

    def _nav_descending(self) -> bool:
        """The land detector's "descent demanded" while the navigator flies."""
        last = self.navigator.last
        return last is None or last.land or last.climb_m_s <= 0.0

    def _nav_flies(self) -> bool:
        """Whether the navigator flies now: its modes, and GUIDED without an attitude target."""
        return self.navigator is not None and (self.mode in NAV_MODES or
                                               (self.mode == Mode.GUIDED and self.target is None))

    def _run_nav(self, now_ns: int, dt: float, imu: ImuReading, nav: NavReading) -> tuple[float, float, float, float]:
        d = self.navigator.update(now_ns, dt, nav, imu.yaw)  # type: ignore[union-attr]
        if self.land_complete:
            if d.land and self.mode != Mode.GUIDED:
                self.disarm(now_ns, force=True, why="landed")
                return (0.0, 0.0, 0.0, 0.0)
            if d.land or not self.navigator.wants_takeoff(nav):  # type: ignore[union-attr]
                return self._ground_idle()
            self.land_complete = False
            self._landed_since_ns = None
            self._reset_loops()
        return self._fly(d.q, (0.0, 0.0, 0.0), False, self._climb_throttle(d.climb_m_s, dt, nav), True, dt, imu)
