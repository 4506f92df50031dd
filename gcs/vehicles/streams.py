"""Watching the telemetry streams the controller flies on, and getting them back when they fall.

Another ground station on the same link (MAVProxy sends REQUEST_DATA_STREAM(ALL, 4 Hz) at
connect and every 15 s) or an autopilot that forgot our request can lower ATTITUDE and
LOCAL_POSITION_NED from 100 Hz to a few hertz: still "fresh" by the staleness test, far
too slow to control.  :class:`StreamMonitor` measures each stream's rate over short
windows of the loop's clock (the vehicle's own time in lockstep), asks for the rate
again when it falls below ``rerequest_fraction`` of what was requested, and reports a
failure once it has stayed below ``min_rate_hz`` for ``grace_s``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from collections.abc import Mapping

__all__ = ["StreamMonitor", "StreamVerdict"]


@dataclass(frozen=True)
class StreamVerdict:
    """What one window of the monitor found."""

    #: Streams to ask for again now (their rate fell).
    rerequest: tuple[str, ...] = ()
    #: The rate has been too low for too long: why (None = fine).
    failure: str | None = None


@dataclass
class StreamMonitor:
    """Rates of the streams in ``requested_hz`` (message name -> rate asked for [Hz]).

    Parameters
    ----------
    requested_hz : mapping
    min_rate_hz : float
        Below this the controller cannot fly (failsafe after ``grace_s``).
    window_s : float
        Length of one measurement window [s].
    grace_s : float
        How long the rate may stay below ``min_rate_hz`` [s].
    rerequest_fraction : float
        Ask again when a window's rate is below this share of the requested rate.
    rerequest_period_s : float
        At most one request per stream per this period [s].
    """

    requested_hz: Mapping[str, float]
    min_rate_hz: float
    window_s: float = 0.25
    grace_s: float = 1.0
    rerequest_fraction: float = 0.8
    rerequest_period_s: float = 1.0
    rates_hz: dict[str, float] = field(default_factory=dict)
    rerequests: int = 0
    low_windows: int = 0
    _t0_ns: int | None = None
    _counts0: dict[str, int] = field(default_factory=dict)
    _low_since_ns: int | None = None
    _last_request_ns: dict[str, int] = field(default_factory=dict)

    def start(self, now_ns: int, counts: Mapping[str, int]) -> None:
        """Begin measuring at ``now_ns`` from the message counts so far."""
        self._t0_ns = now_ns
        self._counts0 = {k: counts.get(k, 0) for k in self.requested_hz}
        self._low_since_ns = None

    def update(self, now_ns: int, counts: Mapping[str, int]) -> StreamVerdict:
        """Call every tick with the valid-message counts; a verdict at the end of each window."""
        if self._t0_ns is None:
            self.start(now_ns, counts)
            return StreamVerdict()
        dt = (now_ns - self._t0_ns) / 1e9
        if dt < self.window_s:
            return StreamVerdict()
        rerequest = []
        low = False
        for name, want in self.requested_hz.items():
            rate = (counts.get(name, 0) - self._counts0.get(name, 0)) / dt
            self.rates_hz[name] = rate
            if rate < self.rerequest_fraction * want:
                last = self._last_request_ns.get(name)
                if last is None or now_ns - last >= self.rerequest_period_s * 1e9:
                    self._last_request_ns[name] = now_ns
                    rerequest.append(name)
                    self.rerequests += 1
            if rate < self.min_rate_hz:
                low = True
        self._t0_ns = now_ns
        self._counts0 = {k: counts.get(k, 0) for k in self.requested_hz}
        failure = None
        if low:
            self.low_windows += 1
            self._low_since_ns = self._low_since_ns if self._low_since_ns is not None else now_ns - int(dt * 1e9)
            if (now_ns - self._low_since_ns) / 1e9 >= self.grace_s:
                slow = ", ".join(f"{n} {self.rates_hz[n]:.1f} Hz" for n in self.requested_hz
                                 if self.rates_hz.get(n, 0.0) < self.min_rate_hz)
                failure = (f"telemetry too slow to control for {self.grace_s:g} s ({slow}; at least "
                           f"{self.min_rate_hz:g} Hz needed)")
        else:
            self._low_since_ns = None
        return StreamVerdict(tuple(rerequest), failure)
