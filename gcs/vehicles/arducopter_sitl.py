"""ArduPilot's own ArduCopter SITL (the real C++ firmware) as the child vehicle of ``gcs fly --sitl arducopter``.

The firmware is found by ``--arducopter PATH`` or the environment variable
:data:`ENV_VAR`: the ``arducopter`` binary, or a directory holding it.  Defaults files next to
the binary (``copter.parm``, and ``frame-<model>.parm`` for the frame) are passed with
``--defaults``, as ArduPilot's own ``sim_vehicle.py`` does.  It runs in a fresh working
directory (its ``eeprom.bin`` wiped with ``-w``, its own log in ``arducopter.log``) on the
first free instance ``-I N``; its SERIAL0 is ``tcp:127.0.0.1:5760 + 10 N``, where it waits
for the ground station before it starts its clock.  ``--speedup S`` runs its simulated time S
times faster than the wall: the flight then runs on the vehicle's clock (its telemetry time
stamps), see :class:`gcs.flight.clock.PacedVehicleClock`.

The firmware exits by itself when its parent (this process) is gone; :meth:`ArduCopterSitl.stop`
stops it with SIGTERM (SIGKILL after a timeout) and removes the working directory unless asked
to keep it.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import tempfile
import time
from pathlib import Path

from gcs.link.mavlink import LinkError
from gcs.vehicles.firmware_child import FirmwareChild

__all__ = ["ENV_VAR", "HOME", "ArduCopterSitl", "find_arducopter", "locate_arducopter"]

#: Environment variable naming the ArduCopter SITL binary (or its directory).
ENV_VAR = "GCS_ARDUCOPTER"
#: ArduPilot's SITL home (CMAC, Canberra): lat, lon, altitude [m], heading [deg].
HOME = "-35.363261,149.165230,584,353"
#: SITL instances probed for a free port.
MAX_INSTANCES = 40


def find_arducopter(path: str | os.PathLike | None) -> Path:
    """The ArduCopter SITL binary from ``path`` or :data:`ENV_VAR`.

    Raises
    ------
    LinkError
        Neither given, or no executable ``arducopter`` there (the message says where it looked).
    """
    given = path if path is not None else os.environ.get(ENV_VAR)
    if not given:
        raise LinkError(f"no ArduCopter SITL binary: give --arducopter PATH or set {ENV_VAR} (the 'arducopter' "
                        "binary built with ./waf copter --board sitl, or its directory)")
    p = Path(given).expanduser()
    if p.is_dir():
        p = p / "arducopter"
    if not (p.is_file() and os.access(p, os.X_OK)):
        raise LinkError(f"{p}: not an executable ArduCopter SITL binary (from {'--arducopter' if path else ENV_VAR})")
    return p.resolve()


def locate_arducopter(*fallbacks: str | os.PathLike) -> str | None:
    """The binary as :func:`find_arducopter` finds it from :data:`ENV_VAR`, else the first of ``fallbacks``
    that holds one (as a string); None without one (tests and benchmarks skip then)."""
    for candidate in (os.environ.get(ENV_VAR), *fallbacks):
        if not candidate:
            continue
        try:
            return str(find_arducopter(candidate))
        except LinkError:
            continue
    return None


def _port_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def free_instance() -> int:
    """The first SITL instance whose TCP ports (SERIAL0..2: 5760/5762/5763 + 10 N) are free."""
    for n in range(MAX_INSTANCES):
        base = 5760 + 10 * n
        if all(_port_free(base + k) for k in (0, 2, 3)):
            return n
    raise LinkError(f"no free ArduCopter SITL instance among the first {MAX_INSTANCES} (TCP 5760 + 10 N busy)")


class ArduCopterSitl(FirmwareChild):
    """One ArduCopter SITL child process.

    Parameters
    ----------
    binary : path-like or None
        The binary or its directory (None: :data:`ENV_VAR`).
    speedup : float
        Simulated seconds per wall second (``--speedup``).
    model : str
        ArduPilot's frame model (``x``, ``quad`` = + frame, ...; ``x:/path/frame.json`` with the frame's
        values, e.g. its mass, from a JSON file).
    workdir : path-like or None
        Where it runs (None: a new temporary directory, removed by :meth:`stop`).
    defaults : sequence of path-like or None
        ``--defaults`` files (None: ``copter.parm`` and ``frame-<model>.parm`` next to the binary, those present).
    """

    def __init__(self, binary=None, *, speedup: float = 1.0, model: str = "x", workdir=None, defaults=None) -> None:
        if not 0.1 <= speedup <= 100.0:
            raise ValueError(f"speedup must be in 0.1..100, got {speedup!r}")
        self.binary = find_arducopter(binary)
        self.speedup = float(speedup)
        self.model = model
        self._own_dir = workdir is None
        self.workdir = Path(tempfile.mkdtemp(prefix="gcs-arducopter-") if workdir is None else workdir)
        if defaults is None:
            here = self.binary.parent
            frame = model.split(":", 1)[0]  # "x:frame.json": the X frame with a JSON file's values
            defaults = [p for p in (here / "copter.parm", here / f"frame-{frame}.parm") if p.is_file()]
        self.defaults = [Path(d) for d in defaults]
        self.instance: int | None = None
        self.proc: subprocess.Popen | None = None
        self.name = "ArduCopter SITL"
        self._exit_text: str | None = None

    @property
    def url(self) -> str:
        return f"tcp:127.0.0.1:{5760 + 10 * (self.instance or 0)}"

    @property
    def log_path(self) -> Path:
        return self.workdir / "arducopter.log"

    def command(self) -> list[str]:
        args = [str(self.binary), "--model", self.model, "--speedup", f"{self.speedup:g}", f"-I{self.instance}",
                "-w", "--home", HOME]
        if self.defaults:
            args += ["--defaults", ",".join(str(d) for d in self.defaults)]
        return args

    def start(self, timeout_s: float = 20.0) -> ArduCopterSitl:
        """Start it and wait until it listens on its SERIAL0 port.

        Raises
        ------
        LinkError
            It cannot start, exits, or does not listen within ``timeout_s`` (with its last log line).
        """
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.instance = free_instance()
        log = open(self.log_path, "wb")  # noqa: SIM115  the child writes it for its whole life
        try:
            # Its own session: a Ctrl-C at the terminal reaches the ground station, which lands first.
            self.proc = subprocess.Popen(self.command(), cwd=self.workdir, stdin=subprocess.DEVNULL, stdout=log,
                                         stderr=subprocess.STDOUT, start_new_session=True)
        except OSError as exc:
            raise LinkError(f"cannot start {self.name} ({self.binary}): {exc}") from None
        finally:
            log.close()
        port = 5760 + 10 * self.instance
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            why = self.exit_reason()
            if why is not None:
                raise LinkError(why)
            text = self.log_path.read_bytes()[-8192:].decode(errors="replace")
            if "Waiting for connection" in text or f"bind port {port}" in text:
                return self
            time.sleep(0.05)
        self.stop()
        raise LinkError(f"{self.name} did not listen on tcp 127.0.0.1:{port} within {timeout_s:g} s")

    def stop(self, timeout_s: float = 5.0, keep_workdir: bool = False) -> None:
        self._stop_process(timeout_s)
        if self._own_dir and not keep_workdir:
            shutil.rmtree(self.workdir, ignore_errors=True)

    def __enter__(self) -> ArduCopterSitl:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
