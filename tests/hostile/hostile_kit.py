"""Flights through the hostile proxy: ``gcs fly`` and ``sitl`` as separate processes, and what to check.

:func:`run_flight` starts the proxy (:mod:`mitm`), then ``gcs fly --connect udpin:127.0.0.1:G``
(as a subprocess, output to files), waits until it listens, then ``python -m sitl.cli --udp
127.0.0.1:<proxy> --seed N [--lockstep]``; an optional ``action`` is called every 20 ms while the
flight runs (signals, a second client, ...).  When the ground station has exited (or was killed,
or overran its deadline: a hang), the SITL is stopped with SIGINT and everything is collected in
an :class:`Outcome`.  :func:`problems` lists every broken acceptance rule of the hostile-link
issue; a test asserts that the list is empty, so one failing flight reports all it broke.

The documented exit codes (README "Failsafes and exit codes"): 0 completed, 2 bad config or
option, 3 telemetry lost, 4 geofence, 5 interrupted, 6 link error, 7 preflight refused,
8 immediate land, 9 the vehicle left guided control.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

from mitm import MitmProxy, StreamClobberer

ROOT = Path(__file__).resolve().parents[2]
EXIT_CODES = {"completed": 0, "bad_config": 2, "telemetry_lost": 3, "geofence": 4, "interrupted": 5,
              "link_error": 6, "preflight_refused": 7, "immediate_land": 8, "vehicle_took_over": 9}
DOCUMENTED_CODES = set(EXIT_CODES.values())
#: Every flight of the session: (test id, what was injected, the outcome in one line); conftest prints it.
REGISTRY: list[dict] = []
#: On the ground: altitude above the takeoff point below this [m].
GROUND_M = 0.25
CHANGED_RE = re.compile(r"^(GUID_OPTIONS|ATC_ANGLE_BOOST) \S+ -> \S+")


_SITL_HELP: list[str] = []


def sitl_supports(text: str) -> bool:
    """``text`` appears in ``sitl --help`` (options that the SITL gained: the suite uses them when there)."""
    if not _SITL_HELP:
        p = subprocess.run([sys.executable, "-m", "sitl.cli", "--help"], capture_output=True, text=True, timeout=60)
        _SITL_HELP.append(p.stdout)
    return text in _SITL_HELP[0]


def free_udp_port() -> int:
    import socket

    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def udp_port_bound(port: int) -> bool:
    """Someone has ``port`` bound (read from /proc/net/udp: no probing bind, no race)."""
    needle = f":{port:04X} "
    try:
        with open("/proc/net/udp") as fh:
            return any(needle in line.split(None, 3)[1] + " " for line in fh.readlines()[1:])
    except OSError:
        return False


def flight_config(workdir: Path, base: str = "outdoor-circle", **flight: float) -> str:
    """A copy of a bundled config with ``[flight]`` keys set (e.g. land_timeout_s=10); its path."""
    text = (ROOT / "configs" / f"{base}.toml").read_text()
    if "[flight]" in text:
        raise RuntimeError(f"{base}.toml has a [flight] table already; extend flight_config")
    text += "\n[flight]\n" + "".join(f"{k} = {v!r}\n" for k, v in flight.items())
    path = workdir / f"{base}-hostile.toml"
    path.write_text(text)
    return str(path)


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
    action: Callable[["Run"], None] | None = None
    clobber: str | None = None       # a MAVProxy-like second client (REQUEST_DATA_STREAM ALL 4 Hz every 2 s):
    #   "own_endpoint" (its own sitl endpoint when the sitl has several, else its own address),
    #   "shared_link" (on the ground station's link: the vehicle sees one peer)
    after_gcs_exit_wait_s: float = 0.0   # keep watching the vehicle (e.g. after killing the gcs)
    after_gcs_exit_until: Callable[["Run"], bool] | None = None
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
                f"vehicle: armed={m['armed']} alt={_f(m['altitude_m'])} max_alt={_f(m['max_altitude_m'])} "
                f"cmds={m['commands_checked']} violations={len(m['violations'])} "
                f"| {self.last_stderr_line()[:160]}")


def _f(v) -> str:
    return "-" if v is None else f"{v:.2f}"


def _tail(path: Path, n: int = 20000) -> str:
    try:
        data = path.read_bytes()
    except OSError:
        return ""
    return data[-n:].decode(errors="replace")


def _python_env() -> dict:
    env = dict(os.environ)
    env.setdefault("PYTHONUNBUFFERED", "1")
    return env


def gcs_command(spec: Spec, gcs_port: int, workdir: Path) -> list[str]:
    cmd = [sys.executable, "-m", "gcs.cli", "fly", "--connect", f"udpin:127.0.0.1:{gcs_port}",
           "--config", spec.config, "--controller", spec.controller,
           "--summary", str(workdir / "summary.json"), "--log", str(workdir / "flight.mcap"), "-q"]
    if spec.lockstep:
        cmd.append("--lockstep")
    if spec.duration_s is not None:
        cmd += ["--duration", f"{spec.duration_s:g}"]
    if spec.output:
        cmd += ["--output", spec.output]
    if spec.signing_key:
        key = workdir / "signing.key"
        key.write_text(spec.signing_key + "\n")
        cmd += ["--signing-key", str(key)]
    return cmd + list(spec.gcs_args)


def sitl_command(spec: Spec, vehicle_port: int, workdir: Path, second_port: int | None = None) -> list[str]:
    cmd = [sys.executable, "-m", "sitl.cli", "--udp", f"127.0.0.1:{vehicle_port}", "--seed", str(spec.sitl_seed)]
    if second_port is not None:
        cmd += ["--udp-listen", f"127.0.0.1:{second_port}"]
    if spec.lockstep:
        cmd.append("--lockstep")
    if spec.signing_key:
        cmd += ["--signing-key", spec.signing_key]
        if sitl_supports("--signing-state"):  # this flight's own state, not the user's cache
            cmd += ["--signing-state", str(workdir / "sitl-signing-state.json")]
    return cmd + list(spec.sitl_args)


def stop_process(p: subprocess.Popen | None, timeout_s: float = 5.0) -> None:
    if p is None or p.poll() is not None:
        return
    try:
        os.kill(p.pid, signal.SIGCONT)
        os.kill(p.pid, signal.SIGINT)
        p.wait(timeout_s)
    except (ProcessLookupError, subprocess.TimeoutExpired):
        try:
            p.kill()
            p.wait(timeout_s)
        except (ProcessLookupError, subprocess.TimeoutExpired):
            pass


def run_flight(spec: Spec, workdir: Path) -> Outcome:
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    proxy = MitmProxy(spec.faults, seed=spec.proxy_seed)
    proxy.monitor.keep_up_raw = spec.keep_up_raw
    proxy.start()
    gcs = sitl = None
    clob = None
    t0 = time.monotonic()
    timed_out = False
    gout = open(workdir / "gcs.out", "wb")
    gerr = open(workdir / "gcs.err", "wb")
    serr = open(workdir / "sitl.err", "wb")
    run = None
    try:
        port = free_udp_port()
        proxy.gcs_addr = ("127.0.0.1", port)
        gcs = subprocess.Popen(gcs_command(spec, port, workdir), cwd=workdir, stdin=subprocess.DEVNULL, stdout=gout,
                               stderr=gerr, env=_python_env())
        end = time.monotonic() + 15.0
        while time.monotonic() < end and gcs.poll() is None and not udp_port_bound(port):
            time.sleep(0.02)
        # The second client gets an endpoint of its own when the SITL has more than one (as MAVProxy on
        # another of the autopilot's links); else it talks to the SITL's one socket from its own address.
        second = (free_udp_port() if spec.clobber == "own_endpoint" and sitl_supports("any number, combined")
                  else None)
        sitl = subprocess.Popen(sitl_command(spec, proxy.vehicle_port, workdir, second), cwd=workdir,
                                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=serr, env=_python_env())
        run = Run(spec, proxy, gcs, sitl, t0)
        if spec.clobber:
            clob = StreamClobberer(proxy, target=None if second is None else ("127.0.0.1", second),
                                   shared_link=spec.clobber == "shared_link").start()
            run.note("second client -> " + ("the ground station's link" if spec.clobber == "shared_link" else
                                            f"its own endpoint udp-listen {second}" if second else
                                            "the sitl's socket, from its own address"))
        deadline = t0 + spec.timeout_s
        while gcs.poll() is None:
            if time.monotonic() > deadline:
                timed_out = True
                run.note("ground station overran its deadline: killed (a hang)")
                try:
                    os.kill(gcs.pid, signal.SIGCONT)
                except ProcessLookupError:
                    pass
                gcs.kill()
                gcs.wait(10)
                break
            if spec.action is not None:
                spec.action(run)
            time.sleep(0.02)
        if spec.after_gcs_exit_wait_s > 0:
            end = time.monotonic() + spec.after_gcs_exit_wait_s
            while time.monotonic() < end:
                if spec.after_gcs_exit_until is not None and spec.after_gcs_exit_until(run):
                    break
                if spec.action is not None:
                    spec.action(run)
                time.sleep(0.05)
    finally:
        wall = time.monotonic() - t0
        if clob is not None:
            clob.stop()
        if gcs is not None and gcs.poll() is None:
            stop_process(gcs)
        stop_process(sitl)
        proxy.stop()
        for fh in (gout, gerr, serr):
            fh.close()
    summary = None
    try:
        summary = json.loads((workdir / "summary.json").read_text())
    except (OSError, ValueError):
        pass
    log_path = workdir / "flight.mcap"
    info_rc, info_out = None, ""
    if log_path.exists():
        info_rc, info_out = log_info(log_path)
    out = Outcome(spec=spec, rc=None if timed_out else gcs.returncode, summary=summary,
                  gcs_stdout=_tail(workdir / "gcs.out"), gcs_stderr=_tail(workdir / "gcs.err"),
                  sitl_rc=None if sitl is None else sitl.returncode, sitl_stderr=_tail(workdir / "sitl.err"),
                  wall_s=wall, timed_out=timed_out, monitor=proxy.monitor.snapshot(), proxy=proxy.stats(),
                  log_path=str(log_path), log_info_rc=info_rc, log_info_out=info_out,
                  notes=run.notes if run else [], gcs_killed=bool(run and run.gcs_killed),
                  sitl_killed=bool(run and run.sitl_killed),
                  proxy_error=None if proxy.error is None else (proxy.error_text or repr(proxy.error))[-1500:],
                  clobber_requests=clob.requests if clob else 0, workdir=str(workdir))
    return out


def log_info(path: Path) -> tuple[int, str]:
    """``gcs log info PATH`` (in this process: the same code as the command, without an interpreter
    start per flight); its exit code and output."""
    import contextlib
    import io

    from gcs.cli import main

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
        try:
            rc = main(["log", "info", str(path)])
        except SystemExit as exc:
            rc = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        except Exception:  # noqa: BLE001 - a crash of the reader is a finding, not a harness error
            import traceback

            buf.write("Traceback (in-process gcs log info):\n" + traceback.format_exc())
            rc = 1
    return (0 if rc is None else int(rc)), buf.getvalue()[-4000:]


# ----------------------------------------------------------------------------- actions
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
                     f"(vehicle altitude {_f(run.monitor.altitude_m())} m)")
            if sig == signal.SIGKILL:
                if target == "gcs":
                    run.gcs_killed = True
                else:
                    run.sitl_killed = True
        if cont_after_s is not None and "sent" in st and "cont" not in st and time.monotonic() - st["sent"] >= cont_after_s:
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


# ----------------------------------------------------------------------------- acceptance
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
        out.append("traceback in sitl: " + o.sitl_stderr[o.sitl_stderr.index("Traceback"):].strip().splitlines()[-1][:300])
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
                       f"altitude {_f(m['altitude_m'])} m)")
        alt = m["altitude_m"]
        if alt is None or alt > GROUND_M:
            out.append(f"the vehicle is not on the ground at the end (altitude {_f(alt)} m above takeoff)")
        if not o.gcs_killed:
            if "landed and disarmed" not in ev and not (o.rc == 9 and "disarmed" in ev):
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
    from gcs.config import load_config

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
