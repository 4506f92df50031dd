"""Hostile-link soak: ``gcs fly`` against ``sitl`` through the man-in-the-middle proxy, >= 10**7 bytes.

Run: ``python benchmarks/bench_soak.py [--quick] [--json]``.

The proxy and the acceptance rules are the hostile-link suite's (``tests/hostile/mitm.py``,
``tests/hostile/hostile_kit/``): every datagram both ways goes through seeded faults — random
datagrams (up to 1400 B), garbage dense in 0xFD/0xFE frame starts, 1-byte 0xFD datagrams, garbage
inside datagrams, bit flips (bad CRCs), truncations, copies, reordering, frames of other system
ids, valid frames with NaN/inf fields from the vehicle's address and from a second address, and
(at a low rate) valid frames with huge values.  Flights (outdoor-circle, PD / NLSOC / LOC in turn,
``--lockstep``, 30 s missions; 10 s with ``--quick``) are flown one after another, each with its own
seeds, until the bytes injected reach the floor: 10**7 (2 * 10**6 with ``--quick``).

Printed: per fault, its events and the bytes it injected (bytes the legitimate peer never sent)
and mutated (legitimate datagrams it changed); per flight, its exit code and reason, the speed and
any acceptance rule it broke; the totals: non-finite or out-of-limit commands on the wire,
tracebacks, hangs (a flight over its deadline), flights that did not end acceptably.  Figures
beside their baseline: the speed of a flight under faults beside the same flight undisturbed
through the proxy.  Nothing asserts: the hostile-link suite (``pytest tests/hostile``) does.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

from benchlib import document, emit, met_text, row

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "hostile"))

import hostile_kit  # noqa: E402
from mitm import (BitFlip, Duplicate, GarbageDatagrams, HostileFields, InlineGarbage, LoneMagic,  # noqa: E402
                  OtherSystem, Reorder, Truncate)

NAN_INF = (float("nan"), float("inf"), float("-inf"))
CONTROLLERS = ("pd", "nlsoc", "loc")


def soak_faults(heavy: float = 1.0) -> list:
    """The soak's fault mix (``heavy`` scales the garbage volume)."""
    return [GarbageDatagrams(p=0.35 * heavy, max_len=1400, count=(1, 3)),
            GarbageDatagrams(p=0.08 * heavy, max_len=600, magic_rich=True),
            LoneMagic(p=0.01), InlineGarbage(p=0.03, max_len=64), BitFlip(p=0.003), Truncate(p=0.003),
            Duplicate(p=0.05), Reorder(p=0.1), OtherSystem(p=0.1),
            HostileFields(p=0.01, values=NAN_INF, name="nonfinite_fields"),
            HostileFields(p=0.01, alt=True, values=NAN_INF, name="other_source_address"),
            HostileFields(p=0.002, values=(1e38, -1e38), huge_time=True, name="huge_fields")]


def fly(spec: hostile_kit.Spec, work: Path, name: str) -> tuple[hostile_kit.Outcome, list[str]]:
    o = hostile_kit.run_flight(spec, work / name)
    return o, hostile_kit.problems(o)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10 s missions, floor 2*10**6 bytes")
    ap.add_argument("--json", action="store_true", help="text on stderr, one JSON document on stdout")
    ap.add_argument("--floor", type=float, default=None, help="bytes to inject (default 1e7; 2e6 with --quick)")
    ap.add_argument("--max-flights", type=int, default=12)
    args = ap.parse_args(argv)
    floor = int(args.floor or (2e6 if args.quick else 1e7))
    duration = 10.0 if args.quick else 30.0
    timeout = 60.0 + 4.0 * duration
    t_start = time.monotonic()
    flights: list[dict] = []
    per_fault: dict[str, dict[str, int]] = {}
    injected = mutated = 0
    with tempfile.TemporaryDirectory(prefix="bench_soak_") as tmp:
        work = Path(tmp)
        base, base_problems = fly(hostile_kit.Spec(faults=[], duration_s=duration, timeout_s=timeout), work, "baseline")
        base_ratio = (base.summary or {}).get("loop", {}).get("realtime_ratio")
        i = 0
        while injected < floor and i < args.max_flights:
            ctl = CONTROLLERS[i % len(CONTROLLERS)]
            spec = hostile_kit.Spec(faults=soak_faults(), proxy_seed=100 + i, sitl_seed=i, controller=ctl,
                                    duration_s=duration, timeout_s=timeout)
            o, probs = fly(spec, work, f"soak{i}")
            i += 1
            injected += o.proxy["injected_bytes"]
            mutated += o.proxy["mutated_bytes"]
            for name, f in o.proxy["faults"].items():
                d = per_fault.setdefault(name, dict.fromkeys(f, 0))
                for k, v in f.items():
                    d[k] += v
            m = o.monitor
            flights.append({"flight": i, "controller": ctl, "rc": o.rc, "reason": o.exit_reason, "wall_s": o.wall_s,
                            "realtime_ratio": (o.summary or {}).get("loop", {}).get("realtime_ratio"),
                            "injected_bytes": o.proxy["injected_bytes"], "mutated_bytes": o.proxy["mutated_bytes"],
                            "forwarded": o.proxy["forwarded"], "commands_checked": m["commands_checked"],
                            "bad_commands": len([v for v in m["violations"] if not v.startswith("vehicle:")]),
                            "traceback": "Traceback" in o.gcs_stderr or "Traceback" in o.sitl_stderr,
                            "hang": o.timed_out, "problems": probs, "stderr": o.last_stderr_line()[:200]})
            print(f"  flight {i}: {ctl}, exit {o.rc} ({o.exit_reason}), {o.wall_s:.1f} s wall, "
                  f"{o.proxy['injected_bytes'] / 1e6:.2f} MB injected, {len(probs)} rule(s) broken",
                  file=sys.stderr, flush=True)
    wall = time.monotonic() - t_start
    bad_cmds = sum(f["bad_commands"] for f in flights)
    tracebacks = sum(f["traceback"] for f in flights)
    hangs = sum(f["hang"] for f in flights)
    unacceptable = sum(bool(f["problems"]) for f in flights)
    completed = sum(f["rc"] == 0 for f in flights)
    ratios = [f["realtime_ratio"] for f in flights if f["realtime_ratio"]]
    ratio = statistics.median(ratios) if ratios else None
    d = {"floor_bytes": floor, "injected_bytes": injected, "mutated_bytes": mutated, "flights": flights,
         "faults": per_fault, "baseline": {"rc": base.rc, "realtime_ratio": base_ratio, "wall_s": base.wall_s,
                                           "problems": base_problems},
         "bad_commands": bad_cmds, "tracebacks": tracebacks, "hangs": hangs, "unacceptable_flights": unacceptable,
         "completed_flights": completed, "wall_s": wall, "duration_s": duration}
    rows = [
        row("bytes injected", injected, "B", target=f">= {floor:.0e} B", met=injected >= floor,
            note=f"{mutated} B of legitimate datagrams mutated besides"),
        row("non-finite / out-of-limit commands on the wire", bad_cmds, "", target="0", met=bad_cmds == 0),
        row("tracebacks (gcs fly, sitl)", tracebacks, "", target="0", met=tracebacks == 0),
        row("hangs (flight over its deadline)", hangs, "", target="0", met=hangs == 0),
        row("flights breaking an acceptance rule", unacceptable, "", target="0", met=unacceptable == 0,
            note=f"of {len(flights)}; {completed} completed (exit 0)"),
        row("lockstep speed under faults (x real time)", ratio, "x", baseline="the same flight undisturbed",
            baseline_value=base_ratio),
        row("bytes injected per wall second", injected / wall if wall else None, "B/s"),
    ]
    lines = [f"hostile-link soak: {len(flights)} flights of outdoor-circle {duration:g} s (lockstep, through the "
             f"proxy), {injected} B injected + {mutated} B mutated in {wall:.0f} s (floor {floor:.0e} B: "
             f"{met_text(injected >= floor)})",
             f"baseline (no faults): exit {base.rc}, {base_ratio or 0:.1f}x real time, {base.wall_s:.1f} s wall"
             + (f"; broke: {base_problems}" if base_problems else ""),
             "per fault:             events    injected B     mutated B   datagrams+  dropped"]
    for name, f in sorted(per_fault.items(), key=lambda kv: -(kv[1]["injected_bytes"] + kv[1]["mutated_bytes"])):
        lines.append(f"  {name:<20} {f['events']:>8} {f['injected_bytes']:>13} {f['mutated_bytes']:>13} "
                     f"{f['injected_datagrams']:>11} {f['dropped_datagrams']:>8}")
    lines.append("per flight:")
    for f in flights:
        lines.append(f"  {f['flight']:>2} {f['controller']:<6} exit {f['rc']!s:>4} {f['reason']!s:<18} "
                     f"{f['wall_s']:6.1f} s  {f['realtime_ratio'] or 0:5.1f}x  {f['injected_bytes']:>10} B  "
                     f"cmds {f['commands_checked']:>5} bad {f['bad_commands']}"
                     + (f"  | {f['problems'][0][:150]}" if f["problems"] else ""))
    lines.append(f"totals: {bad_cmds} bad commands, {tracebacks} tracebacks, {hangs} hangs, {unacceptable} of "
                 f"{len(flights)} flights broke a rule, {completed} completed")
    emit(document("soak", args.quick, d, rows), "\n".join(lines), args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
