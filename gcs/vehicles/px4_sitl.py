"""PX4's own SITL with its built-in simulator SIH (quadrotor X) as the child vehicle of ``gcs fly --sitl px4``.

The firmware is found by ``--px4 PATH`` or the environment variable :data:`ENV_VAR`: a PX4
build folder (``bin/px4`` and ``etc/``), its ``bin/px4`` binary, a ``.tar.gz`` of such a
folder (unpacked once into the user's cache), or a directory holding one such archive.  It
runs headless (``px4 -d``) with airframe 10040 (``sihsim_quadx``) in a fresh working
directory on the first free instance N, and flies over its offboard/API MAVLink link: PX4
listens on UDP 14580 + N and sends to 127.0.0.1:14540 + N (one port per instance, unlike its
GCS link, which always sends to 14550).  ``speedup`` sets PX4_SIM_SPEED_FACTOR: SIH then runs
its simulated time that much faster than the wall, as far as the machine keeps up (the flight
runs on the vehicle's clock, its telemetry time stamps).
"""

from __future__ import annotations

import hashlib
import math
import os
import shutil
import socket
import subprocess
import tarfile
import tempfile
import time
from pathlib import Path

from gcs.link.mavlink import LinkError
from gcs.vehicles.firmware_child import FirmwareChild

__all__ = ["ENV_VAR", "Px4Sitl", "find_px4", "locate_px4", "MAX_INSTANCE"]

#: Environment variable naming the PX4 SITL build (folder, binary or archive).
ENV_VAR = "GCS_PX4"
#: Highest instance with its own offboard port (PX4 sends to 14549 for every instance above 9).
MAX_INSTANCE = 9
#: The airframe: SIH quadrotor X.
AIRFRAME = "10040"


def _cache_dir() -> Path:
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "gcs"


def _unpack(archive: Path) -> Path:
    """A PX4 build archive unpacked once into the cache (keyed by its content's hash)."""
    h = hashlib.sha256()
    with open(archive, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    dest = _cache_dir() / f"px4-{h.hexdigest()[:12]}"
    if (dest / "bin" / "px4").is_file():
        return dest
    _cache_dir().mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix="px4-unpack-", dir=_cache_dir()))
    try:
        with tarfile.open(archive) as tar:
            tar.extractall(tmp, filter="data")
        root = tmp if (tmp / "bin").is_dir() else next((d for d in tmp.iterdir() if (d / "bin").is_dir()), tmp)
        try:
            root.rename(dest)
        except OSError:
            if not (dest / "bin" / "px4").is_file():
                raise
    except (OSError, tarfile.TarError) as exc:
        raise LinkError(f"cannot unpack the PX4 build {archive}: {exc}") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return dest


def find_px4(path: str | os.PathLike | None) -> Path:
    """The PX4 build folder (holding ``bin/px4`` and ``etc/``) from ``path`` or :data:`ENV_VAR`.

    Raises
    ------
    LinkError
        Neither given, or nothing runnable there (the message says where it looked).
    """
    given = path if path is not None else os.environ.get(ENV_VAR)
    if not given:
        raise LinkError(f"no PX4 SITL: give --px4 PATH or set {ENV_VAR} (a px4_sitl_default build folder with bin/px4 "
                        "and etc/, its bin/px4, or a .tar.gz of it)")
    p = Path(given).expanduser()
    if p.is_dir() and not (p / "bin" / "px4").exists():
        archives = sorted(p.glob("*.tar.gz"))
        if len(archives) == 1:
            p = archives[0]
    if p.is_file() and p.name.endswith((".tar.gz", ".tgz")):
        p = _unpack(p)
    elif p.is_file() and p.name == "px4":
        p = p.parent.parent
    binary = p / "bin" / "px4"
    if not (binary.is_file() and os.access(binary, os.X_OK) and (p / "etc" / "init.d-posix").is_dir()):
        raise LinkError(f"{p}: not a PX4 SITL build (bin/px4 and etc/init.d-posix expected; from "
                        f"{'--px4' if path else ENV_VAR})")
    return p.resolve()


def locate_px4(*fallbacks: str | os.PathLike) -> str | None:
    """The build as :func:`find_px4` finds it from :data:`ENV_VAR`, else from the first of ``fallbacks``
    that holds one; None without one (tests and benchmarks skip then)."""
    for candidate in (os.environ.get(ENV_VAR), *fallbacks):
        if not candidate:
            continue
        try:
            return str(find_px4(candidate))
        except LinkError:
            continue
    return None


def _udp_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("0.0.0.0", port))
        except OSError:
            return False
    return True


def free_instance() -> int:
    """The first instance whose ports (PX4's 18570/14580 + N, ours 14540 + N) and lock file are free."""
    for n in range(MAX_INSTANCE + 1):
        lock = Path(f"/tmp/px4_lock-{n}")
        if lock.exists() and _locked(lock):
            continue
        if all(_udp_free(p + n) for p in (18570, 14580, 14540)):
            return n
    raise LinkError(f"no free PX4 SITL instance among 0..{MAX_INSTANCE} (UDP 14540/14580/18570 + N busy)")


def _locked(lock: Path) -> bool:
    """Whether a running PX4 holds ``lock`` (fuser, where present; else assume it does)."""
    fuser = shutil.which("fuser")
    if fuser is None:
        return True
    return subprocess.run([fuser, str(lock)], capture_output=True).returncode == 0


class Px4Sitl(FirmwareChild):
    """One PX4 SITL + SIH child process.

    Parameters
    ----------
    build : path-like or None
        What :func:`find_px4` takes (None: :data:`ENV_VAR`).
    speedup : float
        PX4_SIM_SPEED_FACTOR (1: real time).
    workdir : path-like or None
        Where it runs (None: a new temporary directory, removed by :meth:`stop`).
    params : mapping of str to float, optional
        Parameters set at its start (``PX4_PARAM_<NAME>``, which PX4's rcS applies after the airframe's).
    """

    def __init__(self, build=None, *, speedup: float = 1.0, workdir=None, params=None) -> None:
        if not 0.1 <= speedup <= 50.0:
            raise ValueError(f"speedup must be in 0.1..50, got {speedup!r}")
        self.build = find_px4(build)
        self.binary = self.build / "bin" / "px4"
        self.speedup = float(speedup)
        self.params = {str(k).upper(): float(v) for k, v in (params or {}).items()}
        for name, value in self.params.items():
            if not name.replace("_", "").isalnum() or not math.isfinite(value):
                raise ValueError(f"a PX4 parameter must be NAME=finite number, got {name}={value!r}")
        self._own_dir = workdir is None
        self.workdir = Path(tempfile.mkdtemp(prefix="gcs-px4-") if workdir is None else workdir)
        self.instance: int | None = None
        self.proc: subprocess.Popen | None = None
        self.name = "PX4 SITL"
        self._exit_text: str | None = None

    @property
    def url(self) -> str:
        """Where the ground station listens: PX4's offboard link sends to 127.0.0.1:14540 + N."""
        return f"udpin:127.0.0.1:{14540 + (self.instance or 0)}"

    @property
    def log_path(self) -> Path:
        return self.workdir / "px4.log"

    @property
    def events_path(self) -> Path:
        return self.build / "etc" / "extras" / "all_events.json.xz"

    def environment(self) -> dict[str, str]:
        env = dict(os.environ)
        env.update(PX4_SYS_AUTOSTART=AIRFRAME, PX4_SIM_MODEL="sihsim_quadx", PX4_SIMULATOR="sihsim",
                   PX4_SIM_SPEED_FACTOR=f"{self.speedup:g}")
        env.update({f"PX4_PARAM_{name}": f"{value:g}" for name, value in self.params.items()})
        return env

    def command(self) -> list[str]:
        return [str(self.binary), "-d", "-i", str(self.instance), "-w", str(self.workdir), str(self.build / "etc")]

    def start(self, timeout_s: float = 30.0) -> Px4Sitl:
        """Start it and wait until its startup script has run.

        Raises
        ------
        LinkError
            It cannot start, exits, or does not finish starting within ``timeout_s`` (with its last log line).
        """
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.instance = free_instance()
        log = open(self.log_path, "wb")  # noqa: SIM115  the child writes it for its whole life
        try:
            # Its own session: a Ctrl-C at the terminal reaches the ground station, which lands first.
            self.proc = subprocess.Popen(self.command(), cwd=self.workdir, env=self.environment(),
                                         stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                         start_new_session=True)
        except OSError as exc:
            raise LinkError(f"cannot start {self.name} ({self.binary}): {exc}") from None
        finally:
            log.close()
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            why = self.exit_reason()
            if why is not None:
                raise LinkError(why)
            if b"Startup script returned" in self.log_path.read_bytes()[-65536:]:
                return self
            time.sleep(0.05)
        self.stop()
        raise LinkError(f"{self.name} did not finish starting within {timeout_s:g} s ({self._last_log_line()})")

    def stop(self, timeout_s: float = 5.0, keep_workdir: bool = False) -> None:
        self._stop_process(timeout_s)
        if self.instance is not None:
            for leftover in (f"/tmp/px4_lock-{self.instance}", f"/tmp/px4-sock-{self.instance}"):
                try:
                    os.unlink(leftover)
                except OSError:
                    pass
        if self._own_dir and not keep_workdir:
            shutil.rmtree(self.workdir, ignore_errors=True)

    def __enter__(self) -> Px4Sitl:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
