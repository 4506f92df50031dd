"""The vehicle session: the one small interface between the mission loop and a vehicle.

Three implementations: a MAVLink autopilot (:class:`gcs.vehicles.mavlink.MavlinkSession`, whose
firmware conventions are an autopilot profile), the 4-DOF rig (:class:`gcs.vehicles.rig.RigSession`)
and the in-process plant of ``gcs sim`` (:class:`gcs.vehicles.plant.PlantSession`).  The loop
(:class:`gcs.flight.loop.MissionLoop`) calls, each tick: :meth:`pump`, :meth:`estimate`,
:meth:`disturbance_m_s2`, the checks (:meth:`fresh`, :meth:`health`, :meth:`control_lost`),
then :meth:`send` (and for the log :meth:`observer_log`); once a second :meth:`housekeeping`; after
the mission :meth:`finish`.
"""

from __future__ import annotations

from typing import Protocol
from collections.abc import Sequence

from gcs.flight.context import FlightContext
from quadrotor.state import Command, State

__all__ = ["VehicleSession"]


class VehicleSession(Protocol):
    """A vehicle the mission loop flies."""

    #: What the vehicle leaves when it stops taking our setpoints (for the failsafe message).
    control_name: str
    #: The vehicle lands itself once told to (MAVLink LAND); False: the loop flies the descent
    #: to the ground and :meth:`finish` disarms.
    lands_itself: bool
    #: False for a vehicle that cannot fail (the in-process plant): the loop skips :meth:`fault`,
    #: :meth:`fresh`, :meth:`health` and :meth:`control_lost` (default True when absent).
    supervised: bool

    def attach(self, ctx: FlightContext) -> None:
        """Take the flight's context (clock, events, log, interrupts); in lockstep set ``ctx.clock``."""

    def preflight(self) -> None:
        """Everything before arming, then arm; raises PreflightRefused or LinkError."""

    def pump(self) -> int:
        """Take the telemetry waiting now (never blocks); the number of messages."""

    def estimate(self, dt_s: float, last_command: Command | None) -> State:
        """The state estimate for this tick, the last command applied for ``dt_s`` (0: the current
        estimate, nothing predicted or measured)."""

    def truth(self) -> State | None:
        """The true state (a simulation's), or None for a real vehicle."""

    def disturbance_m_s2(self) -> tuple[float, float, float]:
        """The estimated steady disturbance acceleration (x, y, z up; paper frame) [m/s^2] the
        controller compensates; zeros where none is estimated."""

    def observer_log(self) -> tuple[float, float, float, float, float, float] | None:
        """The disturbance observer's estimate for the log (:data:`gcs.log.topics.DISTURBANCE_FIELDS`:
        the acceleration the laws are given, then the velocity-reading offset), None without an observer."""

    def fresh(self, now_ns: int, stale_s: float) -> bool:
        """Telemetry newer than ``stale_s``."""

    def fault(self) -> tuple[str, str] | None:
        """A failure that ends the flight at once ``(exit_reason, text)``: the vehicle's process died
        (``link_error``), the output guard blocked a command (``unsafe_command``; already said: text "")."""

    def health(self, now_ns: int) -> tuple[str, str] | None:
        """A failsafe ``(exit_reason, text)`` once the telemetry is fresh: streams too slow to control."""

    def control_lost(self) -> str | None:
        """Why the vehicle is no longer ours to steer (disarmed, another mode, cut off), or None."""

    def mission_origin(self, state: State) -> tuple[float, float, float]:
        """Where the mission's (0, 0, 0) is."""

    def send(self, state: State, command: Command) -> None:
        """The limited command to the vehicle."""

    def housekeeping(self) -> None:
        """Once a second during the mission: heartbeats, round-trip probes."""

    def landed(self) -> bool:
        """On the ground (vehicles that do not land themselves)."""

    def finish(self, reason: str) -> None:
        """After the loop: land and disarm (or wait for the vehicle to), as ``reason`` asks."""

    def abandon(self) -> None:
        """The last resort when :meth:`finish` raised: whatever makes the vehicle's own failsafe land it."""

    def restore(self) -> None:
        """Put back what was changed on the vehicle for the flight (once it is disarmed)."""

    def disarm_on_ground(self) -> None:
        """After a preflight refusal that came after arming: disarm."""

    def summary(self) -> dict:
        """Link and session counters for the flight summary."""

    def loop_summary(self) -> dict:
        """Extra ``loop`` figures (lockstep timeouts)."""


def finite(values: Sequence[float]) -> bool:
    """Every value finite (NaN and infinities propagate through the sum)."""
    s = sum(values)
    return s - s == 0.0
