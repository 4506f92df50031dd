"""The two processes of a hostile flight: their command lines, ports, configs, and how they are stopped."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .spec import Spec

ROOT = Path(__file__).resolve().parents[3]

_SITL_HELP: list[str] = []


def sitl_supports(text: str) -> bool:
    """``text`` appears in ``sitl --help`` (options that the SITL gained: the suite uses them when there)."""
    if not _SITL_HELP:
        p = subprocess.run([sys.executable, "-m", "sitl.cli", "--help"], capture_output=True, text=True, timeout=60)
        _SITL_HELP.append(p.stdout)
    return text in _SITL_HELP[0]


def free_udp_port() -> int:
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


def python_env() -> dict:
    env = dict(os.environ)
    env.setdefault("PYTHONUNBUFFERED", "1")
    return env


def tail(path: Path, n: int = 20000) -> str:
    """The last ``n`` bytes of a file as text ("" if it cannot be read)."""
    try:
        data = path.read_bytes()
    except OSError:
        return ""
    return data[-n:].decode(errors="replace")


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
    """SIGCONT then SIGINT, and SIGKILL if it is still there after ``timeout_s``."""
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
