"""Helpers of the ground-station client tests: the built-in SITL as a subprocess (real time or faster).

The SITL runs from this checkout (``SITL_CLIENTS_PATH`` overrides the source tree, e.g. an older
commit's clone to compare), on a free TCP port, with ``--parent-pid`` so it ends with pytest even
if a test is killed; the fixture terminates (then kills) it in any case.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
START_TIMEOUT_S = 60.0


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=15)


#: Flights (take-off, hold, RTL, missions) run this much faster than real time (``sitl --speedup``);
#: the clients' own timeouts are wall-clock and generous.
FLIGHT_SPEEDUP = 4.0


def start_sitl(*extra: str):
    """Start the SITL (``--tcp 127.0.0.1:PORT`` + ``extra``); yields PORT once it listens."""
    src = os.environ.get("SITL_CLIENTS_PATH", str(ROOT))
    port = free_port()
    env = dict(os.environ, PYTHONPATH=src, PYTHONUNBUFFERED="1")
    cmd = [sys.executable, "-c", "import sys; from sitl.cli import main; sys.exit(main())",
           "--tcp", f"127.0.0.1:{port}", "--parent-pid", str(os.getpid()), *extra]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env,
                            text=True, cwd=src)
    try:
        ready = threading.Event()
        threading.Thread(target=lambda: (proc.stdout.readline(), ready.set()), daemon=True).start()
        assert ready.wait(START_TIMEOUT_S), "the SITL printed no endpoint"
        assert proc.poll() is None, "the SITL exited at start"
        yield port
    finally:
        stop(proc)
        proc.stdout.close()
