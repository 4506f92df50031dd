"""``gcs fly`` against ``sitl --emulate arducopter --ekf-ready-s 1`` (real time, a short flight), and the link side."""

from __future__ import annotations

import json
import subprocess
import sys
import time

from pymavlink import mavutil

from sitl.copter.ardupilot_emulation.status import IDENTITY


def test_gcs_fly_waits_for_the_ekf_spools_up_flies_lands_and_disarms(tmp_path):
    summary = tmp_path / "s.json"
    p = subprocess.run([sys.executable, "-m", "gcs.cli", "fly", "--controller", "nlsoc", "--duration", "10",
                        "--sitl-arg=--emulate", "--sitl-arg=arducopter", "--sitl-arg=--ekf-ready-s",
                        "--sitl-arg=1", "--no-log", "-q", "--summary", str(summary)],
                       capture_output=True, text=True, timeout=240, env={"GCS_STATE_DIR": str(tmp_path),
                                                                         **__import__("os").environ})
    doc = json.loads(summary.read_text())
    assert doc["exit_reason"] == "completed", (p.stdout[-2000:], p.stderr[-2000:])
    texts = [e["text"] for e in doc["events"]]
    assert any("capabilities 0xfbef" in t for t in texts)          # identified as the firmware
    assert any("EKF3 IMU0 is using GPS" in t for t in texts)
    assert any("spooling up" in t for t in texts)                  # gcs waited for the arming delay
    assert any("Disarming motors: landed" in t for t in texts)
    assert doc["metrics"]["rms_error_m"] < 0.2


def test_heartbeat_and_position_before_and_after_the_ekf_is_ready():
    port = 15642
    sitl = subprocess.Popen([sys.executable, "-m", "sitl.cli", "--udp-listen", f"127.0.0.1:{port}", "--emulate",
                             "arducopter", "--ekf-ready-s", "4"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    m = None
    try:
        sitl.stdout.readline()
        m = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=255)
        m.mav.heartbeat_send(6, 8, 0, 0, 0)
        hb = m.wait_heartbeat(timeout=10)
        assert hb.base_mode == 81 and hb.system_status == 1                  # BOOT
        m.mav.command_long_send(1, 1, 511, 0, 32, 20000, 0, 0, 0, 0, 0)     # LOCAL_POSITION_NED at 50 Hz
        m.mav.command_long_send(1, 1, 176, 0, 1, 20, 0, 0, 0, 0, 0)          # GUIDED_NOGPS
        m.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)           # arm: refused
        refusal = m.recv_match(type="STATUSTEXT", blocking=True, timeout=10)
        assert refusal is not None and refusal.text.startswith("PreArm: ")
        assert m.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=1) is None
        pos = m.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=30)
        assert pos is not None and pos.time_boot_ms >= 4000
        deadline = time.monotonic() + 30
        hb = None
        while time.monotonic() < deadline:
            hb = m.recv_match(type="HEARTBEAT", blocking=True, timeout=5)
            if hb is not None and hb.system_status == 3:
                break
        assert hb is not None and hb.system_status == 3                      # STANDBY
        m.mav.command_long_send(1, 1, 520, 0, 1, 0, 0, 0, 0, 0, 0)
        ver = m.recv_match(type="AUTOPILOT_VERSION", blocking=True, timeout=10)
        assert ver.capabilities == IDENTITY[0] and ver.flight_sw_version == IDENTITY[1]
        assert bytes(ver.flight_custom_version) == bytes(IDENTITY[2])
    finally:
        if m is not None:
            m.close()
        sitl.terminate()
        sitl.wait(timeout=10)
