"""The ``sitl`` command: help, errors, endpoints, clean shutdown."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import pytest
from sitl_testkit import Gcs

from sitl.cli import main

SITL = [sys.executable, "-m", "sitl.cli"]


def run_cli(args, timeout=30):
    return subprocess.run(SITL + args, capture_output=True, text=True, timeout=timeout)


def test_help_documents_everything(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for word in ("--udp", "--udp-listen", "--tcp", "--pty", "--lockstep", "--vehicle", "--wind", "--seed", "--baud",
                 "--loss", "--latency", "--signing-key", "--model", "--param", "GUID_OPTIONS", "GUID_TIMEOUT",
                 "SET_ACTUATOR_CONTROL_TARGET", "quad-1kg", "talon-550"):
        assert word in out


@pytest.mark.parametrize("args, words", [
    (["--bogus"], "unrecognized arguments"),
    (["--udp", "1.2.3.4:x"], "bad port"),
    (["--tcp", "70000"], "port out of range"),
    (["--wind", "fast"], "--wind"),
    (["--wind", "-3"], "--wind: speed"),
    (["--loss", "2"], "--loss"),
    (["--param", "GUID_OPTIONS"], "NAME=VALUE"),
    (["--param", "NOPE=1"], "NOPE"),
    (["--param", "GUID_TIMEOUT=99"], "GUID_TIMEOUT"),
    (["--period", "0.003"], "multiple"),
    (["--vehicle", "no-such"], "no such vehicle"),
    (["--start-attitude", "1,2"], "--start-attitude"),
])
def test_bad_arguments_give_one_line_errors(capsys, args, words):
    try:
        code = main(args)          # every case fails before serving
    except SystemExit as e:        # argparse errors
        code = e.code
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("sitl: error: ") and words in err
    assert "Traceback" not in err


def test_bad_vehicle_file_names_the_key(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text(textwrap.dedent("""
        [vehicle]
        mass_kg = 1.0
        inertia_kg_m2 = [0.01, 0.01, 0.02]
        [rotors]
        arm_length_m = 0.2
        max_thrust_n = 6.0
        time_constant_s = -0.01
    """))
    r = run_cli(["--vehicle", str(p), "--udp-listen", "127.0.0.1:0"])
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.count("\n") == 1
    assert r.stderr.startswith(f"sitl: error: {p}: rotors.time_constant_s: must be > 0, got -0.01")


def test_describe_prints_the_normalisation():
    r = run_cli(["--describe"])
    assert r.returncode == 0
    assert "hover thrust     0.4004" in r.stdout and "1.9490" in r.stdout and "24.5 N" in r.stdout


def start(args):
    proc = subprocess.Popen(SITL + args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline().strip()
    assert line, proc.stderr.read()
    return proc, line


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_pty_prints_the_device_and_stops_cleanly(sig):
    proc, device = start(["--pty", "--lockstep"])
    try:
        assert device.startswith("/dev/") and os.path.exists(device)
        gcs = Gcs(device, baud=57600)
        try:
            assert gcs.wait_heartbeat() is not None
            assert gcs.param_get("GUID_TIMEOUT").param_value == 3.0
        finally:
            gcs.close()
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0 and "Traceback" not in err


def test_udp_listen_lockstep_subprocess_flies():
    proc, cs = start(["--udp-listen", "127.0.0.1:0", "--lockstep", "--seed", "2", "--param", "GUID_OPTIONS=8",
                      "--wind", "2,90,0.5", "--vehicle", "talon-550"])
    try:
        assert cs.startswith("udpout:127.0.0.1:")
        gcs = Gcs(cs)
        try:
            assert gcs.wait_heartbeat() is not None
            assert gcs.param_get("GUID_OPTIONS").param_value == 8
            gcs.start_lockstep_streams()
            gcs.set_mode(20)
            assert gcs.arm().result == 0
            for _ in range(100):
                pos = gcs.step(0.55)
            assert -pos.z > 0.5
        finally:
            gcs.close()
        proc.terminate()
        _, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0 and "Traceback" not in err


def test_port_in_use_is_a_clean_error():
    import socket
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(1)
    try:
        r = run_cli(["--tcp", f"127.0.0.1:{s.getsockname()[1]}"])
    finally:
        s.close()
    assert r.returncode == 1 and r.stderr.startswith("sitl: error: cannot listen on tcp")
    assert "Traceback" not in r.stderr


@pytest.mark.parametrize("args, option", [
    (["--wind", "nan"], "--wind"), (["--wind", "2,nan"], "--wind"), (["--wind", "inf"], "--wind"),
    (["--wind", "1e9"], "--wind"), (["--wind", "2,90,-1"], "--wind"), (["--wind", "2,90,1,0"], "--wind"),
    (["--latency", "inf"], "--latency"), (["--latency", "nan"], "--latency"), (["--latency", "-1"], "--latency"),
    (["--latency", "1e6"], "--latency"), (["--loss", "nan"], "--loss"), (["--loss", "-0.1"], "--loss"),
    (["--baud", "-1"], "--baud"), (["--baud", "7"], "--baud"), (["--baud", "30000000"], "--baud"),
    (["--seed", "-1"], "--seed"),
    (["--seed", str(2**64)], "--seed"), (["--seed", "x"], "--seed"), (["--period", "inf"], "--period"),
    (["--period", "nan"], "--period"), (["--period", "0"], "--period"), (["--period", "-0.01"], "--period"),
    (["--period", "100"], "--period"), (["--start-altitude", "nan"], "--start-altitude"),
    (["--start-altitude", "-1"], "--start-altitude"), (["--start-attitude", "nan,0,0"], "--start-attitude"),
    (["--start-attitude", "0,95,0"], "--start-attitude"), (["--start-attitude", "0,0,inf"], "--start-attitude"),
    (["--prearm-delay", "inf"], "--prearm-delay"), (["--prearm-delay", "-1"], "--prearm-delay"),
    (["--param", "GUID_TIMEOUT=nan"], "--param GUID_TIMEOUT"), (["--param", "MOT_THST_HOVER=inf"], "--param"),
    (["--sysid", "0"], "--sysid"), (["--sysid", "300"], "--sysid"), (["--parent-pid", "0"], "--parent-pid"),
    (["--signing-state", "/tmp/x.json"], "--signing-state"), (["--bit-error-rate", "0.1"], "--bit-error-rate"),
    (["--rig", "4dof", "--latency", "inf"], "--latency"), (["--rig", "4dof", "--period", "0.0025"], "--period"),
    (["--rig", "4dof", "--bit-error-rate", "nan"], "--bit-error-rate"),
    (["--rig", "4dof", "--bit-error-rate", "1"], "--bit-error-rate"), (["--rig", "4dof", "--tcp", "5"], "--tcp"),
])
def test_bad_numbers_are_refused_before_anything_starts(capsys, args, option):
    try:
        code = main(args + ["--udp-listen", "127.0.0.1:0"] if "--rig" not in args else args)
    except SystemExit as e:
        code = e.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith(f"sitl: error: {option}"), err
    assert "Traceback" not in err


@pytest.mark.parametrize("args", [["--wind", "nan"], ["--latency", "inf"]])
def test_the_command_refuses_non_finite_values(args):
    r = run_cli(args + ["--lockstep"])
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.startswith(f"sitl: error: {args[0]}: ") and r.stderr.count("\n") == 1


def test_udp_and_tcp_together_are_allowed(capsys):
    code = main(["--udp", "127.0.0.1:9", "--tcp", "127.0.0.1:0", "--period", "nan"])
    assert code == 2 and "not allowed" not in capsys.readouterr().err
