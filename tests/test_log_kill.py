"""A writer killed with SIGKILL leaves a readable, truncated log that reaches to about its last second."""

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from gcs.log import topics as T
from gcs.log.mcap.reader import read_log

pytestmark = pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")

# Log times are wall-clock nanoseconds (time.time_ns) so that the test can compare them with
# the moment it killed the writer.  "paced" writes a 1 kHz control loop (chunks never fill up
# in a second: only the periodic flush saves the data); "burst" writes as fast as it can;
# "idle" writes for half a second and then stops (only the background thread flushes).
WRITER = textwrap.dedent("""
    import sys, time
    from gcs.log.writer import FlightLog
    from quadrotor.state import Command, State
    path, mode = sys.argv[1], sys.argv[2]
    log = FlightLog(path)
    log.metadata("flight", {"controller": "pd"})
    s, r, c = State(z=1.0), State(z=2.0), Command(9.81, 0.0, 0.0, 0.0)
    print("ready", flush=True)
    k = 0
    t0 = time.monotonic()
    while True:
        log.control_tick(time.time_ns(), state=s, reference=r, command=c, k=k, truth=s)
        k += 1
        if mode == "paced":
            time.sleep(max(0.0, t0 + k * 0.001 - time.monotonic()))
        elif mode == "idle" and time.monotonic() - t0 > 0.5:
            print("idle", k, flush=True)
            time.sleep(3600)
""")


@pytest.mark.parametrize("mode", ["paced", "burst", "idle"])
def test_sigkill_leaves_a_readable_truncated_log(tmp_path, mode):
    path = tmp_path / f"{mode}.mcap"
    script = tmp_path / "writer.py"
    script.write_text(WRITER)
    proc = subprocess.Popen([sys.executable, str(script), str(path), mode], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        written = None
        if mode == "idle":
            written = int(proc.stdout.readline().split()[1])
        time.sleep(2.0)
        killed_ns = time.time_ns()
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    log = read_log(path, [T.STATE, T.HORIZON])
    assert log.truncated and log.problem
    assert log.metadata_dict("flight") == {"controller": "pd"}
    n = log.counts.get(T.STATE, 0)
    assert n > 0
    ticks = [m["k"] for _, m in log.decoded(T.HORIZON)]
    assert ticks == list(range(len(ticks))), "what was read is a gap-free prefix"
    if mode == "idle":
        assert n == written, "an idle writer must have flushed everything"
    else:
        lag_s = (killed_ns - log.last_ns[T.STATE]) / 1e9
        print(f"{mode}: {n} ticks, lost the last {lag_s:.3f} s")
        assert lag_s < 1.0, f"the last {lag_s:.2f} s before the kill were lost"
