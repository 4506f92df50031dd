"""How a flight ended: the exit reasons and codes, and the end-of-flight summary.

====  =================  ==========================================================
code  exit_reason        what happened
====  =================  ==========================================================
0     completed          mission flown, landed, disarmed
3     telemetry_lost     telemetry older than ``telemetry_stale_s``: safe descent
4     geofence           geofence or ceiling breached: landing
5     interrupted        Ctrl-C / SIGTERM: controlled descent, landed, disarmed
6     link_error         no heartbeat, port cannot be opened, the child simulator died
7     preflight_refused  link budget, stale telemetry, battery, mode or arming refused
8     immediate_land     a second Ctrl-C: land at once
9     vehicle_took_over  the vehicle left our control (disarmed, another mode, the rig's
                         cut-off): setpoints stop, the vehicle is left to itself
10    unsafe_command     a non-finite or out-of-limit estimate or command was caught
                         (never sent): a safe level command, then landing
11    internal_error     an exception in the ground station while flying: landing
12    telemetry_slow     the streams the controller flies on stayed too slow (after
                         asking for them again): landing
13    out_of_authority   a fault past the vehicle's authority (thrust at its top for 1 s,
                         the attitude output's rate correction at its bound for 2 s):
                         landing (:mod:`gcs.flight.authority`)
====  =================  ==========================================================

Whatever ends the flight, the vehicle is landed and disarmed (or left to the pilot, 9),
the parameters changed for the flight are restored and the log is finished.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from gcs.metrics import FlightRecord

__all__ = ["EXIT_CODES", "FlightResult"]

EXIT_CODES = {"completed": 0, "telemetry_lost": 3, "geofence": 4, "interrupted": 5, "link_error": 6,
              "preflight_refused": 7, "immediate_land": 8, "vehicle_took_over": 9, "unsafe_command": 10,
              "internal_error": 11, "telemetry_slow": 12,
              "out_of_authority": 13}


@dataclass
class FlightResult:
    """End-of-flight summary (see :meth:`to_json`)."""

    controller: str
    config: str
    exit_reason: str
    duration_s: float
    metrics: dict
    loop: dict
    events: list = field(default_factory=list)
    link: dict = field(default_factory=dict)
    record: FlightRecord | None = None
    log_path: str | None = None
    detail: str = ""
    experiment: str = ""

    @property
    def exit_code(self) -> int:
        return EXIT_CODES[self.exit_reason]

    @classmethod
    def refused(cls, controller: str, config: str, reason: str, detail: str, events: list | None = None
                ) -> FlightResult:
        """A flight that never flew (refused, a link error, an internal error before the mission)."""
        return cls(controller, config, reason, 0.0, {}, {"ticks": 0, "deadline_misses": 0, "jitter_p99_ms": 0.0,
                                                         "tick_p99_ms": 0.0}, list(events or []), detail=detail)

    def to_json(self) -> dict:
        doc = {"controller": self.controller, "config": self.config, "exit_reason": self.exit_reason,
               "exit_code": self.exit_code, "duration_s": self.duration_s, "metrics": self.metrics,
               "loop": self.loop, "events": self.events, "link": self.link, "log": self.log_path}
        if self.detail:
            doc["detail"] = self.detail
        return doc
