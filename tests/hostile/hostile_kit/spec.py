"""What a hostile flight is (:class:`Spec`), what an action sees while it flies (:class:`Run`) and what
came of it (:class:`Outcome`)."""

from __future__ import annotations

import subprocess
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from mitm import MitmProxy


def fmt(v) -> str:
    """A length in metres for a message ("-" when unknown)."""
    return "-" if v is None else f"{v:.2f}"


@dataclass
class Spec:
    """One flight.  ``timeout_s``: wall time after which the ground station counts as hung."""

    faults: Sequence = ()
    proxy_seed: int = 0
    sitl_seed: int = 0
    lockstep: bool = True
    config: str = "outdoor-circle"
    controller: str = "pd"
    duration_s: float | None = 10.0
    output: str | None = None
    signing_key: str | None = None   # 64 hex digits, for both sides
    gcs_args: Sequence[str] = ()
    sitl_args: Sequence[str] = ()
    timeout_s: float = 60.0
    action: Callable[[Run], None] | None = None
    clobber: str | None = None       # a MAVProxy-like second client (REQUEST_DATA_STREAM ALL 4 Hz every 2 s):
    #   "own_endpoint" (its own sitl endpoint when the sitl has several, else its own address),
    #   "shared_link" (on the ground station's link: the vehicle sees one peer)
    after_gcs_exit_wait_s: float = 0.0   # keep watching the vehicle (e.g. after killing the gcs)
    after_gcs_exit_until: Callable[[Run], bool] | None = None
    keep_up_raw: bool = False


@dataclass
class Run:
    """A flight in progress (what an action sees)."""

    spec: Spec
    proxy: MitmProxy
    gcs: subprocess.Popen
    sitl: subprocess.Popen | None
    t0: float
    notes: list[str] = field(default_factory=list)
    state: dict = field(default_factory=dict)
    gcs_killed: bool = False
    sitl_killed: bool = False

    @property
    def monitor(self):
        return self.proxy.monitor

    def armed_for_s(self) -> float | None:
        """Wall seconds since the vehicle first reported armed (None before)."""
        t = self.monitor.armed_at_wall
        return None if t is None else time.monotonic() - t

    def note(self, text: str) -> None:
        self.notes.append(f"{time.monotonic() - self.t0:6.2f} s {text}")


@dataclass
class Outcome:
    spec: Spec
    rc: int | None
    summary: dict | None
    gcs_stdout: str
    gcs_stderr: str
    sitl_rc: int | None
    sitl_stderr: str
    wall_s: float
    timed_out: bool
    monitor: dict
    proxy: dict
    log_path: str
    log_info_rc: int | None
    log_info_out: str
    notes: list[str]
    gcs_killed: bool
    sitl_killed: bool
    proxy_error: str | None
    clobber_requests: int = 0
    workdir: str = ""

    @property
    def events(self) -> list[str]:
        return [e.get("text", "") for e in (self.summary or {}).get("events", [])]

    @property
    def exit_reason(self) -> str | None:
        return (self.summary or {}).get("exit_reason")

    def last_stderr_line(self) -> str:
        lines = [ln for ln in self.gcs_stderr.splitlines() if ln.strip()]
        return lines[-1] if lines else ""

    def line(self) -> str:
        m = self.monitor
        return (f"rc={self.rc} reason={self.exit_reason} wall={self.wall_s:.1f}s "
                f"injected={self.proxy['injected_bytes']}B mutated={self.proxy['mutated_bytes']}B "
                f"vehicle: armed={m['armed']} alt={fmt(m['altitude_m'])} max_alt={fmt(m['max_altitude_m'])} "
                f"cmds={m['commands_checked']} violations={len(m['violations'])} "
                f"| {self.last_stderr_line()[:160]}")
