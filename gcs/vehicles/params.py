"""The vehicle's parameters as a flight uses them: read, set for the flight, restored after it.

A value is trusted only once the vehicle reports it (the PARAM_VALUE echo of
:meth:`gcs.link.mavlink.MavlinkLink.param_set`); every change is remembered with the
value it replaced and put back by :meth:`VehicleParams.restore` once the vehicle is
disarmed, whatever ended the flight.

A ground station killed in flight (SIGKILL, a crash of the machine) cannot restore anything;
so every change is also written, before the flight uses it, to a journal file
(:class:`ParamJournal`, one per vehicle link, in :func:`state_dir`).  The next flight on the same
link calls :meth:`VehicleParams.recover` first: a parameter that still holds the value an
earlier flight set is put back to the value before it (one that changed since is left alone).
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Callable
from pathlib import Path

from gcs.errors import PreflightRefused
from gcs.link.mavlink import LinkError
from gcs.link.param_encoding import same_float32

__all__ = ["ParamJournal", "VehicleParams", "state_dir", "STATE_DIR_ENV"]

#: Environment variable for the directory of the parameter journals.
STATE_DIR_ENV = "GCS_STATE_DIR"


def state_dir() -> Path:
    """``$GCS_STATE_DIR``, else ``$XDG_STATE_HOME/gcs``, else ``~/.local/state/gcs``."""
    if os.environ.get(STATE_DIR_ENV):
        return Path(os.environ[STATE_DIR_ENV])
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "gcs"


class ParamJournal:
    """``{name: {"original": v0, "flight": v1}}`` of one vehicle, kept on disk while the flight has it changed.

    Parameters
    ----------
    key : str
        The vehicle: its link and system id (e.g. ``tcp:127.0.0.1:5760#1``).
    folder : path-like or None
        Default :func:`state_dir`.
    """

    def __init__(self, key: str, folder=None) -> None:
        safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", key).strip("_") or "vehicle"
        self.path = Path(folder if folder is not None else state_dir()) / f"params-{safe}.json"
        self.key = key

    def load(self) -> dict[str, dict[str, float]]:
        """The entries left on disk ({} if none or unreadable: then nothing is restored)."""
        try:
            doc = json.loads(self.path.read_text())
        except (OSError, ValueError):
            return {}
        entries = doc.get("params", {}) if isinstance(doc, dict) else {}
        if not isinstance(entries, dict):
            return {}
        out = {}
        for name, e in entries.items():
            if isinstance(e, dict) and all(isinstance(e.get(k), int | float) for k in ("original", "flight")):
                out[str(name)] = {"original": float(e["original"]), "flight": float(e["flight"])}
        return out

    def save(self, entries: dict[str, dict[str, float]]) -> str | None:
        """Write ``entries`` (removing the file when empty); an error text, or None."""
        try:
            if not entries:
                self.path.unlink(missing_ok=True)
                return None
            self.path.parent.mkdir(parents=True, exist_ok=True)
            tmp = self.path.with_suffix(".tmp")
            tmp.write_text(json.dumps({"vehicle": self.key, "params": entries}, indent=1))
            os.replace(tmp, self.path)
        except OSError as exc:
            return f"{self.path}: {exc.strerror or exc}"
        return None


class VehicleParams:
    """Parameters of one vehicle over ``link``.

    Parameters
    ----------
    link : MavlinkLink
    on_message : callable (msg)
        Every message received while waiting (the telemetry goes on).
    event : callable (kind, text)
    check_interrupt : callable ()
        Raises PreflightRefused once Ctrl-C was pressed.
    journal : ParamJournal or None
        Where changes are kept until restored (None: a fresh child simulator, nothing outlives it).
    """

    def __init__(self, link, on_message: Callable, event: Callable[[str, str], None],
                 check_interrupt: Callable[[], None], journal: ParamJournal | None = None) -> None:
        self.link = link
        self.on_message = on_message
        self.event = event
        self.check_interrupt = check_interrupt
        self.journal = journal
        #: name -> the value it had before the flight changed it.
        self.changed: dict[str, float] = {}
        self._flight_values: dict[str, float] = {}

    def recover(self) -> None:
        """Put back what an earlier flight on this vehicle changed and could not restore (see the module docstring)."""
        if self.journal is None:
            return
        left = self.journal.load()
        for name, e in list(left.items()):
            self.check_interrupt()
            try:
                now = self.link.param_get(name, timeout_s=1.0, retries=1, on_message=self.on_message)
            except LinkError:
                self.event("warning", f"{name}: left changed by an earlier flight ({self.journal.path}) but not "
                                      "readable; not restored")
                continue
            if now == e["flight"] and now != e["original"]:
                back = self.link.param_set(name, e["original"], timeout_s=1.0, retries=1, on_message=self.on_message)
                if back != e["original"]:
                    raise PreflightRefused(f"{name} is still {now:g}, the value an earlier flight that did not "
                                           f"finish set; putting back {e['original']:g} failed")
                self.event("param", f"{name} was left at its flight value {now:g} by an earlier gcs fly that did "
                                    f"not finish: restored to {e['original']:g}")
            del left[name]
        self._save(left)

    def _save(self, entries) -> None:
        if self.journal is not None:
            err = self.journal.save(entries)
            if err is not None:
                self.event("warning", f"parameter journal not written: {err}")

    def _journal_entries(self) -> dict[str, dict[str, float]]:
        return {n: {"original": v, "flight": self._flight_values[n]} for n, v in self.changed.items()}

    def get(self, name: str, default: float | None) -> float:
        """A parameter of the vehicle; ``default=None`` makes it required (refuse without it)."""
        self.check_interrupt()
        try:
            value = self.link.param_get(name, timeout_s=1.0, retries=1, on_message=self.on_message)
        except LinkError:
            if default is None:
                raise PreflightRefused(f"parameter {name} not readable; it is needed to fly") from None
            self.event("warning", f"parameter {name} not readable; assuming {default:g}")
            return default
        if not math.isfinite(value):
            raise PreflightRefused(f"parameter {name} = {value} is not a finite number")
        return value

    def set(self, name: str, value: float, old: float) -> float:
        """Set ``name`` for the flight (``old`` is put back by :meth:`restore`); the value the vehicle holds."""
        before = self._flight_values.get(name)
        if self.journal is not None:  # on disk before the vehicle holds it: a kill in between is covered
            self._flight_values[name] = value
            self._save(dict(self._journal_entries(), **{name: {"original": self.changed.get(name, old),
                                                                "flight": value}}))
        try:
            new = self.link.param_set(name, value, on_message=self.on_message)
        except LinkError:
            # Unknown whether the vehicle holds it: kept for restore() and in the journal.
            self._flight_values[name] = value
            self.changed.setdefault(name, old)
            self._save(self._journal_entries())
            raise
        if new == value:
            self.changed.setdefault(name, old)
            self._flight_values[name] = value
        elif before is not None:
            self._flight_values[name] = before
        else:
            self._flight_values.pop(name, None)
        self._save(self._journal_entries())
        return new

    def said(self, text: str) -> None:
        self.event("param", text)

    def restore(self, armed: Callable[[], bool]) -> None:
        """Put back every parameter changed for the flight (not while the vehicle is still armed).

        A flight that changed nothing leaves the journal alone: what an earlier one left stays there
        for the next :meth:`recover` (e.g. after a refusal of a vehicle still armed by its last flight).
        """
        if not self.changed:
            return
        put_back = {}
        for name, value in list(self.changed.items()):
            if armed():
                self.event("warning", f"vehicle still armed: {name} left at its flight value")
                continue
            try:
                self.link.param_set(name, value, timeout_s=1.0, retries=1, on_message=self.on_message)
                self.event("param", f"{name} restored to {value:g}")
                del self.changed[name]
                put_back[name] = value
            except LinkError as exc:
                self.event("warning", f"{name} not restored: {exc}")
        self._save(self._journal_entries())
        self._read_back(put_back)

    def _read_back(self, put_back: dict[str, float], rounds: int = 3) -> None:
        """Read every restored parameter once more and put back any that changed since its echo.

        Another system on the link (a second ground station, a replay of our own PARAM_SET) can
        change a parameter between our PARAM_SET's echo and the end of the flight; the vehicle
        accepts PARAM_SET from any system id unless told otherwise.
        """
        for _ in range(rounds):
            wrong = {}
            for name, value in put_back.items():
                try:
                    now = self.link.param_get(name, timeout_s=1.0, retries=1, on_message=self.on_message)
                except LinkError as exc:
                    self.event("warning", f"{name}: restored value not read back: {exc}")
                    continue
                if not same_float32(now, value):
                    wrong[name] = value
                    self.event("warning", f"{name} is {now:g} after it was restored to {value:g} (changed by "
                                          "another system on the link?): putting it back again")
                    try:
                        self.link.param_set(name, value, timeout_s=1.0, retries=1, on_message=self.on_message)
                    except LinkError as exc:
                        self.event("warning", f"{name} not restored: {exc}")
            if not wrong:
                return
            put_back = wrong
        for name, value in put_back.items():
            self.event("warning", f"{name} keeps changing after it is restored to {value:g}; left as the vehicle "
                                  "holds it")
