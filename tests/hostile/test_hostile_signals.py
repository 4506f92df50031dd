"""SIGSTOP / SIGKILL of either side in flight (through the proxy, which watches the vehicle).

* gcs stopped 2 s, then continued (real time: a lockstep vehicle would just wait): the vehicle
  ends landed and disarmed, parameters restored, the log readable.
* gcs killed in flight (real time): nobody lands it but the vehicle itself (ArduCopter's guided
  timeout, GUID_TIMEOUT); the proxy watches it end disarmed on the ground.  The log of the killed
  ground station is readable (its writer process finishes the file).
* sitl stopped 2 s, then continued: the ground station's failsafe acts (stale telemetry) and the
  vehicle ends landed and disarmed.
* sitl killed: the ground station exits with the documented code of a lost link (3, telemetry
  lost) and its one-line reason, without a traceback, soon: within ``land_timeout_s`` (6 s in
  this test's config) + 10 s of the kill.
"""

from __future__ import annotations

import re
import signal

from hostile_kit import Spec, flight_config, report, signal_after_armed, vehicle_down


def test_gcs_sigstop_2s_then_sigcont(fly):
    spec = Spec(lockstep=False, duration_s=6.0, timeout_s=60.0,
                action=signal_after_armed("gcs", signal.SIGSTOP, 2.0, cont_after_s=2.0))
    o, verdict = fly(spec)
    assert any("SIGCONT" in n for n in o.notes), f"the signals were not sent: {o.notes}"
    assert not verdict, report(o, verdict)


def test_gcs_sigkill_vehicle_lands_itself(fly):
    spec = Spec(lockstep=False, duration_s=20.0, timeout_s=60.0,
                action=signal_after_armed("gcs", signal.SIGKILL, 3.0),
                after_gcs_exit_wait_s=40.0, after_gcs_exit_until=vehicle_down)
    o, verdict = fly(spec)
    assert o.gcs_killed, f"gcs was not killed: {o.notes}"
    assert o.monitor["max_altitude_m"] > 0.5, "killed before it flew"
    assert not verdict, report(o, verdict)


def test_sitl_sigstop_2s_then_sigcont(fly):
    # Lockstep flies as fast as it computes (~20x real time here): a 60 s mission keeps the vehicle in
    # the air for the 0.8 + 2 wall seconds (a 10 s one had landed before the SIGSTOP on a fast machine).
    spec = Spec(lockstep=True, duration_s=60.0, timeout_s=60.0,
                action=signal_after_armed("sitl", signal.SIGSTOP, 0.8, cont_after_s=2.0))
    o, verdict = fly(spec)
    assert any("SIGCONT" in n for n in o.notes), f"the signals were not sent: {o.notes}"
    assert not verdict, report(o, verdict)


def test_sitl_sigkill_gcs_exits_lost_link(fly, tmp_path):
    land_timeout = 6.0
    config = flight_config(tmp_path, land_timeout_s=land_timeout)
    spec = Spec(lockstep=True, duration_s=60.0, config=config, timeout_s=60.0,  # in the air at the kill (above)
                action=signal_after_armed("sitl", signal.SIGKILL, 0.8))
    o, verdict = fly(spec, allowed={3})
    assert o.sitl_killed, f"sitl was not killed: {o.notes}"
    kill_t = float(re.match(r"\s*([\d.]+) s", next(n for n in o.notes if "SIGKILL" in n)).group(1))
    took = o.wall_s - kill_t
    if took > land_timeout + 10.0:
        verdict.append(f"gcs fly took {took:.1f} s after the vehicle died to exit (bound: land_timeout_s "
                       f"{land_timeout:g} s + 10 s)")
    assert not verdict, report(o, verdict)
