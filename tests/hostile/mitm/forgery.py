"""The proxy's forgeries: valid frames (good CRC) with hostile fields, other system ids, wrong signatures."""

from __future__ import annotations

import random

from .faults import BOTH, Fault, Out
from .wire import DOWN, HOSTILE_FLOATS, decode_frames, is_signed, new_parser, split_frames

__all__ = ["mutate_fields", "HostileFields", "OtherSystem", "ForgedSigned"]

#: The system ids an :class:`OtherSystem` copy claims (never the real sender's).
OTHER_SYSIDS = (0, 2, 3, 42, 77, 200, 254, 255, 1)


def mutate_fields(rng: random.Random, msg, values=HOSTILE_FLOATS) -> list[str]:
    """Set one or more fields of a decoded message to hostile values; the names changed."""
    t = msg.get_type()
    changed = []
    if t == "HEARTBEAT":
        name = rng.choice(("custom_mode", "type", "autopilot", "system_status", "mavlink_version"))
        setattr(msg, name, 0xFFFFFFFF if name == "custom_mode" else 255)
        return [name]
    floats = [n for n in msg.get_fieldnames() if isinstance(getattr(msg, n), float)]
    arrays = [n for n in msg.get_fieldnames() if isinstance(getattr(msg, n), (list, tuple))
              and getattr(msg, n) and isinstance(getattr(msg, n)[0], float)]
    for _ in range(rng.randint(1, 3)):
        if arrays and rng.random() < 0.3:
            n = rng.choice(arrays)
            a = list(getattr(msg, n))
            a[rng.randrange(len(a))] = rng.choice(values)
            setattr(msg, n, a)
            changed.append(n)
        elif floats:
            n = rng.choice(floats)
            setattr(msg, n, rng.choice(values))
            changed.append(n)
    return changed


class HostileFields(Fault):
    """Valid frames (good CRC, the sender's ids and sequence) with fields set to NaN/inf/±1e38.

    ``types``: which messages are re-encoded (ATTITUDE, LOCAL_POSITION_NED, HEARTBEAT by
    default; for "up" e.g. SET_ATTITUDE_TARGET).  ``mode``: "inject" adds the hostile copy
    next to the original, "replace" sends it instead of the original.  ``alt``: from the
    alternate socket (a different source address/port).  ``huge_time``: also stamp
    ``time_boot_ms`` with 2**32 - 1.  On a signed link the proxy cannot sign: the copy goes
    unsigned or signed with a wrong key (a forgery).  One frame per received datagram.
    """

    name = "hostile_fields"

    def __init__(self, p=0.05, types=("ATTITUDE", "LOCAL_POSITION_NED", "HEARTBEAT"), mode="inject", alt=False,
                 values=HOSTILE_FLOATS, huge_time=False, directions=(DOWN,), name: str | None = None) -> None:
        super().__init__(p, directions)
        self.types, self.mode, self.alt, self.values, self.huge_time = set(types), mode, alt, values, huge_time
        if name:
            self.name = name
        self._parser = new_parser()

    def _hostile(self, proxy, frame: bytes) -> bytes | None:
        """``frame`` re-encoded with hostile fields, or None when it is not one of ``types``."""
        msgs = decode_frames(self._parser, frame)
        if len(msgs) != 1 or msgs[0].get_type() not in self.types:
            return None
        m = msgs[0]
        mutate_fields(proxy.rng, m, self.values)
        if self.huge_time and hasattr(m, "time_boot_ms"):
            m.time_boot_ms = 0xFFFFFFFF
        return proxy.repack(m, m.get_srcSystem(), m.get_srcComponent(), m.get_seq(), signed_like=is_signed(frame))

    def act(self, proxy, items):
        rng = proxy.rng
        extra = []
        acted = False
        for it in items:
            frames = split_frames(it.data)
            if not frames:
                continue
            new_frames = []
            for f in frames:
                hostile = None if acted else self._hostile(proxy, f)
                if hostile is None:
                    new_frames.append(f)
                    continue
                acted = True
                if self.mode == "replace":
                    self.stats.mutated_bytes += len(f)
                    new_frames.append(hostile)
                else:
                    new_frames.append(f)
                    self.injected(hostile)
                    extra.append(Out(hostile, it.delay + rng.uniform(0.0, 0.002), self.alt))
            it.data = b"".join(new_frames)
        if acted:
            self.stats.events += 1
        return items + extra


class OtherSystem(Fault):
    """Copies of the real frames re-encoded as from another system id (some with hostile fields)."""

    name = "other_system"

    def __init__(self, p=0.2, directions=BOTH) -> None:
        super().__init__(p, directions)
        self._parser = new_parser()

    def act(self, proxy, items):
        rng = proxy.rng
        extra = []
        for it in items:
            for m in decode_frames(self._parser, it.data):
                real = m.get_srcSystem()
                sysid = rng.choice([s for s in OTHER_SYSIDS if s != real])
                if rng.random() < 0.3:
                    mutate_fields(rng, m)
                hostile = proxy.repack(m, sysid, m.get_srcComponent(), rng.randrange(256), signed_like=False)
                self.injected(hostile)
                extra.append(Out(hostile, it.delay, rng.random() < 0.3))
        self.stats.events += 1
        return items + extra


class ForgedSigned(Fault):
    """Frames signed with a wrong key, claiming the real sender's stream (link id, system, component),
    with a huge signing timestamp (2**48 - 1 - small) or one just ahead of the real one."""

    name = "forged_signed"

    def __init__(self, p=0.05, huge=True, directions=BOTH) -> None:
        super().__init__(p, directions)
        self.huge = huge
        self._parser = new_parser()

    def _forge(self, proxy, frame: bytes) -> bytes | None:
        """A forgery of the signed ``frame`` (None when it is not a signed frame of one message)."""
        if not is_signed(frame):
            return None
        msgs = decode_frames(self._parser, frame)
        if len(msgs) != 1:
            return None
        rng = proxy.rng
        m = msgs[0]
        link_id = frame[-13]
        real_ts = int.from_bytes(frame[-12:-6], "little")
        ts = (2 ** 48 - 1 - rng.randrange(1000)) if self.huge else real_ts + rng.randint(1, 1000)
        if rng.random() < 0.5:
            mutate_fields(rng, m)
        return proxy.forge(m, m.get_srcSystem(), m.get_srcComponent(), m.get_seq(), link_id, ts)

    def act(self, proxy, items):
        extra = []
        for it in items:
            for f in split_frames(it.data) or []:
                forged = self._forge(proxy, f)
                if forged is not None:
                    self.injected(forged)
                    extra.append(Out(forged, it.delay))
                    break
        if extra:
            self.stats.events += 1
        return extra + items
