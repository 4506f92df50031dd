"""The vehicle's parameters as a flight uses them: read, set for the flight, restored after it.

A value is trusted only once the vehicle reports it (the PARAM_VALUE echo of
:meth:`gcs.link.mavlink.MavlinkLink.param_set`); every change is remembered with the
value it replaced and put back by :meth:`VehicleParams.restore` once the vehicle is
disarmed, whatever ended the flight.
"""

from __future__ import annotations

import math
from typing import Callable

from gcs.errors import PreflightRefused
from gcs.link.mavlink import LinkError

__all__ = ["VehicleParams"]


class VehicleParams:
    """Parameters of one vehicle over ``link``.

    Parameters
    ----------
    link : MavlinkLink
    on_message : callable (msg)
        Every message received while waiting (the telemetry goes on).
    event : callable (kind, text)
    check_interrupt : callable ()
        Raises PreflightRefused once Ctrl-C was pressed.
    """

    def __init__(self, link, on_message: Callable, event: Callable[[str, str], None],
                 check_interrupt: Callable[[], None]) -> None:
        self.link = link
        self.on_message = on_message
        self.event = event
        self.check_interrupt = check_interrupt
        #: name -> the value it had before the flight changed it.
        self.changed: dict[str, float] = {}

    def get(self, name: str, default: float | None) -> float:
        """A parameter of the vehicle; ``default=None`` makes it required (refuse without it)."""
        self.check_interrupt()
        try:
            value = self.link.param_get(name, timeout_s=1.0, retries=1, on_message=self.on_message)
        except LinkError:
            if default is None:
                raise PreflightRefused(f"parameter {name} not readable; it is needed to fly") from None
            self.event("warning", f"parameter {name} not readable; assuming {default:g}")
            return default
        if not math.isfinite(value):
            raise PreflightRefused(f"parameter {name} = {value} is not a finite number")
        return value

    def set(self, name: str, value: float, old: float) -> float:
        """Set ``name`` for the flight (``old`` is put back by :meth:`restore`); the value the vehicle holds."""
        new = self.link.param_set(name, value, on_message=self.on_message)
        if new == value:
            self.changed.setdefault(name, old)
        return new

    def said(self, text: str) -> None:
        self.event("param", text)

    def restore(self, armed: Callable[[], bool]) -> None:
        """Put back every parameter changed for the flight (not while the vehicle is still armed)."""
        for name, value in list(self.changed.items()):
            if armed():
                self.event("warning", f"vehicle still armed: {name} left at its flight value")
                continue
            try:
                self.link.param_set(name, value, timeout_s=1.0, retries=1, on_message=self.on_message)
                self.event("param", f"{name} restored to {value:g}")
                del self.changed[name]
            except LinkError as exc:
                self.event("warning", f"{name} not restored: {exc}")
