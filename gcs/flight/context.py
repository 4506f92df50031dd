"""What every part of one flight shares: the config, the clock, the events, the log, the interrupts.

A :class:`FlightContext` is made once per flight and handed to the vehicle session and
the mission loop (composition: neither knows the other's class).  :meth:`FlightContext.event`
is the one way anything is said about the flight: it goes to the summary's event list, to
the flight log and to the pilot's console.
"""

from __future__ import annotations

import signal
import threading
from dataclasses import dataclass, field
from typing import Any
from collections.abc import Callable

from gcs.config import Config
from quadrotor.clock import Clock

__all__ = ["FlightContext", "Interrupts"]


class Interrupts:
    """SIGINT/SIGTERM -> a count (first: controlled landing, second: immediate landing)."""

    def __init__(self) -> None:
        self.count = 0
        self._old: dict = {}

    def __enter__(self) -> Interrupts:
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum, frame) -> None:
        self.count += 1

    def __exit__(self, *exc) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)


@dataclass
class FlightContext:
    """The shared parts of one flight.

    Attributes
    ----------
    config : Config
    clock : Clock
        The loop's clock: real time, or the vehicle's own time in lockstep (set by the
        session when it is None at construction).
    recorder : FlightRecorder
        The flight log (``FlightRecorder(None)`` records nothing).
    console : callable (str)
        Where the pilot's lines go.
    interrupts : Interrupts
    events : list of dict
        Everything said about the flight, for the summary.
    """

    config: Config
    clock: Clock | None
    recorder: Any
    console: Callable[[str], None] = field(default=lambda s: None)
    interrupts: Interrupts = field(default_factory=Interrupts)
    events: list[dict] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.recorder.warn is None:
            self.recorder.warn = lambda text: self.event("warning", text)

    @property
    def lockstep(self) -> bool:
        """The clock is the vehicle's (lockstep), not the wall's."""
        return getattr(self.clock, "lockstep", False)

    def now_ns(self) -> int:
        return self.clock.now_ns() if self.clock is not None else 0

    def event(self, kind: str, text: str, **fields: Any) -> None:
        """Record (summary and log) and print an event."""
        t = self.now_ns()
        self.events.append({"t_ns": t, "kind": kind, "text": text, **fields})
        self.recorder.event(t, kind, text, **fields)
        self.console(f"[{kind}] {text}")
