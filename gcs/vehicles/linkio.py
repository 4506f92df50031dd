"""The link I/O every linked vehicle session shares: draining, a failure said once, guarded sends.

A message the output guard (:mod:`gcs.link.guard`) blocks never reaches the wire: the
session's safe command (level, below hover thrust) goes instead and :attr:`LinkIO.fault`
asks the loop to fail safe (exit ``unsafe_command``).  A link that fails is said once; the
failsafe then acts on the stale telemetry.
"""

from __future__ import annotations

from typing import Any
from collections.abc import Callable

from gcs.link.guard import UnsafeCommand
from gcs.link.mavlink import LinkError

__all__ = ["LinkIO"]


class LinkIO:
    """I/O on ``link`` (a MAVLink or rig link) for one session.

    Parameters
    ----------
    link : MavlinkLink or RigLink
    handle : callable (msg)
        Takes every message received.
    event : callable (kind, text)
    safe_command : callable () -> message
        What goes instead of a blocked command.
    on_batch : callable (list) or None
        Sees each drained batch before ``handle`` takes its messages.
    """

    def __init__(self, link: Any, handle: Callable[[Any], None], event: Callable[[str, str], None],
                 safe_command: Callable[[], Any], on_batch: Callable[[list], None] | None = None) -> None:
        self.link = link
        self.handle = handle
        self.on_batch = on_batch
        self.event = event
        self.safe_command = safe_command
        #: ``("unsafe_command", "")`` once the guard blocked a command (the event already said why).
        self.fault: tuple[str, str] | None = None
        self.link_down = False

    def pump(self) -> int:
        """Drain the link into ``handle`` (never blocks); the number of messages."""
        try:
            msgs = self.link.drain()
        except LinkError as exc:
            self.failed(exc)
            return 0
        if self.on_batch is not None and msgs:
            self.on_batch(msgs)
        for m in msgs:
            self.handle(m)
        return len(msgs)

    def pump_wait(self, wait_s: float) -> None:
        """Pump; when nothing was there, wait up to ``wait_s`` for bytes."""
        if self.pump() == 0:
            self.link.wait_readable(wait_s)

    def failed(self, exc: Exception) -> None:
        """A dead link shows as stale telemetry (the failsafe acts); said once."""
        if not self.link_down:
            self.link_down = True
            self.event("warning", f"link failure: {exc}")

    def send(self, msg: Any) -> None:
        """Send ``msg``; a blocked one is replaced by the safe command and fails the flight safe."""
        try:
            self.link.send(msg)
        except UnsafeCommand as exc:
            first = self.fault is None
            if first:
                self.fault = ("unsafe_command", "")
                self.event("failsafe", f"output guard blocked a command ({exc}): safe level command, landing")
            try:
                self.link.send(self.safe_command())
            except (UnsafeCommand, LinkError) as exc2:
                if first:
                    self.event("warning", f"the safe command could not be sent either: {exc2}")
        except LinkError as exc:
            self.failed(exc)

    def quietly(self, send: Callable[[], object]) -> None:
        """Call ``send`` (a heartbeat, a request); a link failure is said once, not raised."""
        try:
            send()
        except LinkError as exc:
            self.failed(exc)
