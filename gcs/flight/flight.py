"""One flight, composed: a vehicle session, a controller, the envelope and the mission loop.

``Flight(config, "nlsoc", MavlinkSession(config, link)).preflight()`` then ``.fly()`` and
``.restore()``; :func:`gcs.api.fly` builds the session (and the child simulator, the link,
the log) from a :class:`gcs.api.FlightSpec` and calls these in order, landing and restoring
whatever happens.
"""

from __future__ import annotations

from typing import Any
from collections.abc import Callable

from gcs.config import Config
from gcs.control import make_controller
from gcs.flight.context import FlightContext, Interrupts
from gcs.flight.loop import MissionLoop
from gcs.log.recorder import FlightRecorder
from gcs.flight.result import FlightResult
from gcs.flight.safety import SafetyEnvelope, envelope_for
from gcs.flight.session import VehicleSession
from quadrotor.clock import Clock

__all__ = ["Flight"]


class Flight:
    """``controller`` flying ``config``'s mission on ``session``.

    Parameters
    ----------
    config : Config
    controller : str
        A name of :data:`gcs.control.CONTROLLERS`.
    session : VehicleSession
    clock : Clock or None
        Real time (e.g. :class:`~quadrotor.clock.MonotonicClock`); None = lockstep on the
        vehicle's own clock (the session provides it).
    recorder : FlightRecorder or None
        The flight log (None: none).
    console : callable (str) or None
    interrupts : Interrupts or None
    live_period_s : float
    envelope : SafetyEnvelope or None
        Default: the config's (:func:`~gcs.flight.safety.envelope_for`).
    """

    def __init__(self, config: Config, controller: str, session: VehicleSession, *, clock: Clock | None = None,
                 recorder: FlightRecorder | None = None, console: Callable[[str], None] | None = None,
                 interrupts: Interrupts | None = None, live_period_s: float = 0.5,
                 envelope: SafetyEnvelope | None = None) -> None:
        self.config = config
        self.session = session
        self.ctx = FlightContext(config, clock, recorder or FlightRecorder(None), console or (lambda s: None),
                                 interrupts or Interrupts())
        session.attach(self.ctx)
        self.controller = make_controller(controller, config)
        self.envelope = envelope or envelope_for(config)
        self.loop = MissionLoop(self.ctx, controller, self.controller, session, envelope=self.envelope,
                                live_period_s=live_period_s)

    @property
    def events(self) -> list[dict[str, Any]]:
        return self.ctx.events

    @property
    def stats(self):
        return self.loop.stats

    def event(self, kind: str, text: str, **fields: Any) -> None:
        self.ctx.event(kind, text, **fields)

    def preflight(self) -> None:
        """Everything before arming, then arm (raises PreflightRefused or LinkError)."""
        self.session.preflight()

    def fly(self) -> FlightResult:
        """The mission and the landing (preflight must have passed); the summary."""
        return self.loop.run()

    def restore(self) -> None:
        """Put back the parameters changed for the flight (once the vehicle is disarmed)."""
        self.session.restore()

    def emergency_land(self) -> None:
        """Land from wherever the flight stands (an exception escaped it): the session's usual landing."""
        self.session.finish("internal_error")
