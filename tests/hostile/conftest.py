"""The hostile-link suite: fixtures, and a report of what was injected (``pytest tests/hostile``).

Every flight through the proxy is recorded in :data:`hostile_kit.REGISTRY`; at the end of the
session a table is printed: per test the exit code, the wall time, the bytes injected, and the
total against the suite's floor of 10**6 injected bytes.
"""

from __future__ import annotations

import pytest

import hostile_kit

#: The suite's floor: the default run injects at least this many bytes in total.
SUITE_INJECTED_FLOOR = 10 ** 6


@pytest.fixture
def fly(request, tmp_path):
    """``fly(spec, **check_kw) -> (outcome, problems)``: one flight through the proxy in its own folder;
    the flight is recorded for the session report."""
    count = [0]

    def run(spec: hostile_kit.Spec, **check_kw):
        count[0] += 1
        o = hostile_kit.run_flight(spec, tmp_path / f"flight{count[0]}")
        return o, hostile_kit.check(request, o, **check_kw)

    return run


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    reg = hostile_kit.REGISTRY
    if not reg:
        return
    tr = terminalreporter
    tr.section("hostile link: flights through the proxy")
    total = sum(r["injected_bytes"] for r in reg)
    mutated = sum(r["mutated_bytes"] for r in reg)
    per_fault: dict[str, int] = {}
    for r in reg:
        for name, f in r["faults"].items():
            per_fault[name] = per_fault.get(name, 0) + f["injected_bytes"] + f["mutated_bytes"]
    for r in reg:
        tr.write_line(f"{'FAIL' if r['problems'] else 'ok  '} {r['test'].split('::')[-1]:<48} exit {r['rc']!s:>4} "
                      f"{r['reason']!s:<18} {r['wall_s']:6.1f} s  injected {r['injected_bytes']:>9} B  "
                      f"mutated {r['mutated_bytes']:>8} B")
    tr.write_line("per fault (injected + mutated bytes): "
                  + ", ".join(f"{k} {v}" for k, v in sorted(per_fault.items(), key=lambda kv: -kv[1])))
    tr.write_line(f"total injected {total} B, mutated {mutated} B over {len(reg)} flights "
                  f"(suite floor {SUITE_INJECTED_FLOOR} B injected: "
                  f"{'met' if total >= SUITE_INJECTED_FLOOR else 'NOT met in this selection'})")
