"""Run every benchmark in this folder: ``python benchmarks/run.py [--quick]``.

Each ``bench_*.py`` is run in its own process (so one's imports and caches do
not skew another's) with the arguments given here; the outputs are printed
one after the other and also written to ``benchmarks/results/latest.txt``.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    out_dir = HERE / "results"
    out_dir.mkdir(exist_ok=True)
    report = []
    status = 0
    for bench in sorted(HERE.glob("bench_*.py")):
        print(f"== {bench.name}", flush=True)
        p = subprocess.run([sys.executable, str(bench), *args], capture_output=True, text=True)
        text = p.stdout + (p.stderr if p.returncode else "")
        print(text, flush=True)
        report.append(f"== {bench.name}\n{text}")
        status = status or p.returncode
    (out_dir / "latest.txt").write_text("\n".join(report))
    return status


if __name__ == "__main__":
    sys.exit(main())
