"""The vehicle's links: every peer of every endpoint, with its own stream rates, sequence numbers and radio.

A link is one peer of one transport, keyed ``(endpoint index, peer)``.  Like an ArduPilot channel
it has its own stream schedule (requests received on it change its rates only), its own parser and
outgoing sequence number (:class:`~sitl.net.endpoint.MavlinkEndpoint`, keyed by the link key) and,
with link emulation, its own :class:`~sitl.net.radio.RadioLink`; the first link's radio is seeded
as a lone link's would be, so adding a second endpoint does not change the first one's losses.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable, Hashable, Sequence
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sitl.net.endpoint import LinkCounters, MavlinkEndpoint
from sitl.net.radio import RadioLink, RadioParams
from sitl.net.transport import Transport

__all__ = ["Link", "Links", "LinkKey"]

LinkKey = tuple[int, Hashable]


class Link:
    """One peer of one endpoint.

    Parameters
    ----------
    key : (int, hashable)
        ``(endpoint index, peer)``.
    streams : object
        The link's stream schedule (made by the factory given to :class:`Links`).
    radio : RadioLink or None
        Link emulation of this link (None: bytes go straight to the transport).
    """

    __slots__ = ("key", "streams", "radio")

    def __init__(self, key: LinkKey, streams: Any, radio: RadioLink | None = None) -> None:
        self.key = key
        self.streams = streams
        self.radio = radio


class Links:
    """All links of the vehicle over one or more transports.

    Parameters
    ----------
    transports : sequence of Transport
        The endpoints, in order (index 0 first).
    endpoint : MavlinkEndpoint
        Framing; its parsers and sequence numbers are keyed by link key.
    counters : LinkCounters
        ``lost_in``, ``lost_out`` and ``dropped_out`` are counted here.
    streams : callable
        Makes the stream schedule of a new link.
    radio : RadioParams or None
        Link emulation applied to every link (None or inactive: none).
    seed : int
        Seeds the radios' loss decisions.
    """

    def __init__(self, transports: Sequence[Transport], endpoint: MavlinkEndpoint, counters: LinkCounters,
                 streams: Callable[[], Any], radio: RadioParams | None = None, seed: int = 0) -> None:
        self.transports = list(transports)
        self._new_streams = streams
        self.endpoint = endpoint
        self.counters = counters
        self._radio = radio if radio is not None and radio.active else None
        self._seed = seed
        self._made = 0
        self.links: dict[LinkKey, Link] = {}
        self._greet: list[LinkKey] = []
        self._gone: list[LinkKey] = []
        self._out: list[tuple[LinkKey, bytes]] = []
        for i, t in enumerate(self.transports):
            for peer in t.peers():
                self.link((i, peer))

    def __len__(self) -> int:
        return len(self.links)

    def link(self, key: LinkKey) -> Link:
        """The link of ``key`` (made if new)."""
        ln = self.links.get(key)
        if ln is None:
            radio = None
            if self._radio is not None:
                seed = self._seed if self._made == 0 else f"{self._seed}/link{self._made}"
                radio = RadioLink(self._radio, seed)
            self._made += 1
            ln = self.links[key] = Link(key, self._new_streams(), radio)
        return ln

    def _drop(self, key: LinkKey) -> None:
        self.links.pop(key, None)
        self.endpoint.forget(key)

    # ------------------------------------------------------------------ input
    def poll(self, now_ns: int) -> list[tuple[LinkKey, bytes, bool]]:
        """Everything received (after link emulation): ``(link key, data, is_datagram)``.

        New peers get a link and are remembered for :meth:`take_greetings`.
        Peers that went away lose their link at the next poll (after what they
        sent last has been handled), unless they came back.
        """
        for i, peer in self._gone:
            if peer not in self.transports[i].peers():
                self._drop((i, peer))
        self._gone = []
        items: list[tuple[LinkKey, bytes, bool]] = []
        for i, t in enumerate(self.transports):
            got = t.receive()
            self._gone.extend((i, peer) for peer in t.take_gone_peers())
            for peer in t.take_new_peers():
                self.link((i, peer))
                self._greet.append((i, peer))
            items.extend(((i, peer), data, dg) for peer, data, dg in got)
        out: list[tuple[LinkKey, bytes, bool]] = []
        for key, data, dg in items:
            ln = self.link(key)
            if ln.radio is None:
                out.append((key, data, dg))
            elif not ln.radio.up.push(dg, data, now_ns):
                self.counters.lost_in += 1
        if self._radio is not None:
            for key, ln in self.links.items():
                if ln.radio is not None:
                    out.extend((key, data, dg) for dg, data in ln.radio.up.pop_ready(now_ns))
        return out

    def take_greetings(self) -> list[LinkKey]:
        """Links that appeared since the last call (the server sends each a HEARTBEAT)."""
        out, self._greet = self._greet, []
        return [k for k in out if k in self.links]

    # ------------------------------------------------------------------ output
    def queue(self, key: LinkKey, msg: mavlink.MAVLink_message) -> None:
        """Encode ``msg`` for link ``key`` (its sequence number) and queue it."""
        self._out.append((key, self.endpoint.encode(msg, key)))

    def queue_all(self, msg: mavlink.MAVLink_message) -> None:
        """Queue ``msg`` for every link, each with its own encoding."""
        for key in self.links:
            self._out.append((key, self.endpoint.encode(msg, key)))

    def discard(self) -> None:
        """Forget the queued frames (tests that drive the server by hand)."""
        self._out.clear()

    def flush(self, now_ns: int) -> None:
        """Send the queued frames (through each link's radio when emulated)."""
        frames, self._out = self._out, []
        ready: dict[LinkKey, list[bytes]] = defaultdict(list)
        for key, f in frames:
            ln = self.links.get(key)
            if ln is not None and ln.radio is not None:
                if not ln.radio.down.push(None, f, now_ns):
                    self.counters.lost_out += 1
            else:
                ready[key].append(f)
        if self._radio is not None:
            for key, ln in self.links.items():
                if ln.radio is not None:
                    got = ln.radio.down.pop_ready(now_ns)
                    if got:
                        ready[key].extend(f for _, f in got)
        for (index, peer), fs in ready.items():
            if 0 <= index < len(self.transports):
                self.counters.dropped_out += self.transports[index].send_to(peer, fs)
            else:
                self.counters.dropped_out += len(fs)

    def next_event_ns(self) -> int | None:
        """When the next emulated chunk is delivered, either direction, any link (None if none)."""
        times = [t for ln in self.links.values() if ln.radio is not None
                 for t in (ln.radio.next_event_ns(),) if t is not None]
        return min(times) if times else None

    # ------------------------------------------------------------------ descriptors
    def filenos(self) -> list[int]:
        """Descriptors to wait on for input."""
        return [fd for t in self.transports for fd in t.filenos()]

    def write_filenos(self) -> list[int]:
        """Descriptors with output waiting for the kernel."""
        return [fd for t in self.transports for fd in t.write_filenos()]

    def flush_transports(self) -> None:
        """Retry output that did not fit into the kernel buffers."""
        for t in self.transports:
            t.flush()

    def close(self) -> None:
        """Close every transport (idempotent)."""
        for t in self.transports:
            t.close()
