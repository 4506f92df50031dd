"""The seeded faults of the proxy that work on bytes and timing (the forgeries are in :mod:`.forgery`).

Faults count what they did (:class:`FaultStats`): ``injected_bytes`` are bytes put on the wire
that the legitimate peer never sent (garbage, copies, forged frames, appended bytes),
``mutated_bytes`` the size of the legitimate datagrams they changed (bit flips, truncations,
re-encoded fields).
"""

from __future__ import annotations

import random
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from .wire import DOWN, UP, split_frames

if TYPE_CHECKING:
    from .proxy import MitmProxy

__all__ = ["Out", "FaultStats", "Fault", "garbage", "GarbageDatagrams", "LoneMagic", "InlineGarbage", "Truncate",
           "BitFlip", "Duplicate", "Reorder", "Delay", "Burst", "Drop"]

BOTH = (DOWN, UP)


@dataclass
class Out:
    """One datagram leaving the proxy: after ``delay`` s, from the alternate socket if ``alt``."""

    data: bytes
    delay: float = 0.0
    alt: bool = False


@dataclass
class FaultStats:
    events: int = 0
    injected_bytes: int = 0
    mutated_bytes: int = 0
    injected_datagrams: int = 0
    dropped_datagrams: int = 0


class Fault:
    """A seeded transformation of the datagrams of one or both directions.

    ``process(proxy, direction, items)`` gets the datagrams produced so far from one
    received datagram (a list of :class:`Out`) and returns the new list.  ``p`` is
    the probability per received datagram that the fault acts; when it does (and, if
    ``needs_items``, there is a datagram left to act on), :meth:`act` does the work.
    """

    name = "fault"
    needs_items = True

    def __init__(self, p: float = 0.1, directions: Sequence[str] = BOTH) -> None:
        self.p = p
        self.directions = tuple(directions)
        self.stats = FaultStats()

    def wants(self, proxy: MitmProxy, direction: str) -> bool:
        return direction in self.directions and proxy.rng.random() < self.p

    def process(self, proxy: MitmProxy, direction: str, items: list[Out]) -> list[Out]:
        if (self.needs_items and not items) or not self.wants(proxy, direction):
            return items
        return self.act(proxy, items)

    def act(self, proxy: MitmProxy, items: list[Out]) -> list[Out]:
        return items

    def injected(self, data: bytes) -> None:
        self.stats.injected_bytes += len(data)
        self.stats.injected_datagrams += 1

    def __repr__(self) -> str:
        return f"{type(self).__name__}(p={self.p}, {'/'.join(self.directions)})"


def garbage(rng: random.Random, n: int, magic_rich: bool = False) -> bytes:
    """``n`` random bytes; ``magic_rich``: with many 0xFD/0xFE frame starts among them."""
    b = bytearray(rng.randbytes(n))
    if magic_rich:
        for i in range(0, n, max(1, rng.randint(3, 40))):
            b[i] = rng.choice((0xFD, 0xFE))
    return bytes(b)


class GarbageDatagrams(Fault):
    """Random datagrams (1..``max_len`` bytes) next to the real one; ``magic_rich``: many 0xFD/0xFE."""

    name = "garbage_datagrams"
    needs_items = False

    def __init__(self, p=0.2, max_len=1400, count=(1, 3), magic_rich=False, directions=BOTH) -> None:
        super().__init__(p, directions)
        self.max_len, self.count, self.magic_rich = max_len, count, magic_rich
        if magic_rich:
            self.name = "magic_garbage"

    def act(self, proxy, items):
        rng = proxy.rng
        self.stats.events += 1
        extra = []
        for _ in range(rng.randint(*self.count)):
            g = garbage(rng, rng.randint(1, self.max_len), self.magic_rich)
            self.injected(g)
            extra.append(Out(g, items[0].delay if items else 0.0))
        return extra + items if rng.random() < 0.5 else items + extra


class LoneMagic(Fault):
    """1-byte datagrams of a frame start (0xFD, sometimes 0xFE) just before the real datagram."""

    name = "lone_magic"
    needs_items = False

    def act(self, proxy, items):
        self.stats.events += 1
        g = bytes((0xFD if proxy.rng.random() < 0.8 else 0xFE,))
        self.injected(g)
        return [Out(g, items[0].delay if items else 0.0), *items]


class InlineGarbage(Fault):
    """Random bytes prepended and/or appended inside the real datagram."""

    name = "inline_garbage"

    def __init__(self, p=0.2, max_len=64, directions=BOTH) -> None:
        super().__init__(p, directions)
        self.max_len = max_len

    def act(self, proxy, items):
        rng = proxy.rng
        it = rng.choice(items)
        where = rng.choice(("pre", "post", "both"))
        pre = garbage(rng, rng.randint(1, self.max_len)) if where in ("pre", "both") else b""
        post = garbage(rng, rng.randint(1, self.max_len)) if where in ("post", "both") else b""
        self.stats.events += 1
        self.stats.injected_bytes += len(pre) + len(post)
        self.stats.mutated_bytes += len(it.data)
        it.data = pre + it.data + post
        return items


class Truncate(Fault):
    """A datagram cut short, or one of its frames cut in the middle with the following frames kept."""

    name = "truncate"

    def act(self, proxy, items):
        rng = proxy.rng
        it = rng.choice(items)
        frames = split_frames(it.data)
        self.stats.events += 1
        self.stats.mutated_bytes += len(it.data)
        if frames and len(frames) > 1 and rng.random() < 0.5:
            k = rng.randrange(len(frames))
            f = frames[k]
            frames[k] = f[:rng.randint(1, len(f) - 1)]
            it.data = b"".join(frames)
        elif len(it.data) > 1:
            it.data = it.data[:rng.randint(1, len(it.data) - 1)]
        return items


class BitFlip(Fault):
    """1..``max_bits`` random bits flipped (a bad CRC, mostly)."""

    name = "bit_flip"

    def __init__(self, p=0.1, max_bits=3, directions=BOTH) -> None:
        super().__init__(p, directions)
        self.max_bits = max_bits

    def act(self, proxy, items):
        rng = proxy.rng
        it = rng.choice(items)
        b = bytearray(it.data)
        for _ in range(rng.randint(1, self.max_bits)):
            i = rng.randrange(len(b))
            b[i] ^= 1 << rng.randrange(8)
        self.stats.events += 1
        self.stats.mutated_bytes += len(b)
        it.data = bytes(b)
        return items


class Duplicate(Fault):
    """The datagram sent again (1..``max_copies`` times), now or a few ms later."""

    name = "duplicate"

    def __init__(self, p=0.1, max_copies=2, max_delay=0.005, directions=BOTH) -> None:
        super().__init__(p, directions)
        self.max_copies, self.max_delay = max_copies, max_delay

    def act(self, proxy, items):
        rng = proxy.rng
        self.stats.events += 1
        extra = []
        for it in items:
            for _ in range(rng.randint(1, self.max_copies)):
                self.injected(it.data)
                extra.append(Out(it.data, it.delay + rng.uniform(0.0, self.max_delay), it.alt))
        return items + extra


class Reorder(Fault):
    """Frames of a datagram split into one datagram each and shuffled; some held back a few ms."""

    name = "reorder"

    def __init__(self, p=0.2, max_delay=0.008, directions=BOTH) -> None:
        super().__init__(p, directions)
        self.max_delay = max_delay

    def act(self, proxy, items):
        rng = proxy.rng
        out = []
        for it in items:
            frames = split_frames(it.data)
            if frames and len(frames) > 1:
                rng.shuffle(frames)
                out += [Out(f, it.delay, it.alt) for f in frames]
            else:
                out.append(it)
        for it in out:
            if rng.random() < 0.5:
                it.delay += rng.uniform(0.0, self.max_delay)
        self.stats.events += 1
        self.stats.mutated_bytes += sum(len(i.data) for i in items)
        return out


class Delay(Fault):
    """A datagram held back ``lo``..``hi`` s (later ones overtake it)."""

    name = "delay"
    needs_items = False

    def __init__(self, p=0.1, lo=0.005, hi=0.08, directions=BOTH) -> None:
        super().__init__(p, directions)
        self.lo, self.hi = lo, hi

    def act(self, proxy, items):
        d = proxy.rng.uniform(self.lo, self.hi)
        self.stats.events += 1
        for it in items:
            it.delay += d
        return items


class Burst(Fault):
    """Every ``period`` s (wall) the direction is held for ``hold`` s, then everything arrives at once."""

    name = "burst"

    def __init__(self, period=(0.5, 2.0), hold=(0.05, 0.2), directions=BOTH) -> None:
        super().__init__(1.0, directions)
        self.period, self.hold = period, hold
        self._windows: dict[str, tuple[float, float]] = {}

    def process(self, proxy, direction, items):
        if direction not in self.directions:
            return items
        now = time.monotonic()
        rng = proxy.rng
        w = self._windows.get(direction)
        if w is None or now >= w[1]:
            start = now + rng.uniform(*self.period)
            w = self._windows[direction] = (start, start + rng.uniform(*self.hold))
        if w[0] <= now < w[1]:
            for it in items:
                it.delay = max(it.delay, w[1] - now)
            self.stats.events += 1
        return items


class Drop(Fault):
    """Datagrams lost."""

    name = "drop"

    def act(self, proxy, items):
        self.stats.events += 1
        self.stats.dropped_datagrams += len(items)
        return []
