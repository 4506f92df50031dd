"""Loop timing: deadline misses, wake-up jitter and per-stage compute time."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["LoopStats", "STAGES"]

#: The stages of one tick, in order.
STAGES = ("decode", "estimate", "control", "send", "log")


@dataclass
class LoopStats:
    """Per-tick timing samples [ns] and counters.

    A deadline is missed when a tick starts one whole period or more after its
    deadline (that tick's telemetry and command are late by a full period);
    the loop then skips to the next deadline in the future, so it never drifts.
    """

    period_ns: int
    ticks: int = 0
    deadline_misses: int = 0
    skipped_ticks: int = 0
    jitter_ns: list[int] = field(default_factory=list)
    tick_ns: list[int] = field(default_factory=list)
    stage_ns: dict[str, list[int]] = field(default_factory=lambda: {s: [] for s in STAGES})

    def record(self, jitter_ns: int, stages_ns: dict[str, int]) -> None:
        self.ticks += 1
        self.jitter_ns.append(jitter_ns)
        self.tick_ns.append(sum(stages_ns.values()))
        for k, v in stages_ns.items():
            self.stage_ns.setdefault(k, []).append(v)
        if jitter_ns >= self.period_ns:
            self.deadline_misses += 1

    @staticmethod
    def _pct_ms(samples: list[int], q: float) -> float:
        return float(np.percentile(np.asarray(samples, dtype=float), q)) / 1e6 if samples else 0.0

    def summary(self) -> dict:
        """``{"ticks", "deadline_misses", "jitter_p99_ms", "tick_p99_ms", ...}``."""
        out = {
            "ticks": self.ticks,
            "deadline_misses": self.deadline_misses,
            "skipped_ticks": self.skipped_ticks,
            "jitter_p50_ms": self._pct_ms(self.jitter_ns, 50),
            "jitter_p99_ms": self._pct_ms(self.jitter_ns, 99),
            "tick_p50_ms": self._pct_ms(self.tick_ns, 50),
            "tick_p99_ms": self._pct_ms(self.tick_ns, 99),
        }
        for s in STAGES:
            out[f"{s}_p50_ms"] = self._pct_ms(self.stage_ns[s], 50)
            out[f"{s}_p99_ms"] = self._pct_ms(self.stage_ns[s], 99)
        return out
