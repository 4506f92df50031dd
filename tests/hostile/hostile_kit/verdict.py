"""The acceptance rules of the hostile-link issue: :func:`problems` lists every rule a flight broke,
:func:`report` turns the list into an assertion message, :data:`REGISTRY` collects every flight for the
session report (conftest prints it).

The documented exit codes (README "Failsafes and exit codes"): 0 completed, 2 bad config or
option, 3 telemetry lost, 4 geofence, 5 interrupted, 6 link error, 7 preflight refused,
8 immediate land, 9 the vehicle left guided control, 10 unsafe command, 11 internal error,
12 telemetry too slow.
"""

from __future__ import annotations

import re
import signal

from gcs.config import load_config

from .spec import Outcome, fmt

EXIT_CODES = {"completed": 0, "bad_config": 2, "telemetry_lost": 3, "geofence": 4, "interrupted": 5,
              "link_error": 6, "preflight_refused": 7, "immediate_land": 8, "vehicle_took_over": 9,
              "unsafe_command": 10, "internal_error": 11, "telemetry_slow": 12, "out_of_authority": 13}
DOCUMENTED_CODES = set(EXIT_CODES.values())
#: Every flight of the session: (test id, what was injected, the outcome in one line); conftest prints it.
REGISTRY: list[dict] = []
#: On the ground: altitude above the takeoff point below this [m].
GROUND_M = 0.25
CHANGED_RE = re.compile(r"^(GUID_OPTIONS|ATC_ANGLE_BOOST) \S+ -> \S+")


def problems(o: Outcome, *, expect_complete: bool = False, allowed: set[int] | None = None,
             check_log: bool = True, vehicle_must_land: bool = True) -> list[str]:
    """Every acceptance rule ``o`` breaks (empty: the flight is acceptable)."""
    out: list[str] = []
    m = o.monitor
    if o.proxy_error:
        out.append(f"harness: the proxy failed: {o.proxy_error}")
    # --- no hang, no traceback
    if o.timed_out:
        out.append(f"hang: gcs fly still running after {o.spec.timeout_s:g} s (killed)")
    if "Traceback" in o.gcs_stderr or "Traceback" in o.gcs_stdout:
        tb = (o.gcs_stderr if "Traceback" in o.gcs_stderr else o.gcs_stdout)
        out.append("traceback in gcs fly: " + tb[tb.index("Traceback"):].strip().splitlines()[-1][:300])
    if "Traceback" in o.sitl_stderr:
        out.append("traceback in sitl: "
                   + o.sitl_stderr[o.sitl_stderr.index("Traceback"):].strip().splitlines()[-1][:300])
    if not o.sitl_killed and o.sitl_rc not in (0, None, -signal.SIGINT):
        out.append(f"sitl exited with {o.sitl_rc} on SIGINT: {o.sitl_stderr.strip().splitlines()[-1:]}")
    # --- the exit code: documented, in the summary, one line of reason
    if not o.timed_out and not o.gcs_killed:
        if o.rc not in DOCUMENTED_CODES:
            out.append(f"exit code {o.rc} is not a documented one ({sorted(DOCUMENTED_CODES)}); "
                       f"stderr: {o.last_stderr_line()[:200]!r}")
        if o.summary is None:
            out.append("no --summary written")
        else:
            if o.summary.get("exit_code") != o.rc:
                out.append(f"summary exit_code {o.summary.get('exit_code')} != process exit code {o.rc}")
            reason = o.summary.get("exit_reason")
            if EXIT_CODES.get(reason) != o.rc:
                out.append(f"summary exit_reason {reason!r} does not match exit code {o.rc}")
        if o.rc not in (0, None):
            last = o.last_stderr_line()
            if not re.match(rf"^gcs fly: \w+ \(exit {o.rc}\)", last):
                out.append(f"exit {o.rc} without its one-line reason 'gcs fly: <reason> (exit {o.rc}): ...' "
                           f"as the last line of stderr (got {last[:200]!r})")
        if allowed is not None and o.rc not in allowed:
            out.append(f"exit code {o.rc} ({o.exit_reason}) not among the acceptable {sorted(allowed)}: "
                       f"{o.last_stderr_line()[:200]!r}")
        if expect_complete and o.rc != 0:
            out.append(f"the flight did not complete: exit {o.rc} ({o.exit_reason}): {o.last_stderr_line()[:200]!r}")
    # --- the wire: commands sane
    bad = [v for v in m["violations"] if not v.startswith("vehicle:")]
    if bad:
        out.append(f"{len(bad)} non-finite / out-of-limit commands from gcs on the wire, first: {bad[0]}")
    vbad = [v for v in m["violations"] if v.startswith("vehicle:")]
    if vbad:
        out.append(f"the vehicle's own telemetry went non-finite: {vbad[0]}")
    # --- an armed flight ends landed and disarmed, parameters restored
    ev = o.events
    armed = m["ever_armed"] or any(e == "armed" for e in ev)
    if armed and vehicle_must_land and not o.sitl_killed:
        if m["armed"] is not False:
            out.append(f"the vehicle is still armed at the end (last HEARTBEAT armed={m['armed']}, "
                       f"altitude {fmt(m['altitude_m'])} m)")
        alt = m["altitude_m"]
        if alt is None or alt > GROUND_M:
            out.append(f"the vehicle is not on the ground at the end (altitude {fmt(alt)} m above takeoff)")
        if not o.gcs_killed and "landed and disarmed" not in ev and not (o.rc == 9 and "disarmed" in ev):
            out.append(f"no 'landed and disarmed' event (exit {o.rc}; last events: {ev[-4:]})")
    if not o.gcs_killed:
        for e in ev:
            mm = CHANGED_RE.match(e)
            if not mm:
                continue
            name = mm.group(1)
            if o.sitl_killed:  # the vehicle is gone: the ground station must say it could not restore
                if not any(x.startswith(f"{name} restored") or (name in x and "not restored" in x)
                           or (name in x and "left at its flight value" in x) for x in ev):
                    out.append(f"{name} was changed ({e!r}); the vehicle died, and no event says it was not "
                               "restored")
            elif not any(x.startswith(f"{name} restored") for x in ev):
                out.append(f"{name} was changed ({e!r}) but not restored")
    pf, pl = m["param_first"], m["param_last"]
    for name in ("GUID_OPTIONS", "ATC_ANGLE_BOOST"):
        if name in pf and pl.get(name) != pf[name] and not o.gcs_killed and not o.sitl_killed:
            out.append(f"{name} is {pl.get(name)} on the vehicle at the end, was {pf[name]} before the flight")
    # --- the log
    if check_log:
        if o.log_info_rc is None:
            out.append("no flight log written")
        elif o.log_info_rc != 0:
            out.append(f"'gcs log info' exits {o.log_info_rc}: {o.log_info_out.strip().splitlines()[-1:]}")
    return out


def fence_problems(o: Outcome, config: str = "outdoor-circle") -> list[str]:
    """Ceiling or fence breached (the vehicle's own telemetry, against the config's [flight] limits)."""
    fc = load_config(config).flight
    m = o.monitor
    out = []
    if m["max_altitude_m"] > fc.ceiling_m:
        out.append(f"ceiling breached: {m['max_altitude_m']:.2f} m > {fc.ceiling_m:g} m")
    if m["max_horizontal_m"] > fc.fence_half_width_m:
        out.append(f"fence breached: {m['max_horizontal_m']:.2f} m from takeoff > {fc.fence_half_width_m:g} m")
    return out


def record(nodeid: str, o: Outcome, verdict: list[str]) -> None:
    REGISTRY.append({"test": nodeid, "injected_bytes": o.proxy["injected_bytes"],
                     "mutated_bytes": o.proxy["mutated_bytes"], "faults": o.proxy["faults"], "rc": o.rc,
                     "reason": o.exit_reason, "wall_s": o.wall_s, "problems": verdict,  # the list itself: tests append
                     "line": o.line()})


def report(o: Outcome, verdict: list[str]) -> str:
    """The assertion message: every problem, then what happened."""
    lines = [f"{len(verdict)} acceptance rule(s) broken:"] + [f"  - {v}" for v in verdict]
    lines += [f"outcome: {o.line()}",
              "faults: " + ", ".join(f"{k}: {v['events']} events, {v['injected_bytes']} B injected, "
                                     f"{v['mutated_bytes']} B mutated" for k, v in o.proxy["faults"].items()),
              f"events: {o.events[-12:]}", f"notes: {o.notes}", f"workdir: {o.workdir}",
              "gcs stderr tail:\n    " + "\n    ".join(o.gcs_stderr.strip().splitlines()[-8:])]
    if o.sitl_stderr.strip():
        lines.append("sitl stderr tail:\n    " + "\n    ".join(o.sitl_stderr.strip().splitlines()[-5:]))
    return "\n".join(lines)


def check(request, o: Outcome, **kw) -> list[str]:
    """Record the flight for the session report and return its problems."""
    verdict = problems(o, **kw)
    record(request.node.nodeid, o, verdict)
    return verdict
