"""``gcs fly --sitl arducopter / --arducopter / --speedup / --ready-timeout``: the options, the FlightSpec
fields behind them, and the ArduCopter SITL child's command line (nothing is started here: the fake
firmware is an executable file that is never run)."""

from __future__ import annotations

import math
import os
import socket
import tempfile
from pathlib import Path

import pytest

import gcs.vehicles.arducopter_sitl as ac
from gcs.api import FlightSpec, fly
from gcs.cli import build_parser, main
from gcs.cli.fly import fly_overrides, spec_from_args
from gcs.link.mavlink import LinkError
from gcs.vehicles.arducopter_sitl import ENV_VAR, HOME, ArduCopterSitl, find_arducopter, free_instance
from quadrotor.errors import ConfigError


@pytest.fixture(autouse=True)
def _isolated(monkeypatch, tmp_path):
    """No real firmware, parameter journal or log outside the test's folder."""
    monkeypatch.delenv(ENV_VAR, raising=False)
    monkeypatch.setenv("GCS_STATE_DIR", str(tmp_path / "state"))
    monkeypatch.chdir(tmp_path)


def fake_firmware(folder: Path, name: str = "arducopter", mode: int = 0o755) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    p = folder / name
    p.write_text("#!/bin/sh\nexit 1\n")
    p.chmod(mode)
    return p


def parse(*argv: str):
    return spec_from_args(build_parser().parse_args(["fly", *argv]))


def stderr_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


# --------------------------------------------------------------------------- argument ranges (argparse: exit 2)
@pytest.mark.parametrize("value", ["0", "100", "nan", "inf", "-1", "0.09", "50.5", "fast"])
def test_speedup_out_of_range_is_refused(capsys, value):
    with pytest.raises(SystemExit) as e:
        main(["fly", "--sitl", "arducopter", "--speedup", value, "--no-log"])
    assert e.value.code == 2
    line = stderr_line(capsys)
    assert "--speedup" in line and "error" in line


@pytest.mark.parametrize("value", ["0.1", "1", "50"])
def test_speedup_in_range_parses(value):
    assert parse("--sitl", "arducopter", "--speedup", value).speedup == float(value)


@pytest.mark.parametrize("value", ["0", "0.5", "3601", "nan", "-5", "soon"])
def test_ready_timeout_out_of_range_is_refused(capsys, value):
    with pytest.raises(SystemExit) as e:
        main(["fly", "--ready-timeout", value, "--no-log"])
    assert e.value.code == 2
    assert "--ready-timeout" in stderr_line(capsys)


def test_unknown_sitl_is_refused(capsys):
    with pytest.raises(SystemExit) as e:
        main(["fly", "--sitl", "inav", "--no-log"])
    assert e.value.code == 2
    assert "--sitl" in stderr_line(capsys)


# --------------------------------------------------------------------------- combinations (ConfigError: exit 2)
@pytest.mark.parametrize(("argv", "names"), [
    (["--arducopter", "/opt/ardupilot/arducopter"], ["--arducopter", "only with --sitl arducopter"]),
    (["--px4", "/opt/px4"], ["--px4", "only with --sitl px4"]),
    (["--sitl", "arducopter", "--px4", "/opt/px4"], ["--px4"]),
    (["--sitl", "lockstep", "--arducopter", "/opt/ac"], ["--arducopter"]),
    (["--connect", "tcp:127.0.0.1:5760", "--arducopter", "/opt/ac"], ["--arducopter"]),
    (["--sitl", "arducopter", "--connect", "tcp:127.0.0.1:5760"], ["--sitl", "--connect"]),
    (["--sitl", "arducopter", "--port", "/dev/ttyUSB0"], ["--sitl", "--port"]),
    (["--sitl", "arducopter", "--rig", "4dof"], ["--sitl", "--rig"]),
    (["--speedup", "2"], ["--speedup", "--sitl arducopter", "--connect"]),
    (["--sitl", "lockstep", "--speedup", "2"], ["--speedup"]),
    (["--port", "/dev/ttyUSB0", "--speedup", "2"], ["--speedup"]),
])
def test_bad_combinations_are_refused_before_anything_opens(capsys, argv, names):
    assert main(["fly", *argv, "--no-log"]) == 2
    line = stderr_line(capsys)
    assert line.startswith("gcs: error: ")
    for name in names:
        assert name in line
    assert capsys.readouterr().out == ""


def test_flightspec_refuses_another_firmware():
    with pytest.raises(ConfigError, match="firmware SITL must be one of arducopter"):
        FlightSpec(firmware="inav")


@pytest.mark.parametrize("kw", [
    {"connect": "tcp:127.0.0.1:5760"},
    {"port": "/dev/ttyUSB0"},
    {"lockstep": True},
    {"vehicle": "rig"},
])
def test_flightspec_firmware_is_the_child_vehicle(kw):
    with pytest.raises(ConfigError, match="--sitl"):
        FlightSpec(firmware="arducopter", **kw)


@pytest.mark.parametrize("speedup", [0.0, 0.09, 50.01, 100.0, -1.0, math.nan, math.inf])
def test_flightspec_speedup_range(speedup):
    with pytest.raises(ConfigError, match="--speedup"):
        FlightSpec(firmware="arducopter", speedup=speedup)


def test_flightspec_speedup_needs_a_firmware_sitl_or_a_connection():
    with pytest.raises(ConfigError, match="--speedup"):
        FlightSpec(speedup=2.0)
    with pytest.raises(ConfigError, match="--speedup"):
        FlightSpec(speedup=2.0, lockstep=True)
    with pytest.raises(ConfigError, match="--speedup"):
        FlightSpec(speedup=2.0, port="/dev/ttyUSB0")
    spec = FlightSpec(speedup=2.0, connect="tcp:127.0.0.1:5760")
    assert spec.paced and not spec.builtin


@pytest.mark.parametrize("seconds", [0.0, 0.99, 3600.5, math.nan])
def test_flightspec_ready_timeout_range(seconds):
    with pytest.raises(ConfigError, match="--ready-timeout"):
        FlightSpec(ready_timeout_s=seconds)


def test_flightspec_defaults_and_paced():
    spec = FlightSpec()
    assert spec.firmware is None and spec.firmware_path is None and spec.speedup is None
    assert spec.ready_timeout_s == 60.0
    assert not spec.paced
    fw = FlightSpec(firmware="arducopter")
    assert fw.paced and fw.builtin
    assert FlightSpec(ready_timeout_s=1.0).ready_timeout_s == 1.0
    assert FlightSpec(ready_timeout_s=3600.0).ready_timeout_s == 3600.0


# --------------------------------------------------------------------------- options -> spec -> command line
def test_options_fill_the_spec():
    spec = parse("--sitl", "arducopter", "--arducopter", "/opt/ac/arducopter", "--speedup", "5",
                 "--ready-timeout", "120")
    assert spec.firmware == "arducopter"
    assert spec.firmware_path == "/opt/ac/arducopter"
    assert spec.speedup == 5.0
    assert spec.ready_timeout_s == 120.0
    assert spec.builtin and spec.paced and not spec.lockstep
    plain = parse()
    assert plain.firmware is None and plain.speedup is None and plain.ready_timeout_s == 60.0
    remote = parse("--connect", "udpin:0.0.0.0:14550", "--speedup", "2.5")
    assert remote.firmware is None and remote.speedup == 2.5 and remote.paced


@pytest.mark.parametrize("spec", [
    FlightSpec(firmware="arducopter", firmware_path="/opt/ac/arducopter", speedup=5.0, ready_timeout_s=120.0),
    FlightSpec(firmware="arducopter", speedup=0.5),
    FlightSpec(firmware="arducopter"),
    FlightSpec(connect="tcp:127.0.0.1:5760", speedup=2.5, log=False),
    FlightSpec(ready_timeout_s=300.0, lockstep=True),
], ids=["all", "slow", "plain", "connect", "ready"])
def test_command_line_round_trips(spec):
    cmd = spec.command_line()
    assert cmd[:2] == ["gcs", "fly"]
    if spec.firmware:
        i = cmd.index("--sitl")
        assert cmd[i + 1] == "arducopter"
    if spec.speedup is not None:
        assert cmd[cmd.index("--speedup") + 1] == f"{spec.speedup:g}"
    if spec.ready_timeout_s != 60.0:
        assert cmd[cmd.index("--ready-timeout") + 1] == f"{spec.ready_timeout_s:g}"
    else:
        assert "--ready-timeout" not in cmd
    assert parse(*cmd[2:]) == spec


def test_command_line_names_the_firmware():
    cmd = " ".join(FlightSpec(firmware="arducopter", firmware_path="/opt/ac", speedup=5.0).command_line())
    assert "--sitl arducopter --arducopter /opt/ac" in cmd
    assert "--speedup 5" in cmd
    assert "--seed" not in cmd  # the built-in SITL's options are not the firmware's


def test_json_round_trips_the_new_fields():
    spec = FlightSpec(firmware="arducopter", firmware_path="/opt/ac", speedup=4.0, ready_timeout_s=90.0)
    doc = spec.to_json()
    assert doc["firmware"] == "arducopter" and doc["firmware_path"] == "/opt/ac"
    assert doc["speedup"] == 4.0 and doc["ready_timeout_s"] == 90.0
    assert FlightSpec.from_json(doc) == spec


def test_fly_arg_overrides_take_the_new_options():
    assert fly_overrides(["--sitl", "arducopter", "--speedup", "5", "--ready-timeout", "30"]) == {
        "firmware": "arducopter", "speedup": 5.0, "ready_timeout_s": 30.0}


# --------------------------------------------------------------------------- no firmware to start: exit 6
def test_missing_arducopter_binary_is_a_link_error_naming_the_path(capsys, tmp_path):
    missing = tmp_path / "nonexistent" / "arducopter"
    assert main(["fly", "--sitl", "arducopter", "--arducopter", str(missing), "--no-log"]) == 6
    err = capsys.readouterr()
    assert str(missing) in err.err
    assert "link_error (exit 6)" in err.err
    assert "loop:" not in err.out  # nothing flown: no end-of-flight table
    assert "[link]" not in err.out


def test_no_arducopter_given_names_the_environment_variable(capsys):
    assert os.environ.get(ENV_VAR) is None
    assert main(["fly", "--sitl", "arducopter", "--no-log"]) == 6
    err = capsys.readouterr().err
    assert ENV_VAR in err and "--arducopter" in err


def test_fly_api_with_missing_firmware_returns_a_refusal(tmp_path):
    result = fly(FlightSpec(firmware="arducopter", firmware_path=str(tmp_path / "nope"), log=False))
    assert result.exit_reason == "link_error"
    assert result.exit_code == 6
    assert str(tmp_path / "nope") in result.detail
    assert result.loop["ticks"] == 0
    assert result.duration_s == 0.0


# --------------------------------------------------------------------------- find_arducopter
def test_find_arducopter_binary_and_directory(tmp_path):
    binary = fake_firmware(tmp_path / "build" / "sitl" / "bin")
    assert find_arducopter(binary) == binary.resolve()
    assert find_arducopter(str(binary)) == binary.resolve()
    assert find_arducopter(binary.parent) == binary.resolve()  # its folder


def test_find_arducopter_from_the_environment(monkeypatch, tmp_path):
    binary = fake_firmware(tmp_path / "bin")
    monkeypatch.setenv(ENV_VAR, str(binary.parent))
    assert find_arducopter(None) == binary.resolve()
    other = fake_firmware(tmp_path / "other")
    assert find_arducopter(other) == other.resolve()  # the option wins over the environment


def test_find_arducopter_expands_the_home_folder(monkeypatch, tmp_path):
    binary = fake_firmware(tmp_path / "ardupilot")
    monkeypatch.setenv("HOME", str(tmp_path))
    assert find_arducopter("~/ardupilot") == binary.resolve()


def test_find_arducopter_neither_given_names_the_variable():
    with pytest.raises(LinkError, match=ENV_VAR) as e:
        find_arducopter(None)
    assert "--arducopter" in str(e.value)
    assert e.value.exit_code == 6


def test_find_arducopter_not_executable_names_it(tmp_path):
    binary = fake_firmware(tmp_path / "bin", mode=0o644)
    with pytest.raises(LinkError) as e:
        find_arducopter(binary)
    assert str(binary) in str(e.value) and "not an executable" in str(e.value)
    assert "--arducopter" in str(e.value)


def test_find_arducopter_directory_without_the_binary_names_where_it_looked(tmp_path):
    folder = tmp_path / "empty"
    folder.mkdir()
    with pytest.raises(LinkError, match=str(folder / "arducopter")):
        find_arducopter(folder)


def test_find_arducopter_bad_environment_says_so(monkeypatch, tmp_path):
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "gone"))
    with pytest.raises(LinkError) as e:
        find_arducopter(None)
    assert str(tmp_path / "gone") in str(e.value) and ENV_VAR in str(e.value)


def test_find_arducopter_a_folder_named_arducopter_is_not_the_binary(tmp_path):
    (tmp_path / "arducopter").mkdir()  # p / "arducopter" is a folder inside a folder: not a file
    (tmp_path / "arducopter" / "arducopter").mkdir()
    with pytest.raises(LinkError):
        find_arducopter(tmp_path / "arducopter")


# --------------------------------------------------------------------------- ArduCopterSitl.command
def test_command_without_defaults_files(tmp_path):
    binary = fake_firmware(tmp_path / "bin")
    sitl = ArduCopterSitl(binary, speedup=5, workdir=tmp_path / "run")
    sitl.instance = 2
    assert sitl.command() == [str(binary.resolve()), "--model", "x", "--speedup", "5", "-I2", "-w", "--home", HOME]
    assert sitl.url == "tcp:127.0.0.1:5780"
    assert sitl.log_path == tmp_path / "run" / "arducopter.log"
    assert not (tmp_path / "run").exists()  # made by start(), not by the constructor


def test_command_with_copter_parm_next_to_the_binary(tmp_path):
    binary = fake_firmware(tmp_path / "bin")
    (binary.parent / "copter.parm").write_text("FRAME_CLASS 1\n")
    sitl = ArduCopterSitl(binary, speedup=2.5, workdir=tmp_path / "run")
    sitl.instance = 0
    cmd = sitl.command()
    assert cmd[0] == str(binary.resolve())
    assert cmd[cmd.index("--model") + 1] == "x"
    assert cmd[cmd.index("--speedup") + 1] == "2.5"
    assert "-I0" in cmd and "-w" in cmd
    assert cmd[cmd.index("--home") + 1] == HOME
    assert cmd[cmd.index("--defaults") + 1] == str(binary.resolve().parent / "copter.parm")


def test_command_with_the_frame_defaults_too(tmp_path):
    binary = fake_firmware(tmp_path / "bin")
    here = binary.resolve().parent
    (here / "copter.parm").write_text("")
    (here / "frame-quad.parm").write_text("")
    (here / "frame-x.parm").write_text("")
    sitl = ArduCopterSitl(binary, model="quad", workdir=tmp_path / "run")
    sitl.instance = 1
    cmd = sitl.command()
    assert cmd[cmd.index("--model") + 1] == "quad"
    assert cmd[cmd.index("--speedup") + 1] == "1"
    assert cmd[cmd.index("--defaults") + 1] == f"{here / 'copter.parm'},{here / 'frame-quad.parm'}"


def test_command_with_explicit_defaults(tmp_path):
    binary = fake_firmware(tmp_path / "bin")
    (binary.parent / "copter.parm").write_text("")
    none = ArduCopterSitl(binary, workdir=tmp_path / "run", defaults=[])
    none.instance = 0
    assert "--defaults" not in none.command()
    mine = ArduCopterSitl(binary, workdir=tmp_path / "run", defaults=[tmp_path / "a.parm", str(tmp_path / "b.parm")])
    mine.instance = 0
    cmd = mine.command()
    assert cmd[cmd.index("--defaults") + 1] == f"{tmp_path / 'a.parm'},{tmp_path / 'b.parm'}"


@pytest.mark.parametrize("speedup", [0.0, 0.05, 100.5, -1.0, math.nan])
def test_sitl_speedup_range(tmp_path, speedup):
    binary = fake_firmware(tmp_path / "bin")
    with pytest.raises(ValueError, match="speedup"):
        ArduCopterSitl(binary, speedup=speedup, workdir=tmp_path / "run")


def test_sitl_without_a_binary_is_a_link_error(tmp_path):
    with pytest.raises(LinkError, match=ENV_VAR):
        ArduCopterSitl(None, workdir=tmp_path / "run")


def test_sitl_not_started_is_alive_and_stop_cleans_its_own_folder(monkeypatch, tmp_path):
    binary = fake_firmware(tmp_path / "bin")
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    sitl = ArduCopterSitl(binary)
    assert sitl.workdir.is_dir() and sitl.workdir.parent == tmp_path / "tmp"
    assert sitl.exit_reason() is None
    sitl.check_alive()
    sitl.stop()
    assert not sitl.workdir.exists()
    given = ArduCopterSitl(binary, workdir=tmp_path / "keep")
    given.workdir.mkdir()
    given.stop()
    assert given.workdir.is_dir()  # not its own: left alone


# --------------------------------------------------------------------------- free_instance
def test_free_instance_skips_an_instance_with_any_busy_port(monkeypatch):
    busy = {5760, 5772, 5783}  # instance 0 SERIAL0, instance 1 SERIAL1, instance 2 SERIAL2
    monkeypatch.setattr(ac, "_port_free", lambda port: port not in busy)
    assert free_instance() == 3
    monkeypatch.setattr(ac, "_port_free", lambda port: True)
    assert free_instance() == 0


def test_free_instance_none_free_is_a_link_error(monkeypatch):
    monkeypatch.setattr(ac, "_port_free", lambda port: False)
    with pytest.raises(LinkError, match="no free ArduCopter SITL instance"):
        free_instance()


def test_free_instance_skips_the_instance_whose_port_is_bound_here():
    """A real socket on instance N's SERIAL0 port: the next call does not pick N."""
    for _ in range(20):  # another process may take a port between the two calls: try again
        n = free_instance()
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            s.bind(("127.0.0.1", 5760 + 10 * n))
        except OSError:
            s.close()
            continue
        try:
            s.listen(1)
            assert not ac._port_free(5760 + 10 * n)
            assert free_instance() != n
        finally:
            s.close()
        return
    pytest.skip("no SITL port could be bound on this machine")
