"""The built-in SITL as a child process, for ``gcs fly`` without ``--port``/``--connect``.

The ground station binds a UDP port first (``udpin:127.0.0.1:0``), then starts
``python -m sitl.cli --udp 127.0.0.1:<that port>`` so the vehicle sends there:
no port race.  The SITL is a separate process, as a real autopilot would be,
so its physics never competes with the 100 Hz loop for the interpreter.
"""

from __future__ import annotations

import os
import selectors
import signal
import subprocess
import sys
import tempfile
from collections.abc import Sequence

from gcs.link.mavlink import LinkError as GcsError  # a dead simulator is a link failure (exit 6)

__all__ = ["EmbeddedSitl", "EmbeddedRig"]


class EmbeddedSitl:
    """A ``sitl`` child process sending to ``127.0.0.1:<gcs_port>``.

    Parameters
    ----------
    gcs_port : int
        The UDP port the ground station listens on.
    lockstep : bool
    seed : int
    extra_args : sequence of str
        More ``sitl`` options (``--wind``, ``--model reduced``, ...).
    """

    def __init__(self, gcs_port: int, *, lockstep: bool, seed: int = 0, extra_args: Sequence[str] = ()) -> None:
        self.args = [sys.executable, "-m", "sitl.cli", "--udp", f"127.0.0.1:{gcs_port}", "--seed", str(seed),
                     "--parent-pid", str(os.getpid()), *(["--lockstep"] if lockstep else []), *extra_args]
        self.proc: subprocess.Popen | None = None
        self.name = "the built-in SITL"
        self._stderr = None
        self._exit_text: str | None = None

    def _spawn(self, stdout) -> None:
        """Start the child; its stderr goes to a temporary file (a pipe nobody reads could fill and
        block it), read once when it exits."""
        self._stderr = tempfile.TemporaryFile()  # noqa: SIM115  read after the child exits, long after this call
        try:
            # Its own process group: a Ctrl-C at the terminal reaches the ground station only,
            # which lands the vehicle before stopping the simulator.
            self.proc = subprocess.Popen(self.args, stdin=subprocess.DEVNULL, stdout=stdout,
                                         stderr=self._stderr, start_new_session=True)
        except OSError as exc:
            raise GcsError(f"cannot start {self.name}: {exc}") from None

    def start(self) -> EmbeddedSitl:
        self._spawn(subprocess.DEVNULL)
        return self

    def exit_reason(self) -> str | None:
        """None while the child runs; once it has exited, why (its exit code and last error line)."""
        if self._exit_text is not None:
            return self._exit_text
        if self.proc is None or self.proc.poll() is None:
            return None
        lines: list[str] = []
        if self._stderr is not None:
            self._stderr.seek(0)
            lines = self._stderr.read()[-4096:].decode(errors="replace").strip().splitlines()
        self._exit_text = (f"{self.name} exited with code {self.proc.returncode}"
                           + (f": {lines[-1].strip()}" if lines else ""))
        return self._exit_text

    def check_alive(self) -> None:
        """Raise if the child died (with its last error line)."""
        why = self.exit_reason()
        if why is not None:
            raise GcsError(why)

    def stop(self, timeout_s: float = 5.0) -> None:
        if self.proc is not None and self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGINT)
                self.proc.wait(timeout_s)
            except (ProcessLookupError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait(timeout_s)
        if self._stderr is not None:
            self._stderr.close()
            self._stderr = None

    def __enter__(self) -> EmbeddedSitl:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


class EmbeddedRig(EmbeddedSitl):
    """The 4-DOF rig emulator (``sitl --rig 4dof``) as a child process on a pseudo-terminal.

    Parameters
    ----------
    lockstep : bool
    seed : int
    baud : int
        Byte-rate limit of the emulated serial line (115200 as the paper's XBee; 0 = none, what
        lockstep uses by default so that it runs faster than real time).
    extra_args : sequence of str
        More ``sitl`` options (``--bit-error-rate``, ``--loss``, ...), after the defaults.

    :attr:`device` is the serial device to open once :meth:`start` returned.
    """

    def __init__(self, *, lockstep: bool, seed: int = 0, baud: int = 115200, extra_args: Sequence[str] = (),
                 start_timeout_s: float = 10.0) -> None:
        self.args = [sys.executable, "-m", "sitl.cli", "--rig", "4dof", "--seed", str(seed), "--baud", str(baud),
                     "--parent-pid", str(os.getpid()), *(["--lockstep"] if lockstep else []), *extra_args]
        self.proc = None
        self.name = "the rig emulator"
        self._stderr = None
        self._exit_text = None
        self.device: str | None = None
        self.start_timeout_s = start_timeout_s

    def start(self) -> EmbeddedRig:
        self._spawn(subprocess.PIPE)
        sel = selectors.DefaultSelector()
        sel.register(self.proc.stdout, selectors.EVENT_READ)  # type: ignore[arg-type]
        ready = sel.select(self.start_timeout_s)
        sel.close()
        line = self.proc.stdout.readline().decode(errors="replace").strip() if ready else ""  # type: ignore[union-attr]
        if not line.startswith("/dev/"):
            self.check_alive()
            self.stop()
            raise GcsError(f"the rig emulator did not report its serial device within {self.start_timeout_s:g} s")
        self.device = line
        return self
