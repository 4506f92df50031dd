"""The rig's serial link: the transport, the XBee radio's baud limit / loss / latency, and bit errors.

:class:`BitErrors` flips each bit independently with probability ``rate``.  The distance to the
next flipped bit is drawn from the geometric distribution and carried across chunks, so the
flipped positions depend only on the seed and the byte count, not on how the stream was cut into
chunks.  Bits flip after the radio on the way in and before it on the way out, as on a noisy hop.
"""

from __future__ import annotations

import math
import random
from typing import Any

from sitl.net.radio import RadioLink, RadioParams
from sitl.net.transport import Transport

__all__ = ["BitErrors", "SerialLink"]


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


class SerialLink:
    """The rig's end of its serial line (a single peer): bytes in, frames out, through the emulation.

    Parameters
    ----------
    transport : Transport
        Normally :class:`~sitl.net.pty.PtyTransport`; closed by :meth:`close`.
    radio : RadioParams or None
        Baud limit / loss / latency of both directions (None or inactive: none).
    bit_error_rate : float
        Probability of flipping each bit, both directions.
    seed : int
        Seeds the radio's losses and the bit errors.
    """

    def __init__(self, transport: Transport, radio: RadioParams | None, bit_error_rate: float, seed: int) -> None:
        self.transport = transport
        self.radio = RadioLink(radio, seed) if radio is not None and radio.active else None
        self.bits_up = BitErrors(bit_error_rate, random.Random(f"{seed}/rig/bits/up"))
        self.bits_down = BitErrors(bit_error_rate, random.Random(f"{seed}/rig/bits/down"))
        self.tx_frames = 0
        self.tx_bytes = 0
        self.lost_in = 0
        self.lost_out = 0
        self.dropped_out = 0
        self._new_peer = False

    def receive(self, now_ns: int) -> list[bytes]:
        """The chunks delivered by ``now_ns`` (after the radio and the bit errors)."""
        t = self.transport
        items = t.receive()
        t.take_gone_peers()
        if t.take_new_peers():
            self._new_peer = True
        radio = self.radio
        if radio is None:
            chunks = [data for _, data, _ in items]
        else:
            for peer, data, _ in items:
                if not radio.up.push(peer, data, now_ns):
                    self.lost_in += 1
            chunks = [data for _, data in radio.up.pop_ready(now_ns)]
        return [self.bits_up.apply(c) for c in chunks]

    def take_new_peer(self) -> bool:
        """True once after the PC first sent something (the rig greets it)."""
        new, self._new_peer = self._new_peer, False
        return new

    def send(self, frames: list[bytes], now_ns: int) -> None:
        """Send encoded frames (through the radio: those delivered by ``now_ns``)."""
        radio = self.radio
        if radio is not None:
            for f in frames:
                if not radio.down.push(None, f, now_ns):
                    self.lost_out += 1
            frames = [f for _, f in radio.down.pop_ready(now_ns)]
        if frames:
            frames = [self.bits_down.apply(f) for f in frames]
            self.tx_frames += len(frames)
            self.tx_bytes += sum(len(f) for f in frames)
            self.dropped_out += self.transport.send(frames)

    def counters(self) -> dict[str, Any]:
        """Frames and bytes sent, chunks lost or dropped, bits flipped."""
        return {"tx_frames": self.tx_frames, "tx_bytes": self.tx_bytes, "lost_in": self.lost_in,
                "lost_out": self.lost_out, "dropped_out": self.dropped_out,
                "bits_flipped_in": self.bits_up.flipped_bits, "bits_flipped_out": self.bits_down.flipped_bits}

    # ------------------------------------------------------------------ what the server loop waits on
    def filenos(self) -> list[int]:
        return self.transport.filenos()

    def write_filenos(self) -> list[int]:
        return self.transport.write_filenos()

    def flush_transports(self) -> None:
        self.transport.flush()

    def next_event_ns(self) -> int | None:
        return self.radio.next_event_ns() if self.radio is not None else None

    def close(self) -> None:
        self.transport.close()
