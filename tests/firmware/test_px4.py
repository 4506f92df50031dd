"""PX4's real firmware in the loop: ``gcs fly --sitl px4`` against PX4 SITL with its simulator SIH (issue 14).

The build is found as ``gcs fly`` finds it (``$GCS_PX4``), else in ``../shared/px4`` beside the
repository (CI has it; its archive is unpacked once into the user's cache); without it every
test here skips, naming where it looked.  Real time (PX4_SIM_SPEED_FACTOR 1).  Each flight is
a separate ``gcs fly`` process, as a user runs it, with its summary and its log.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from gcs.log.mcap.reader import read_log
from gcs.vehicles.px4_sitl import ENV_VAR, locate_px4

ROOT = Path(__file__).resolve().parents[2]
BUILD = locate_px4(ROOT.parent / "shared" / "px4")
pytestmark = pytest.mark.skipif(BUILD is None, reason=f"no PX4 SITL build (${ENV_VAR} unset, "
                                                      f"{ROOT.parent / 'shared' / 'px4'} absent)")


def _env(tmp_path: Path) -> dict:
    env = dict(os.environ, GCS_STATE_DIR=str(tmp_path / "state"), PYTHONPATH=str(ROOT))
    env[ENV_VAR] = BUILD  # type: ignore[assignment]
    return env


def _fly_args(tmp_path: Path, name: str, *extra: str, quiet: bool = True) -> list[str]:
    return [sys.executable, "-m", "gcs.cli", "fly", "--sitl", "px4", "--summary", str(tmp_path / f"{name}.json"),
            "--log", str(tmp_path / f"{name}.mcap"), *(["-q"] if quiet else []), *extra]


def _events(tmp_path: Path, name: str) -> tuple[dict, list[str]]:
    s = json.loads((tmp_path / f"{name}.json").read_text())
    return s, [e["text"] if isinstance(e, dict) else str(e) for e in s.get("events", [])]


def _check_landed_and_restored(ev: list[str]) -> None:
    assert "landed and disarmed" in ev, ev[-8:]
    for name in ("COM_OBL_RC_ACT", "COM_OF_LOSS_T"):
        assert any(e.startswith(f"{name} ") and " -> " in e for e in ev), f"{name} not set: {ev[:12]}"
        assert any(e.startswith(f"{name} restored") for e in ev), f"{name} not restored: {ev[-10:]}"
    assert not any("GUID_OPTIONS" in e or "ATC_" in e for e in ev), "ArduPilot parameters sent to PX4"


def test_a_circle_on_px4_in_offboard(tmp_path):
    """Recognised as PX4 from HEARTBEAT, setpoints streamed before OFFBOARD, confirmed, armed, flown,
    landed by NAV_LAND, disarmed by PX4, its parameters (INT32 bytewise) restored, a complete log."""
    p = subprocess.run(_fly_args(tmp_path, "pd", "--controller", "pd", "--duration", "14"), env=_env(tmp_path),
                       capture_output=True, text=True, timeout=240)
    assert "Traceback" not in p.stderr + p.stdout, p.stderr[-2000:]
    assert p.returncode == 0, p.stderr[-2000:]
    s, ev = _events(tmp_path, "pd")
    assert s["exit_reason"] == "completed"
    assert "Offboard" in ev and "Land" in ev, ev  # the modes, by PX4's names
    _check_landed_and_restored(ev)
    assert not read_log(tmp_path / "pd.mcap", None).truncated
    rms = s["metrics"]["rms_error_m"]
    assert math.isfinite(rms) and rms < 0.6, f"RMS position error {rms:.3f} m"  # the take-off and 6 s of circle


def test_actuator_output_is_refused_on_px4_before_arming(tmp_path):
    p = subprocess.run(_fly_args(tmp_path, "act", "--output", "actuator", "--duration", "5"), env=_env(tmp_path),
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 7, p.stderr[-2000:]
    assert "actuator" in p.stderr.strip().splitlines()[-1].lower()
    _, ev = _events(tmp_path, "act")
    assert "armed" not in ev


def test_ctrl_c_on_px4_lands_disarms_and_restores(tmp_path):
    proc = subprocess.Popen(_fly_args(tmp_path, "int", "--controller", "loc", quiet=False), env=_env(tmp_path),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        for line in proc.stdout:  # type: ignore[union-attr]
            if line.startswith("t ") and float(line.split()[1]) >= 3.0:
                proc.send_signal(signal.SIGINT)
                break
        proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    s, ev = _events(tmp_path, "int")
    assert s["exit_reason"] == "interrupted"
    _check_landed_and_restored(ev)
