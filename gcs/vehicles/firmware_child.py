"""What the firmware launchers (:mod:`gcs.vehicles.arducopter_sitl`, :mod:`gcs.vehicles.px4_sitl`) share:
a child process in its own process group writing one log file, its exit put in words, its stop."""

from __future__ import annotations

import os
import signal
import subprocess
from pathlib import Path

from gcs.link.mavlink import LinkError

__all__ = ["FirmwareChild"]


class FirmwareChild:
    """Mixin of a launcher with ``name`` (str), ``proc`` (Popen or None, started with
    ``start_new_session=True``), ``log_path`` (Path) and ``_exit_text`` (str or None, initially None)."""

    name: str
    proc: subprocess.Popen | None
    _exit_text: str | None
    log_path: Path

    def _last_log_line(self) -> str:
        try:
            lines = self.log_path.read_bytes()[-4096:].decode(errors="replace").strip().splitlines()
        except OSError:
            return ""
        return lines[-1].strip() if lines else ""

    def exit_reason(self) -> str | None:
        """None while it runs; once it has exited, its exit code and last log line."""
        if self._exit_text is not None:
            return self._exit_text
        if self.proc is None or self.proc.poll() is None:
            return None
        last = self._last_log_line()
        self._exit_text = f"{self.name} exited with code {self.proc.returncode}" + (f": {last}" if last else "")
        return self._exit_text

    def check_alive(self) -> None:
        """Raises :class:`~gcs.link.mavlink.LinkError` with :meth:`exit_reason` once it has exited."""
        why = self.exit_reason()
        if why is not None:
            raise LinkError(why)

    def _stop_process(self, timeout_s: float) -> None:
        """SIGTERM to its process group, SIGKILL after ``timeout_s`` [s]."""
        if self.proc is None or self.proc.poll() is not None:
            return
        try:
            os.killpg(self.proc.pid, signal.SIGTERM)
            self.proc.wait(timeout_s)
        except (ProcessLookupError, subprocess.TimeoutExpired):
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.proc.wait(timeout_s)
