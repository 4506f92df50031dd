"""A stream-clobbering second client: MAVProxy's ``set streamrate 4`` on the same vehicle.

A second ground station (system 255 component 0, as MAVProxy) sends REQUEST_DATA_STREAM(target
1/1, MAV_DATA_STREAM_ALL, 4 Hz, start) at connect and every 2 s of vehicle time (or wall time,
whichever first), with a HEARTBEAT a second, while ``gcs fly`` flies the outdoor circle:

* ``own_endpoint``: from its own link (a second endpoint of the sitl, ``--udp-listen``, when the
  sitl has more than one; else from its own address to the sitl's socket);
* ``shared_link``: on the ground station's own link (injected by the proxy: the vehicle sees one
  peer), as when both sit behind one MAVProxy.

The flight must complete within the tracking bounds of the same flight undisturbed (same seeds,
lockstep), or end in a controlled landing (the failsafe's LAND: exit 3, landed and disarmed);
never a ceiling or fence breach (the vehicle's own LOCAL_POSITION_NED, watched by the proxy).
"""

from __future__ import annotations

import pytest

from hostile_kit import Spec, fence_problems, report

#: Tracking bound: the disturbed flight's RMS position error may exceed the undisturbed one's by 50 % + 2 cm.
RMS_FACTOR, RMS_SLACK_M = 1.5, 0.02
BASE = dict(lockstep=True, duration_s=14.0, sitl_seed=5, proxy_seed=0, timeout_s=60.0)
_baseline: dict = {}


@pytest.fixture
def baseline(fly):
    """The undisturbed flight through the proxy (flown once per session; also the harness's own check)."""
    if "o" not in _baseline:
        o, verdict = fly(Spec(**BASE), expect_complete=True)
        _baseline.update(o=o, verdict=verdict)
    o, verdict = _baseline["o"], _baseline["verdict"]
    assert not verdict, "the undisturbed baseline failed:\n" + report(o, verdict)
    assert o.monitor["commands_checked"] > 1000 and o.monitor["max_altitude_m"] > 1.0
    return o


@pytest.mark.parametrize("where", ["own_endpoint", "shared_link"])
def test_mavproxy_stream_requests_do_not_break_the_flight(fly, baseline, where):
    rms0 = baseline.summary["metrics"]["rms_error_m"]
    o, verdict = fly(Spec(clobber=where, **BASE), allowed={0, 3})
    verdict += fence_problems(o)
    assert o.clobber_requests >= 2, f"the second client sent {o.clobber_requests} requests"
    if o.rc == 0:
        rms = o.summary["metrics"]["rms_error_m"]
        bound = RMS_FACTOR * rms0 + RMS_SLACK_M
        if not rms <= bound:
            verdict.append(f"tracking: RMS error {rms:.3f} m with the second client, {rms0:.3f} m undisturbed "
                           f"(bound {bound:.3f} m)")
    elif o.rc == 3 and "landed and disarmed" not in o.events:
        verdict.append("the failsafe landing did not end landed and disarmed")
    ds = o.monitor["down_counts"]
    assert not verdict, (report(o, verdict) + f"\nsecond client: {o.clobber_requests} requests; vehicle sent "
                         f"ATTITUDE x{ds.get('ATTITUDE', 0)}, LOCAL_POSITION_NED x{ds.get('LOCAL_POSITION_NED', 0)} "
                         f"(undisturbed: x{baseline.monitor['down_counts'].get('ATTITUDE', 0)})")
