"""MAVProxy (the real ground station, headless, commands on stdin) against the built-in SITL.

Issue 15 item 3: connect, all parameters within 2 s of the first heartbeat (MAVFTP
``@PARAM/param.pck``), mode, arming, mission upload and download, fence and rally lists, no
fence-breach text at connect; a mission flown in AUTO (take-off, waypoints, land, disarmed).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import threading
import time

import pytest

pytestmark = pytest.mark.skipif(shutil.which("mavproxy.py") is None, reason="MAVProxy not installed")

TIMEOUT_S = 60.0
PARAM_DOWNLOAD_S = 2.0  # the bound, from the first heartbeat to all parameters

MISSION = [  # seq, current, frame, command, p1..p4, lat, lon, alt, autocontinue (QGC WPL 110)
    (0, 1, 0, 16, 0, 0, 0, 0, -35.3632607, 149.1652299, 584.0, 1),
    (1, 0, 3, 22, 0, 0, 0, 0, 0.0, 0.0, 10.0, 1),
    (2, 0, 3, 16, 0, 0, 0, 0, -35.3630000, 149.1655000, 20.0, 1),
    (3, 0, 3, 16, 0, 0, 0, 0, -35.3628000, 149.1650000, 25.0, 1),
    (4, 0, 3, 20, 0, 0, 0, 0, 0.0, 0.0, 0.0, 1),
]


class MavProxy:
    """``mavproxy.py`` with stdin commands; stdout lines collected (with arrival time) by a thread."""

    def __init__(self, port: int, state_dir: str):
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        self.proc = subprocess.Popen(
            [shutil.which("mavproxy.py") or "mavproxy.py", f"--master=tcp:127.0.0.1:{port}",
             f"--state-basedir={state_dir}", "--default-modules=" + ",".join(
                 ("link", "signing", "log", "wp", "rally", "fence", "ftp", "param", "arm", "mode",
                  "cmdlong", "misc"))],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env,
            text=True, cwd=state_dir)
        self.lines: list[tuple[float, str]] = []
        self._cond = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            with self._cond:
                self.lines.append((time.monotonic(), line.rstrip("\n")))
                self._cond.notify_all()

    def send(self, command: str) -> int:
        """Send a command line; returns the index of the output lines after which to look."""
        with self._cond:
            mark = len(self.lines)
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()
        return mark

    def expect(self, pattern: str, since: int = 0, timeout: float = TIMEOUT_S) -> tuple[float, re.Match]:
        rx = re.compile(pattern)
        deadline = time.monotonic() + timeout
        i = since
        with self._cond:
            while True:
                for t, line in self.lines[i:]:
                    m = rx.search(line)
                    if m:
                        return t, m
                i = len(self.lines)
                left = deadline - time.monotonic()
                if left <= 0 or (self.proc.poll() is not None and not self._reader.is_alive()):
                    tail = "\n".join(line for _, line in self.lines[-30:])
                    raise AssertionError(f"no {pattern!r} from MAVProxy in {timeout} s; last lines:\n{tail}")
                self._cond.wait(min(left, 0.5))

    def text(self) -> str:
        with self._cond:
            return "\n".join(line for _, line in self.lines)

    def close(self) -> None:
        try:
            if self.proc.poll() is None:
                self.proc.stdin.write("exit\n")
                self.proc.stdin.flush()
                self.proc.wait(timeout=3)
        except (OSError, subprocess.TimeoutExpired, ValueError):
            pass
        finally:
            if self.proc.poll() is None:  # MAVProxy's threads outlive "exit" and SIGTERM: a test client
                self.proc.kill()
                self.proc.wait(timeout=15)
            for f in (self.proc.stdin, self.proc.stdout):
                try:
                    f.close()
                except OSError:
                    pass


def _mavproxy(port: int, state_dir):
    mp = MavProxy(port, str(state_dir))
    try:
        yield mp
    finally:
        mp.close()


@pytest.fixture
def mavproxy(sitl_port, tmp_path):
    yield from _mavproxy(sitl_port, tmp_path)


@pytest.fixture
def mavproxy_flying(fast_sitl_port, tmp_path):
    """MAVProxy on a SITL running FLIGHT_SPEEDUP times faster than real time."""
    yield from _mavproxy(fast_sitl_port, tmp_path)


def _write_wpl(path, items) -> None:
    rows = ["QGC WPL 110"] + ["\t".join(str(v) for v in item) for item in items]
    path.write_text("\n".join(rows) + "\n")


def _read_wpl(path) -> list[list[float]]:
    lines = path.read_text().splitlines()
    assert lines[0].startswith("QGC WPL 110"), lines[:1]
    return [[float(v) for v in line.split()] for line in lines[1:] if line.strip()]


def test_connect_and_download_all_parameters_fast(mavproxy):
    t_hb, _ = mavproxy.expect(r"Detected vehicle 1:1")
    t_params, m = mavproxy.expect(r"Received (\d+) parameters(?: \((\w+)\))?")
    elapsed = t_params - t_hb
    print(f"MAVProxy parameter download: {m.group(1)} parameters via {m.group(2) or 'PARAM_REQUEST_LIST'} "
          f"in {elapsed:.3f} s from the first heartbeat")
    assert int(m.group(1)) > 20
    assert m.group(2) == "ftp", "parameters not fetched by MAVFTP @PARAM/param.pck"
    assert elapsed < PARAM_DOWNLOAD_S, f"parameters took {elapsed:.2f} s from the first heartbeat"
    mark = mavproxy.send("param show SYSID_THISMAV")
    mavproxy.expect(r"SYSID_THISMAV\s+1\b", since=mark)
    assert "breach" not in mavproxy.text().lower(), "fence breach reported at connect"


def test_mode_and_arm(mavproxy):
    mavproxy.expect(r"Received \d+ parameters")
    mark = mavproxy.send("mode GUIDED")
    mavproxy.expect(r"DO_SET_MODE: ACCEPTED|Mode GUIDED", since=mark)
    mavproxy.expect(r"Mode GUIDED", since=mark)
    mark = mavproxy.send("arm throttle")
    mavproxy.expect(r"COMPONENT_ARM_DISARM: ACCEPTED", since=mark)
    mavproxy.expect(r"^ARMED|\bARMED\b", since=mark)
    mark = mavproxy.send("disarm")
    mavproxy.expect(r"DISARMED", since=mark)


def test_mission_upload_download_fence_rally(mavproxy, tmp_path):
    mavproxy.expect(r"Received \d+ parameters")
    src = tmp_path / "mission.txt"
    _write_wpl(src, MISSION)
    mark = mavproxy.send(f"wp load {src}")
    mavproxy.expect(rf"Sent all {len(MISSION)} waypoints|Loaded {len(MISSION)} waypoints", since=mark)
    mavproxy.expect(rf"Sent all {len(MISSION)} waypoints", since=mark)
    out = tmp_path / "way.txt"
    if out.exists():
        out.unlink()
    mark = mavproxy.send("wp list")
    mavproxy.expect(rf"Saved {len(MISSION)} waypoints to", since=mark)
    got = _read_wpl(out)
    assert len(got) == len(MISSION)
    for want, row in zip(MISSION[1:], got[1:]):  # item 0 is the vehicle's home
        assert row[0] == want[0] and row[3] == want[3], row
        if want[8] or want[9]:  # a position: its frame kept (a frame-less RTL may come back as 0)
            assert row[2] == want[2], row
        assert row[8:11] == pytest.approx(want[8:11], abs=1e-6), row
    mark = mavproxy.send("fence list")
    mavproxy.expect(r"Requesting \d+ fence items|fence", since=mark)
    mark = mavproxy.send("rally list")
    mavproxy.expect(r"Requesting \d+ rally items", since=mark)
    assert "breach" not in mavproxy.text().lower()
    assert "timeout" not in "\n".join(
        line for _, line in mavproxy.lines[mark:] if "rally" in line.lower()).lower()


FLIGHT = [  # a short mission from the SITL's home: take-off, two waypoints ~15 m apart, land there
    (0, 1, 0, 16, 0, 0, 0, 0, -35.3632607, 149.1652299, 584.0, 1),
    (1, 0, 3, 22, 0, 0, 0, 0, 0.0, 0.0, 6.0, 1),
    (2, 0, 3, 16, 0, 0, 0, 0, -35.3631300, 149.1652299, 6.0, 1),
    (3, 0, 3, 16, 0, 0, 0, 0, -35.3631300, 149.1653900, 8.0, 1),
    (4, 0, 3, 21, 0, 0, 0, 0, 0.0, 0.0, 0.0, 1),
]


def test_mission_flown_in_auto(mavproxy_flying, tmp_path):
    mp = mavproxy_flying
    mp.expect(r"Received \d+ parameters")
    src = tmp_path / "flight.txt"
    _write_wpl(src, FLIGHT)
    mark = mp.send(f"wp load {src}")
    mp.expect(rf"Sent all {len(FLIGHT)} waypoints", since=mark)
    mark = mp.send("mode GUIDED")
    mp.expect(r"Mode GUIDED", since=mark)
    mark = mp.send("arm throttle")
    mp.expect(r"\bARMED\b", since=mark)
    mark = mp.send("mode AUTO")
    mp.expect(r"Mode AUTO", since=mark)
    for seq in range(1, len(FLIGHT)):  # ArduCopter's texts: "Mission: 1 Takeoff", ..., "Reached command #4"
        mp.expect(rf"Reached command #{seq}\b", since=mark, timeout=120.0)
    mp.expect(r"DISARMED", since=mark, timeout=60.0)
    text = mp.text()
    assert "Mission: 1 Takeoff" in text and "Mission: 4 Land" in text
    assert "breach" not in text.lower()
