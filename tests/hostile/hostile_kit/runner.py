"""One flight through the proxy: the proxy, ``gcs fly --connect udpin:...``, ``sitl --udp ...``, the
spec's action while it flies, and the :class:`Outcome`."""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import subprocess
import time
import traceback
from pathlib import Path

from mitm import MitmProxy, StreamClobberer

from .procs import free_udp_port, gcs_command, python_env, sitl_command, sitl_supports, stop_process, tail, \
    udp_port_bound
from .spec import Outcome, Run, Spec


def run_flight(spec: Spec, workdir: Path) -> Outcome:
    """Fly ``spec`` in ``workdir`` (the processes' output, summary, log and keys go there)."""
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    proxy = MitmProxy(spec.faults, seed=spec.proxy_seed)
    proxy.monitor.keep_up_raw = spec.keep_up_raw
    proxy.start()
    flight = _Flight(spec, workdir, proxy)
    with open(workdir / "gcs.out", "wb") as gout, open(workdir / "gcs.err", "wb") as gerr, \
            open(workdir / "sitl.err", "wb") as serr:
        try:
            flight.launch(gout, gerr, serr)
            flight.watch()
        finally:
            flight.teardown()
    return flight.outcome()


class _Flight:
    """The processes and the second client of one flight, from the launch to the outcome."""

    def __init__(self, spec: Spec, workdir: Path, proxy: MitmProxy) -> None:
        self.spec, self.workdir, self.proxy = spec, workdir, proxy
        self.t0 = time.monotonic()
        self.wall = 0.0
        self.timed_out = False
        self.gcs: subprocess.Popen | None = None
        self.sitl: subprocess.Popen | None = None
        self.clob: StreamClobberer | None = None
        self.run: Run | None = None

    def launch(self, gout, gerr, serr) -> None:
        """``gcs fly`` first (until it listens), then the SITL, then the second client if any."""
        spec, workdir = self.spec, self.workdir
        port = free_udp_port()
        self.proxy.gcs_addr = ("127.0.0.1", port)
        self.gcs = subprocess.Popen(gcs_command(spec, port, workdir), cwd=workdir, stdin=subprocess.DEVNULL,
                                    stdout=gout, stderr=gerr, env=python_env())
        end = time.monotonic() + 15.0
        while time.monotonic() < end and self.gcs.poll() is None and not udp_port_bound(port):
            time.sleep(0.02)
        # The second client gets an endpoint of its own when the SITL has more than one (as MAVProxy on
        # another of the autopilot's links); else it talks to the SITL's one socket from its own address.
        second = (free_udp_port() if spec.clobber == "own_endpoint" and sitl_supports("any number, combined")
                  else None)
        self.sitl = subprocess.Popen(sitl_command(spec, self.proxy.vehicle_port, workdir, second), cwd=workdir,
                                     stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=serr,
                                     env=python_env())
        self.run = Run(spec, self.proxy, self.gcs, self.sitl, self.t0)
        if spec.clobber:
            self._start_clobberer(second)

    def _start_clobberer(self, second: int | None) -> None:
        shared = self.spec.clobber == "shared_link"
        self.clob = StreamClobberer(self.proxy, target=None if second is None else ("127.0.0.1", second),
                                    shared_link=shared).start()
        self.run.note("second client -> " + ("the ground station's link" if shared else
                                             f"its own endpoint udp-listen {second}" if second else
                                             "the sitl's socket, from its own address"))

    def watch(self) -> None:
        """The action every 20 ms until the ground station exits (killed at its deadline: a hang), then
        the vehicle watched on for ``after_gcs_exit_wait_s``."""
        spec, gcs, run = self.spec, self.gcs, self.run
        deadline = self.t0 + spec.timeout_s
        while gcs.poll() is None:
            if time.monotonic() > deadline:
                self.timed_out = True
                run.note("ground station overran its deadline: killed (a hang)")
                with contextlib.suppress(ProcessLookupError):
                    os.kill(gcs.pid, signal.SIGCONT)
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

    def teardown(self) -> None:
        self.wall = time.monotonic() - self.t0
        if self.clob is not None:
            self.clob.stop()
        if self.gcs is not None and self.gcs.poll() is None:
            stop_process(self.gcs)
        stop_process(self.sitl)
        self.proxy.stop()

    def outcome(self) -> Outcome:
        workdir, proxy, run, sitl = self.workdir, self.proxy, self.run, self.sitl
        summary = None
        with contextlib.suppress(OSError, ValueError):
            summary = json.loads((workdir / "summary.json").read_text())
        log_path = workdir / "flight.mcap"
        info_rc, info_out = log_info(log_path) if log_path.exists() else (None, "")
        return Outcome(
            spec=self.spec, rc=None if self.timed_out else self.gcs.returncode, summary=summary,
            gcs_stdout=tail(workdir / "gcs.out"), gcs_stderr=tail(workdir / "gcs.err"),
            sitl_rc=None if sitl is None else sitl.returncode, sitl_stderr=tail(workdir / "sitl.err"),
            wall_s=self.wall, timed_out=self.timed_out, monitor=proxy.monitor.snapshot(), proxy=proxy.stats(),
            log_path=str(log_path), log_info_rc=info_rc, log_info_out=info_out,
            notes=run.notes if run else [], gcs_killed=bool(run and run.gcs_killed),
            sitl_killed=bool(run and run.sitl_killed),
            proxy_error=None if proxy.error is None else (proxy.error_text or repr(proxy.error))[-1500:],
            clobber_requests=self.clob.requests if self.clob else 0, workdir=str(workdir))


def log_info(path: Path) -> tuple[int, str]:
    """``gcs log info PATH`` (in this process: the same code as the command, without an interpreter
    start per flight); its exit code and output."""
    from gcs.cli import main

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
        try:
            rc = main(["log", "info", str(path)])
        except SystemExit as exc:
            rc = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        except Exception:  # noqa: BLE001 - a crash of the reader is a finding, not a harness error
            buf.write("Traceback (in-process gcs log info):\n" + traceback.format_exc())
            rc = 1
    return (0 if rc is None else int(rc)), buf.getvalue()[-4000:]
