"""The vehicle's clock seen from the loop's: rate and offset from the fastest deliveries.

A vehicle stamps its samples on its own clock (``time_boot_ms``), whose rate is not the ground
station's: a crystal is off by tens of ppm, a SITL on a loaded machine runs at 0.98 of the wall
clock, PX4 SITL's boot time runs at 0.988 of it.  Every sample arrives some time after its stamp:
``d = arrival - stamp`` is the clock offset plus the delivery delay, and the *fastest* deliveries
(the smallest ``d``) are the ones that show the offset.  With a vehicle clock running at ``r`` of
the loop's, the fastest ``d`` moves on a line of slope ``1 - r`` in loop time.

:class:`VehicleTimeMap` bins the deliveries by arrival (:data:`BIN_S`), keeps the smallest ``d`` of
each bin over the last :data:`WINDOW_S`, and fits the *lower support line* of those minima: the
line below every one of them that is highest at their mean time (the linear programme of clock-skew
estimation from one-way delays; it is not pulled up by late points, which only lie above it).  The
slope is bounded to :data:`MAX_SLOPE` (vehicle clocks at 0.88..1.12 of the loop's).  The line is the
*floor*: a sample's age is ``now - floor(now) - stamp``, its age on the vehicle's clock.

What stays old: the floor is a line through past fastest deliveries, so it cannot jump; a stall of
the link or of the ground station, a backlog or a late batch arrives with ``d`` above the line and
its age is its lateness, at once (it would be absorbed as a rate only past the window, by which
time the stale timeout has long acted).  A silent vehicle ages by arrival in the caller.
"""

from __future__ import annotations

from collections import deque

import numpy as np

__all__ = ["VehicleTimeMap", "BIN_S", "WINDOW_S", "MAX_SLOPE"]

#: Width of a bin of deliveries (its fastest one is kept) [s].
BIN_S = 0.5
#: Length of the history the line is fitted over [s].
WINDOW_S = 10.0
#: Largest |d(arrival - stamp)/d(arrival)|: vehicle clocks at 1 -/+ this of the loop's [s/s].
MAX_SLOPE = 0.12

_BIN_NS = int(BIN_S * 1e9)
_N_BINS = int(round(WINDOW_S / BIN_S))


class VehicleTimeMap:
    """Loop time <-> vehicle time, tracking a vehicle clock that runs at its own rate.

    ``observe`` each timed sample; ``age_ns`` of a stamp is how old it is on the vehicle's clock at a
    loop time, whenever it arrived.  Before any sample ``offset_ns`` is None and ages are 0.
    """

    def __init__(self) -> None:
        self._bins: deque[tuple[int, int]] = deque(maxlen=_N_BINS)  # (arrival, d) of each closed bin's fastest
        self._cur: tuple[int, int] | None = None  # the open bin's fastest (arrival, d)
        self._cur_bin = 0
        self._slope = 0.0
        self._t0_ns = 0  # the line: d = _c_ns + _slope * (t - _t0_ns)
        self._c_ns = 0.0
        self._fitted = False
        self._last_ns = 0
        self._first: tuple[int, int] | None = None  # the first closed bin's fastest (arrival, d)

    # ---------------------------------------------------------------- what users read
    @property
    def offset_ns(self) -> int | None:
        """The floor (arrival minus stamp of the fastest delivery) at the last sample's arrival [ns]."""
        if self._cur is None:
            return None
        return self._floor(self._last_ns)

    @property
    def rate(self) -> float:
        """Vehicle seconds per loop second (1.0 until the history spans a few bins)."""
        return 1.0 - self._slope

    @property
    def mean_rate(self) -> float:
        """Vehicle seconds per loop second since the first closed bin (the floor's rise over all of it).

        The long-run rate a user compares with the vehicle's crystal; :attr:`rate` is the windowed
        slope the floor is carried at, which follows a vehicle clock that slows under load or pauses.
        1.0 until the history spans :data:`WINDOW_S` / 4.
        """
        if self._first is None or self._last_ns - self._first[0] < _BIN_NS * _N_BINS // 4:
            return self.rate
        t, d = self._first
        return 1.0 - (self._floor(self._last_ns) - d) / (self._last_ns - t)

    def vehicle_time_ns(self, now_ns: int) -> int | None:
        """The vehicle's clock at loop time ``now_ns`` less the fastest delivery (None before any sample)."""
        if self._cur is None:
            return None
        return now_ns - self._floor(now_ns)

    def age_ns(self, now_ns: int, stamp_ns: int) -> int:
        """Age of a sample stamped ``stamp_ns`` (vehicle clock) at loop time ``now_ns``."""
        if self._cur is None:
            return 0
        return now_ns - self._floor(now_ns) - stamp_ns

    # ---------------------------------------------------------------- feeding
    def observe(self, arrival_ns: int, stamp_ns: int) -> None:
        """One sample stamped ``stamp_ns`` (vehicle clock) arrived at loop time ``arrival_ns``."""
        d = arrival_ns - stamp_ns
        b = arrival_ns // _BIN_NS
        if self._cur is None:
            self._cur, self._cur_bin = (arrival_ns, d), b
        elif b != self._cur_bin:
            self._bins.append(self._cur)
            if self._first is None:
                self._first = self._cur
            self._cur, self._cur_bin = (arrival_ns, d), b
            self._fit()
        elif d < self._cur[1]:
            self._cur = (arrival_ns, d)
        self._last_ns = max(self._last_ns, arrival_ns)

    def _floor(self, now_ns: int) -> int:
        t, d = self._cur
        cur = d + self._slope * (now_ns - t)  # the open bin's fastest, carried at the fitted rate
        if not self._fitted:
            return int(cur)
        return int(min(cur, self._c_ns + self._slope * (now_ns - self._t0_ns)))

    def _fit(self) -> None:
        """The lower support line of the closed bins' minima (highest at their mean time), slope bounded."""
        pts = np.array(self._bins, dtype=np.float64)
        t0 = pts[-1, 0]
        t = (pts[:, 0] - t0) * 1e-9  # s, the newest bin at 0
        d = pts[:, 1] * 1e-9
        if len(t) < 2 or t[-1] - t[0] < BIN_S:
            slopes = np.array([0.0])
        else:
            i, j = np.triu_indices(len(t), 1)
            dt = t[j] - t[i]
            ok = dt > 0.5 * BIN_S
            slopes = np.concatenate(((d[j] - d[i])[ok] / dt[ok], [0.0, -MAX_SLOPE, MAX_SLOPE]))
            slopes = np.clip(slopes, -MAX_SLOPE, MAX_SLOPE)
        c = np.min(d[None, :] - slopes[:, None] * t[None, :], axis=1)  # each slope's support offset
        best = int(np.argmax(c + slopes * t.mean()))
        self._slope = float(slopes[best])
        self._t0_ns = int(t0)
        self._c_ns = float(c[best]) * 1e9
        self._fitted = True
