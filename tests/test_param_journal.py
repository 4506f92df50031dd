"""ParamJournal and VehicleParams: parameters set for a flight, journaled on disk, restored or recovered.

The vehicle is a fake link holding a dict of values; LinkError simulates a link that does not answer.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from gcs.errors import PreflightRefused
from gcs.link.mavlink import LinkError
from gcs.vehicles.params import STATE_DIR_ENV, ParamJournal, VehicleParams, state_dir

KEY = "tcp:127.0.0.1:5760#1"


class FakeLink:
    """A vehicle's parameters over a link: ``fail_get`` / ``fail_set`` names raise LinkError; ``refuse`` names
    keep their value on PARAM_SET (the vehicle answers with what it holds)."""

    def __init__(self, values: dict[str, float], journal: ParamJournal | None = None) -> None:
        self.values = {k: float(v) for k, v in values.items()}
        self.journal = journal
        self.fail_get: set[str] = set()
        self.fail_set: set[str] = set()
        self.refuse: set[str] = set()
        #: name -> values another system on the link writes, one after each of our PARAM_SETs of it.
        self.tamper: dict[str, list[float]] = {}
        self.gets: list[str] = []
        self.sets: list[tuple[str, float]] = []
        #: The journal on disk at each PARAM_SET, as the vehicle is about to take it.
        self.journal_at_set: list[dict] = []

    def param_get(self, name, timeout_s=3.0, retries=2, on_message=None) -> float:
        self.gets.append(name)
        if name in self.fail_get or name not in self.values:
            raise LinkError(f"no PARAM_VALUE for {name} after {retries + 1} tries")
        return self.values[name]

    def param_set(self, name, value, timeout_s=3.0, retries=2, on_message=None) -> float:
        self.sets.append((name, value))
        if self.journal is not None:
            self.journal_at_set.append(self.journal.load())
        if name in self.fail_set:
            raise LinkError(f"no PARAM_VALUE echo for {name} after {retries + 1} tries")
        if name not in self.refuse:
            self.values[name] = float(value)
        held = self.values[name]  # the echo we get
        if self.tamper.get(name):
            self.values[name] = self.tamper[name].pop(0)
        return held


class Events(list):
    def __call__(self, kind: str, text: str) -> None:
        self.append((kind, text))

    def texts(self, kind: str) -> list[str]:
        return [t for k, t in self if k == kind]


def make(tmp_path: Path, values: dict[str, float], *, journal: bool = True):
    j = ParamJournal(KEY, tmp_path) if journal else None
    link = FakeLink(values, j)
    events = Events()
    params = VehicleParams(link, on_message=lambda m: None, event=events, check_interrupt=lambda: None, journal=j)
    return params, link, j, events


def disarmed() -> bool:
    return False


# --------------------------------------------------------------------------- ParamJournal
def test_journal_path_is_a_safe_file_name_in_the_folder(tmp_path):
    j = ParamJournal(KEY, tmp_path)
    assert j.path == tmp_path / "params-tcp_127.0.0.1_5760_1.json"
    assert j.key == KEY
    assert ParamJournal("/dev/ttyUSB0#1", tmp_path).path.name == "params-dev_ttyUSB0_1.json"
    assert ParamJournal(":::", tmp_path).path.name == "params-vehicle.json"


def test_journal_round_trip_and_empty_removes_the_file(tmp_path):
    j = ParamJournal(KEY, tmp_path / "deep" / "er")  # the folder is made when needed
    entries = {"GUID_OPTIONS": {"original": 0.0, "flight": 8.0}, "ATC_ANGLE_BOOST": {"original": 1.0, "flight": 0.0}}
    assert j.save(entries) is None
    assert j.path.is_file()
    assert j.load() == entries
    doc = json.loads(j.path.read_text())
    assert doc["vehicle"] == KEY
    assert not list(j.path.parent.glob("*.tmp"))  # written by replace, no temporary left
    assert j.save({}) is None
    assert not j.path.exists()
    assert j.load() == {}
    assert j.save({}) is None  # nothing to remove: fine


def test_journal_save_error_is_a_text_not_an_exception(tmp_path):
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("x")
    j = ParamJournal(KEY, blocker)
    err = j.save({"A": {"original": 0.0, "flight": 1.0}})
    assert err is not None and str(blocker) in err


@pytest.mark.parametrize("content", [
    b"{not json",
    b"",
    b"\xff\xfe\x00garbage",
    b"[1, 2, 3]",
    b'"params"',
    b'{"vehicle": "x"}',
    b'{"params": {"A": {"original": "0", "flight": 8}, "B": 5, "C": {"original": 1}}}',
])
def test_garbled_journal_is_ignored(tmp_path, content):
    j = ParamJournal(KEY, tmp_path)
    j.path.write_bytes(content)
    assert j.load() == {}


@pytest.mark.parametrize("content", [b'{"params": [1, 2]}', b'{"params": null}', b'{"params": "A"}'])
def test_journal_with_params_not_an_object_is_ignored(tmp_path, content):
    j = ParamJournal(KEY, tmp_path)
    j.path.write_bytes(content)
    assert j.load() == {}


def test_unreadable_journal_is_ignored(tmp_path):
    j = ParamJournal(KEY, tmp_path)
    j.path.mkdir()  # reading a folder: OSError
    assert j.load() == {}


def test_journal_keeps_the_valid_entries_of_a_partly_bad_file(tmp_path):
    j = ParamJournal(KEY, tmp_path)
    j.path.write_text(json.dumps({"params": {"A": {"original": 0, "flight": 8}, "B": {"original": None,
                                                                                     "flight": 1}}}))
    assert j.load() == {"A": {"original": 0.0, "flight": 8.0}}


# --------------------------------------------------------------------------- state_dir
def test_state_dir_honours_gcs_state_dir(monkeypatch, tmp_path):
    monkeypatch.setenv(STATE_DIR_ENV, str(tmp_path / "gcs-state"))
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "xdg"))
    assert STATE_DIR_ENV == "GCS_STATE_DIR"
    assert state_dir() == tmp_path / "gcs-state"
    assert ParamJournal(KEY).path.parent == tmp_path / "gcs-state"


def test_state_dir_then_xdg_state_home(monkeypatch, tmp_path):
    monkeypatch.delenv(STATE_DIR_ENV, raising=False)
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "xdg"))
    assert state_dir() == tmp_path / "xdg" / "gcs"
    monkeypatch.setenv(STATE_DIR_ENV, "")  # empty: not set
    assert state_dir() == tmp_path / "xdg" / "gcs"


def test_state_dir_default_is_under_home(monkeypatch, tmp_path):
    monkeypatch.delenv(STATE_DIR_ENV, raising=False)
    monkeypatch.delenv("XDG_STATE_HOME", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    assert state_dir() == tmp_path / ".local" / "state" / "gcs"


# --------------------------------------------------------------------------- VehicleParams.set / restore
def test_set_writes_the_journal_before_the_vehicle_holds_the_value(tmp_path):
    params, link, j, _ = make(tmp_path, {"GUID_OPTIONS": 0.0})
    assert not j.path.exists()
    assert params.set("GUID_OPTIONS", 8.0, 0.0) == 8.0
    assert link.journal_at_set == [{"GUID_OPTIONS": {"original": 0.0, "flight": 8.0}}]
    assert j.load() == {"GUID_OPTIONS": {"original": 0.0, "flight": 8.0}}
    assert params.changed == {"GUID_OPTIONS": 0.0}
    assert link.values["GUID_OPTIONS"] == 8.0


def test_second_set_keeps_the_first_original_and_the_other_entries(tmp_path):
    params, link, j, _ = make(tmp_path, {"A": 1.0, "B": 5.0})
    params.set("A", 0.0, 1.0)
    params.set("B", 6.0, 5.0)
    assert link.journal_at_set[1] == {"A": {"original": 1.0, "flight": 0.0}, "B": {"original": 5.0, "flight": 6.0}}
    params.set("A", 2.0, 0.0)  # changed again: what is put back is still the value before the flight
    assert link.journal_at_set[2]["A"] == {"original": 1.0, "flight": 2.0}
    assert j.load() == {"A": {"original": 1.0, "flight": 2.0}, "B": {"original": 5.0, "flight": 6.0}}
    assert params.changed == {"A": 1.0, "B": 5.0}


def test_set_refused_by_the_vehicle_is_not_kept(tmp_path):
    params, link, j, _ = make(tmp_path, {"ATC_ANGLE_BOOST": 1.0})
    link.refuse.add("ATC_ANGLE_BOOST")
    assert params.set("ATC_ANGLE_BOOST", 0.0, 1.0) == 1.0  # what the vehicle holds
    assert link.journal_at_set == [{"ATC_ANGLE_BOOST": {"original": 1.0, "flight": 0.0}}]
    assert params.changed == {}
    assert not j.path.exists()  # the vehicle holds its own value: nothing to recover


def test_set_without_journal(tmp_path):
    params, link, _, _ = make(tmp_path, {"A": 0.0}, journal=False)
    assert params.set("A", 8.0, 0.0) == 8.0
    assert params.changed == {"A": 0.0}
    assert list(tmp_path.iterdir()) == []
    params.restore(disarmed)
    assert link.values["A"] == 0.0


def test_restore_puts_back_empties_and_deletes_the_journal(tmp_path):
    params, link, j, events = make(tmp_path, {"GUID_OPTIONS": 0.0, "ATC_ANGLE_BOOST": 1.0})
    params.set("GUID_OPTIONS", 8.0, 0.0)
    params.set("ATC_ANGLE_BOOST", 0.0, 1.0)
    assert j.path.exists()
    params.restore(disarmed)
    assert link.values == {"GUID_OPTIONS": 0.0, "ATC_ANGLE_BOOST": 1.0}
    assert params.changed == {}
    assert not j.path.exists()
    assert events.texts("param") == ["GUID_OPTIONS restored to 0", "ATC_ANGLE_BOOST restored to 1"]


def test_restore_while_armed_leaves_the_value_and_the_journal(tmp_path):
    params, link, j, events = make(tmp_path, {"A": 0.0})
    params.set("A", 8.0, 0.0)
    params.restore(lambda: True)
    assert link.values["A"] == 8.0
    assert params.changed == {"A": 0.0}
    assert j.load() == {"A": {"original": 0.0, "flight": 8.0}}
    assert any("still armed" in t for t in events.texts("warning"))
    params.restore(disarmed)  # later, once disarmed
    assert link.values["A"] == 0.0
    assert not j.path.exists()


def test_restore_failure_keeps_the_entry(tmp_path):
    params, link, j, events = make(tmp_path, {"A": 0.0, "B": 1.0})
    params.set("A", 8.0, 0.0)
    params.set("B", 0.0, 1.0)
    link.fail_set.add("A")
    params.restore(disarmed)
    assert params.changed == {"A": 0.0}
    assert j.load() == {"A": {"original": 0.0, "flight": 8.0}}
    assert link.values["B"] == 1.0
    assert any(t.startswith("A not restored") for t in events.texts("warning"))


def test_restore_reads_back_and_puts_back_a_value_changed_after_its_echo(tmp_path):
    # CI: another system replayed our PARAM_SET with a mutated value right after the restore's echo.
    params, link, j, events = make(tmp_path, {"GUID_OPTIONS": 0.0, "ATC_ANGLE_BOOST": 1.0})
    params.set("GUID_OPTIONS", 8.0, 0.0)
    params.set("ATC_ANGLE_BOOST", 0.0, 1.0)
    link.tamper["GUID_OPTIONS"] = [2147483648.0]
    params.restore(disarmed)
    assert link.values == {"GUID_OPTIONS": 0.0, "ATC_ANGLE_BOOST": 1.0}
    assert link.sets[-1] == ("GUID_OPTIONS", 0.0)
    assert link.gets.count("GUID_OPTIONS") == 2 and link.gets.count("ATC_ANGLE_BOOST") == 1
    assert any(t.startswith("GUID_OPTIONS is 2.14748e+09 after it was restored to 0") for t in events.texts("warning"))
    assert not j.path.exists()


def test_restore_gives_up_on_a_value_that_keeps_changing(tmp_path):
    params, link, _, events = make(tmp_path, {"A": 0.0})
    params.set("A", 8.0, 0.0)
    link.tamper["A"] = [5.0] * 10
    params.restore(disarmed)
    assert link.sets.count(("A", 0.0)) == 4  # the restore and 3 read-back rounds
    assert any("A keeps changing after it is restored to 0" in t for t in events.texts("warning"))


def test_restore_with_an_unreadable_read_back_warns(tmp_path):
    params, link, _, events = make(tmp_path, {"A": 0.0})
    params.set("A", 8.0, 0.0)
    link.fail_get.add("A")
    params.restore(disarmed)
    assert link.values["A"] == 0.0
    assert any(t.startswith("A: restored value not read back") for t in events.texts("warning"))


def test_journal_write_failure_is_a_warning(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    j = ParamJournal(KEY, blocker)
    link = FakeLink({"A": 0.0})
    events = Events()
    params = VehicleParams(link, lambda m: None, events, lambda: None, j)
    assert params.set("A", 8.0, 0.0) == 8.0  # the flight goes on
    assert any("parameter journal not written" in t for t in events.texts("warning"))


def test_set_that_raised_stays_journaled_after_restore(tmp_path):
    params, link, j, _ = make(tmp_path, {"A": 0.0})
    link.fail_set.add("A")
    with pytest.raises(LinkError):
        params.set("A", 8.0, 0.0)
    assert j.load() == {"A": {"original": 0.0, "flight": 8.0}}  # a kill here would be covered
    params.restore(disarmed)  # what the flight does after the link error (gcs.api: flight.restore())
    assert j.load() == {"A": {"original": 0.0, "flight": 8.0}}


def test_refused_second_set_keeps_the_held_flight_value_in_the_journal(tmp_path):
    params, link, j, _ = make(tmp_path, {"A": 0.0})
    params.set("A", 8.0, 0.0)
    link.refuse.add("A")
    assert params.set("A", 16.0, 8.0) == 8.0
    assert j.load() == {"A": {"original": 0.0, "flight": 8.0}}


# --------------------------------------------------------------------------- VehicleParams.recover
def journal_with(tmp_path: Path, entries: dict) -> ParamJournal:
    j = ParamJournal(KEY, tmp_path)
    assert j.save(entries) is None
    return j


def test_recover_restores_a_parameter_left_at_its_flight_value(tmp_path):
    journal_with(tmp_path, {"GUID_OPTIONS": {"original": 0.0, "flight": 8.0}})
    params, link, j, events = make(tmp_path, {"GUID_OPTIONS": 8.0})
    params.recover()
    assert link.values["GUID_OPTIONS"] == 0.0
    assert link.sets == [("GUID_OPTIONS", 0.0)]
    (text,) = events.texts("param")
    assert "left at its flight value 8" in text and "restored to 0" in text
    assert not j.path.exists()
    assert params.changed == {}  # nothing of this flight's to restore


def test_recover_leaves_a_parameter_changed_since_alone(tmp_path):
    journal_with(tmp_path, {"A": {"original": 0.0, "flight": 8.0}, "B": {"original": 1.0, "flight": 0.0}})
    params, link, j, events = make(tmp_path, {"A": 8.0, "B": 0.5})  # B was set by someone else since
    params.recover()
    assert link.values == {"A": 0.0, "B": 0.5}
    assert link.sets == [("A", 0.0)]
    assert len(events.texts("param")) == 1
    assert not j.path.exists()


def test_recover_drops_a_parameter_already_back_at_its_original(tmp_path):
    journal_with(tmp_path, {"A": {"original": 0.0, "flight": 8.0}})
    params, link, j, events = make(tmp_path, {"A": 0.0})
    params.recover()
    assert link.sets == []
    assert events == []
    assert not j.path.exists()


def test_recover_keeps_an_unreadable_parameter_in_the_journal(tmp_path):
    journal_with(tmp_path, {"A": {"original": 0.0, "flight": 8.0}, "B": {"original": 1.0, "flight": 0.0}})
    params, link, j, events = make(tmp_path, {"A": 8.0, "B": 0.0})
    link.fail_get.add("B")
    params.recover()
    assert link.values["A"] == 0.0
    assert link.values["B"] == 0.0
    assert j.load() == {"B": {"original": 1.0, "flight": 0.0}}  # tried again next time
    assert any(t.startswith("B: left changed by an earlier flight") and "not restored" in t
               for t in events.texts("warning"))


def test_recover_refuses_when_the_vehicle_will_not_take_the_original(tmp_path):
    journal_with(tmp_path, {"A": {"original": 0.0, "flight": 8.0}})
    params, link, j, _ = make(tmp_path, {"A": 8.0})
    link.refuse.add("A")
    with pytest.raises(PreflightRefused, match="A is still 8"):
        params.recover()
    assert j.load() == {"A": {"original": 0.0, "flight": 8.0}}


def test_recover_with_no_journal_file_does_nothing(tmp_path):
    params, link, j, events = make(tmp_path, {"A": 8.0})
    params.recover()
    assert link.gets == [] and link.sets == [] and events == []
    assert not j.path.exists()


def test_recover_without_a_journal_does_nothing(tmp_path):
    params, link, _, events = make(tmp_path, {"A": 8.0}, journal=False)
    params.recover()
    assert link.gets == [] and link.sets == [] and events == []


def test_recover_ignores_a_garbled_journal(tmp_path):
    j = ParamJournal(KEY, tmp_path)
    j.path.write_text('{"params": {"A": {"original": 0, "fli')
    params, link, _, events = make(tmp_path, {"A": 8.0})
    params.recover()
    assert link.gets == [] and link.sets == []
    assert link.values["A"] == 8.0
    assert events == []


def test_recover_checks_for_interrupts(tmp_path):
    journal_with(tmp_path, {"A": {"original": 0.0, "flight": 8.0}})
    j = ParamJournal(KEY, tmp_path)
    link = FakeLink({"A": 8.0})

    def interrupted():
        raise PreflightRefused("interrupted")

    params = VehicleParams(link, lambda m: None, Events(), interrupted, j)
    with pytest.raises(PreflightRefused, match="interrupted"):
        params.recover()
    assert link.sets == []
    assert j.load() == {"A": {"original": 0.0, "flight": 8.0}}


def test_a_killed_flight_is_recovered_by_the_next_one(tmp_path):
    """Flight 1 sets parameters and is killed (no restore); flight 2 on the same link puts them back."""
    vehicle = {"GUID_OPTIONS": 0.0, "ATC_ANGLE_BOOST": 1.0}
    first, link1, _, _ = make(tmp_path, vehicle)
    first.set("GUID_OPTIONS", 8.0, 0.0)
    first.set("ATC_ANGLE_BOOST", 0.0, 1.0)
    # SIGKILL: nothing restored.  The vehicle keeps the flight values.
    second, link2, j, events = make(tmp_path, link1.values)
    second.recover()
    assert link2.values == vehicle
    assert len(events.texts("param")) == 2
    assert not j.path.exists()
