"""What every link to a vehicle shares: waiting for one message without losing the others."""

from __future__ import annotations

import time
from typing import Any
from collections.abc import Callable

__all__ = ["MessageWaiter", "serial_errors"]


class MessageWaiter:
    """Mixin: :meth:`wait` on top of the link's ``drain()`` (every message waiting now, never
    blocking) and ``wait_readable(s)``; messages received after the awaited one are kept in
    ``_pending`` for the next ``drain()``."""

    _pending: list

    def drain(self) -> list:  # pragma: no cover - provided by the link
        raise NotImplementedError

    def wait_readable(self, timeout_s: float) -> None:  # pragma: no cover - provided by the link
        raise NotImplementedError

    def wait(self, predicate: Callable[[Any], bool], timeout_s: float,
             on_message: Callable[[Any], None] | None = None) -> Any | None:
        """Receive until ``predicate(msg)`` holds or ``timeout_s`` of wall time passes; every message
        received meanwhile is also passed to ``on_message``."""
        deadline = time.monotonic() + timeout_s
        while True:
            batch = self.drain()
            for i, msg in enumerate(batch):
                if on_message is not None:
                    on_message(msg)
                if predicate(msg):
                    # What came after the awaited message is not lost: the next drain returns it.
                    self._pending = batch[i + 1:] + self._pending
                    return msg
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return None
            self.wait_readable(min(0.02, remaining))


def serial_errors() -> type[Exception]:
    """pyserial's exception class (an OSError subclass on recent versions)."""
    try:
        from serial import SerialException
    except ImportError:  # pragma: no cover - pyserial is a dependency
        return OSError
    return SerialException
