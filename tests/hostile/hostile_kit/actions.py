"""Actions a hostile test runs every 20 ms while the flight flies (signals to either process), and
what "the vehicle is down" means."""

from __future__ import annotations

import os
import signal
import time

from .spec import Run, fmt
from .verdict import GROUND_M


def signal_after_armed(target: str, sig: int, after_s: float, cont_after_s: float | None = None):
    """An action: ``after_s`` wall seconds after the vehicle first reported armed, send ``sig`` to
    ``target`` ("gcs" or "sitl"); with ``cont_after_s``, SIGCONT that much later."""
    def action(run: Run) -> None:
        st = run.state
        armed = run.armed_for_s()
        if armed is None:
            return
        proc = run.gcs if target == "gcs" else run.sitl
        if "sent" not in st and armed >= after_s:
            st["sent"] = time.monotonic()
            try:
                os.kill(proc.pid, sig)
            except ProcessLookupError:
                return
            run.note(f"{signal.Signals(sig).name} to {target} {armed:.2f} s after arming "
                     f"(vehicle altitude {fmt(run.monitor.altitude_m())} m)")
            if sig == signal.SIGKILL:
                if target == "gcs":
                    run.gcs_killed = True
                else:
                    run.sitl_killed = True
        if (cont_after_s is not None and "sent" in st and "cont" not in st
                and time.monotonic() - st["sent"] >= cont_after_s):
            st["cont"] = time.monotonic()
            try:
                os.kill(proc.pid, signal.SIGCONT)
            except ProcessLookupError:
                return
            run.note(f"SIGCONT to {target}")
    return action


def vehicle_down(run: Run) -> bool:
    """The vehicle reports disarmed, on the ground."""
    m = run.monitor
    alt = m.altitude_m()
    return m.armed is False and alt is not None and alt < GROUND_M
