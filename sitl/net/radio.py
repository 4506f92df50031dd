"""Telemetry-radio emulation between the vehicle and its endpoint: baud limit, loss, latency.

Each direction is a :class:`RadioPipe`: a chunk (an outgoing MAVLink frame, or
whatever the ground station wrote) is lost with probability ``loss``, else
queued; it leaves ``latency_s`` after it entered, and the line then carries it
at ``baud / 10`` bytes per second (8N1), one chunk after the other.  A chunk
that would overflow ``queue_bytes`` is dropped (a radio's buffer is small).
Loss decisions come from a seeded generator, so they repeat for a given
seed and traffic.  Times are integer nanoseconds from the injected clock.
"""

from __future__ import annotations

import math
import random
from collections import deque
from dataclasses import dataclass
from collections.abc import Hashable

__all__ = ["RadioParams", "RadioPipe", "RadioLink"]


@dataclass(frozen=True)
class RadioParams:
    """Link emulation settings.

    Attributes
    ----------
    baud : int
        Serial rate [bit/s]; 0 = unlimited.  10 bits per byte.
    loss : float
        Probability that a chunk is lost, 0..1.
    latency_s : float
        One-way delay added to every chunk [s].
    queue_bytes : int
        Buffer of each direction [bytes].
    """

    baud: int = 0
    loss: float = 0.0
    latency_s: float = 0.0
    queue_bytes: int = 4096

    def __post_init__(self) -> None:
        if self.baud < 0:
            raise ValueError(f"baud must be >= 0, got {self.baud!r}")
        if not 0.0 <= self.loss <= 1.0:
            raise ValueError(f"loss must be in [0, 1], got {self.loss!r}")
        if not 0.0 <= self.latency_s < math.inf:
            raise ValueError(f"latency must be finite and >= 0, got {self.latency_s!r}")
        if self.queue_bytes < 280:
            raise ValueError(f"queue_bytes must hold a MAVLink frame (>= 280), got {self.queue_bytes!r}")

    @property
    def active(self) -> bool:
        """True when the link changes anything."""
        return self.baud > 0 or self.loss > 0 or self.latency_s > 0


class RadioPipe:
    """One direction of the radio.

    Parameters
    ----------
    params : RadioParams
    rng : random.Random
        Loss decisions.
    """

    def __init__(self, params: RadioParams, rng: random.Random) -> None:
        self.params = params
        self._rng = rng
        self._queue: deque[tuple[int, Hashable, bytes]] = deque()
        self._queued = 0
        self._line_free_ns = 0
        self._ns_per_byte = 10e9 / params.baud if params.baud > 0 else 0.0
        self._latency_ns = int(round(params.latency_s * 1e9))
        self.lost = 0
        self.dropped = 0

    def push(self, key: Hashable, data: bytes, now_ns: int) -> bool:
        """Enter a chunk; False if it was lost or dropped."""
        if self.params.loss > 0.0 and self._rng.random() < self.params.loss:
            self.lost += 1
            return False
        if self._queued + len(data) > self.params.queue_bytes:
            self.dropped += 1
            return False
        self._queue.append((now_ns + self._latency_ns, key, data))
        self._queued += len(data)
        return True

    def _done_ns(self, release_ns: int, size: int) -> int:
        start = release_ns if release_ns > self._line_free_ns else self._line_free_ns
        return start + int(size * self._ns_per_byte)

    def pop_ready(self, now_ns: int) -> list[tuple[Hashable, bytes]]:
        """Chunks fully delivered by ``now_ns``, in order."""
        out = []
        q = self._queue
        while q:
            release, key, data = q[0]
            done = self._done_ns(release, len(data)) if self._ns_per_byte else release
            if done > now_ns:
                break
            q.popleft()
            self._queued -= len(data)
            if self._ns_per_byte:
                self._line_free_ns = done
            out.append((key, data))
        return out

    def next_event_ns(self) -> int | None:
        """When the head chunk will be delivered (None if empty)."""
        if not self._queue:
            return None
        release, _, data = self._queue[0]
        return self._done_ns(release, len(data)) if self._ns_per_byte else release


class RadioLink:
    """Both directions: ``up`` (ground station to vehicle) and ``down``.

    Parameters
    ----------
    params : RadioParams
    seed : int or str
        Seeds the loss decisions (``up`` and ``down`` have their own streams).
    """

    def __init__(self, params: RadioParams, seed: int | str = 0) -> None:
        self.params = params
        self.up = RadioPipe(params, random.Random(f"{seed}/radio/up"))
        self.down = RadioPipe(params, random.Random(f"{seed}/radio/down"))

    def next_event_ns(self) -> int | None:
        """Earliest delivery in either direction."""
        times = [t for t in (self.up.next_event_ns(), self.down.next_event_ns()) if t is not None]
        return min(times) if times else None
