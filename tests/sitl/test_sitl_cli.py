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
    (["--wind", "-3"], "mean_speed_m_s"),
    (["--loss", "2"], "--loss"),
    (["--param", "GUID_OPTIONS"], "NAME=VALUE"),
    (["--param", "NOPE=1"], "NOPE"),
    (["--param", "GUID_TIMEOUT=99"], "GUID_TIMEOUT"),
    (["--period", "0.003"], "multiple"),
    (["--vehicle", "no-such"], "no such vehicle"),
    (["--start-attitude", "1,2"], "--start-attitude"),
    (["--udp", "127.0.0.1:9", "--tcp", "5"], "not allowed with"),
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
    assert r.stderr.strip() == f"sitl: error: {p}: rotors.time_constant_s: must be > 0, got -0.01"


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
