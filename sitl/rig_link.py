"""Bit errors on the rig's serial link (a noisy XBee hop), on top of :mod:`sitl.radio`.

:class:`BitErrors` flips each bit of the byte stream independently with
probability ``rate``.  The distance to the next flipped bit is drawn from the
geometric distribution and carried across chunks, so the flipped positions
depend only on the seed and the byte count, not on how the stream was cut
into chunks.
"""

from __future__ import annotations

import math
import random

__all__ = ["BitErrors"]


class BitErrors:
    """Seeded independent bit flips.

    Parameters
    ----------
    rate : float
        Bit error rate, 0 <= rate < 1 (0 = none).
    rng : random.Random
    """

    def __init__(self, rate: float, rng: random.Random) -> None:
        if not 0.0 <= rate < 1.0:
            raise ValueError(f"bit error rate must be in [0, 1), got {rate!r}")
        self.rate = rate
        self._rng = rng
        self._log_keep = math.log1p(-rate) if rate > 0 else 0.0
        self.flipped_bits = 0
        self._skip = self._draw() if rate > 0 else -1

    def _draw(self) -> int:
        """Number of clean bits before the next flipped one."""
        u = 1.0 - self._rng.random()  # (0, 1]
        return int(math.log(u) / self._log_keep)

    def apply(self, data: bytes) -> bytes:
        """``data`` with its bits flipped where the error process says."""
        if self.rate <= 0 or not data:
            return data
        nbits = 8 * len(data)
        if self._skip >= nbits:
            self._skip -= nbits
            return data
        out = bytearray(data)
        pos = self._skip
        while pos < nbits:
            out[pos >> 3] ^= 1 << (pos & 7)
            self.flipped_bits += 1
            pos += 1 + self._draw()
        self._skip = pos - nbits
        return bytes(out)
