"""The fault matrix: real ``gcs fly`` flights against ``sitl`` through the hostile proxy (mitm.py).

Each case is one flight (outdoor-circle cut at 10 s: takeoff and a piece of the circle, then
LAND) with one kind of fault in both directions unless said otherwise.  Every flight must keep
the acceptance rules of the hostile-link issue (``hostile_kit.problems``): no hang, no
traceback, a documented exit code with its one-line reason, 0 non-finite or out-of-limit
commands on the wire, an armed flight ends landed and disarmed with its parameters restored,
a readable log.  Faults that forge nothing a receiver could take for a valid frame of its peer
(garbage, bad CRCs, truncations, copies, other system ids, frames from another address,
non-finite values) must not stop the flight either: it completes (exit 0).

Lockstep (``sitl --lockstep``, ``gcs fly --lockstep``) unless the fault is about timing; note
that in lockstep a datagram lost to a fault costs the loop up to 0.5 s of waiting for the
step's telemetry, so lossy faults run at low rates.
"""

from __future__ import annotations

import math

import pytest

from hostile_kit import Spec, problems, report  # noqa: F401
from mitm import (DOWN, UP, BitFlip, Burst, Delay, Drop, Duplicate, ForgedSigned, GarbageDatagrams,  # noqa: F401
                  HostileFields, InlineGarbage, LoneMagic, OtherSystem, Reorder, Truncate)

NAN_INF = (math.nan, math.inf, -math.inf)


def _cases():
    # name: (faults factory, Spec overrides, expect_complete)
    return {
        # ~100 random datagrams of up to 1400 B per 1000 forwarded, both ways (the bulk of the suite's bytes)
        "garbage_datagrams": (lambda: [GarbageDatagrams(p=0.2, max_len=1400, count=(1, 3))],
                              {"min_injected": 500_000}, True),
        # garbage dense in 0xFD / 0xFE frame starts, and 1-byte 0xFD datagrams
        "magic_garbage": (lambda: [GarbageDatagrams(p=0.06, max_len=600, magic_rich=True)], {}, True),
        "lone_magic_bytes": (lambda: [LoneMagic(p=0.03)], {"output": "rates"}, True),
        "inline_garbage": (lambda: [InlineGarbage(p=0.02, max_len=64)], {}, True),
        # bad CRCs and truncated frames (each loses a datagram: low rates in lockstep)
        "bad_crc_and_truncation": (lambda: [BitFlip(p=0.003), Truncate(p=0.003)], {"output": "actuator"}, True),
        "duplicates_and_reorder": (lambda: [Duplicate(p=0.1), Reorder(p=0.3)], {}, True),
        # copies of the vehicle's frames as from other system ids: the ground station ignores them
        "other_system_ids": (lambda: [OtherSystem(p=0.3, directions=(DOWN,))], {"output": "rates"}, True),
        # copies of our setpoints (30 % with hostile fields) as from other system ids, to the vehicle: an
        # autopilot takes setpoints from any system on an unsigned link (ArduPilot SYSID_ENFORCE 0), so the
        # vehicle flies the mutated copies too and wanders metres off; the flight lands (not following the
        # reference: out_of_authority), it is not flown on
        "other_system_setpoints_to_vehicle": (lambda: [OtherSystem(p=0.3, directions=(UP,))], {"output": "rates"},
                                              False),
        # valid frames (good CRC, the vehicle's ids) with NaN / inf in ATTITUDE, LOCAL_POSITION_NED
        "nonfinite_fields": (lambda: [HostileFields(p=0.03, values=NAN_INF, name="nonfinite_fields")], {}, True),
        # the same from a second socket (another source port) than the vehicle's
        "other_source_address": (lambda: [HostileFields(p=0.05, alt=True, values=NAN_INF + (1e38, -1e38),
                                                        huge_time=True, name="other_source_address")], {}, True),
        # valid frames with huge values (+-1e38, time_boot_ms 2**32-1, HEARTBEAT modes 2**32-1): spoofing that
        # an unsigned link cannot tell from the truth; the flight may end early but safely
        "huge_fields": (lambda: [HostileFields(p=0.01, values=(1e38, -1e38), huge_time=True, name="huge_fields")],
                        {}, False),
        # the ground station's setpoints replaced by NaN/inf ones on the way: the vehicle must refuse them
        "nonfinite_setpoints_to_vehicle": (lambda: [HostileFields(
            p=0.03, types=("SET_ATTITUDE_TARGET", "SET_ACTUATOR_CONTROL_TARGET"), mode="replace", values=NAN_INF,
            directions=(UP,), name="nonfinite_setpoints")], {"output": "actuator"}, True),
        # timing, in real time: delays, bursts (the link held 30..120 ms), reordering, copies, 1 % loss
        "timing_realtime": (lambda: [Delay(p=0.05, lo=0.005, hi=0.06), Burst(period=(0.5, 2.0), hold=(0.03, 0.12)),
                                     Reorder(p=0.2), Duplicate(p=0.05), Drop(p=0.01)],
                            {"lockstep": False, "duration_s": 6.0}, True),
        # everything at once, lower rates
        "everything": (lambda: [GarbageDatagrams(p=0.05, max_len=1400), GarbageDatagrams(p=0.02, max_len=300,
                                                                                         magic_rich=True),
                                LoneMagic(p=0.01), InlineGarbage(p=0.02), BitFlip(p=0.003), Truncate(p=0.003),
                                Duplicate(p=0.05), Reorder(p=0.1), OtherSystem(p=0.1),
                                HostileFields(p=0.01, values=NAN_INF, name="nonfinite_fields"),
                                HostileFields(p=0.01, alt=True, values=NAN_INF, name="other_source_address"),
                                HostileFields(p=0.003, values=(1e38,), huge_time=True, name="huge_fields")],
                       {"proxy_seed": 7, "sitl_seed": 3}, False),
    }


CASES = _cases()


@pytest.mark.parametrize("case", list(CASES))
def test_fault_matrix(fly, case):
    faults, overrides, expect_complete = CASES[case]
    overrides = dict(overrides)
    min_injected = overrides.pop("min_injected", 1)
    spec = Spec(faults=faults(), proxy_seed=overrides.pop("proxy_seed", 1), timeout_s=60.0, **overrides)
    o, verdict = fly(spec, expect_complete=expect_complete)
    assert not verdict, report(o, verdict)
    # (an undisturbed flight through the proxy is the baseline of test_hostile_streams.py)
    assert o.proxy["injected_bytes"] + o.proxy["mutated_bytes"] >= min_injected, \
        f"the fault acted too little: {o.proxy['faults']}"
