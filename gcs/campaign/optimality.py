"""The optimality gap of the altitude subproblem, as campaign output (JSON and Markdown).

A thin layer over :func:`gcs.optimal_affine.optimality_table`: each controller's eq. 17
cost on the affine z-psi model divided by the exact affine-LQ optimum, for several
horizons and both NLSOC input conventions (``compensated``: u = thrust - m g, what
``nlsoc`` minimises; ``literal``: u = thrust, the printed law).  It is computed from the
configs alone (no flight), so ``gcs campaign --optimality-only`` gives it in seconds.
"""

from __future__ import annotations

from dataclasses import asdict
from collections.abc import Sequence

from gcs.config import load_config
from gcs.control import CONTROLLERS
from gcs.optimal_affine import optimality_table

__all__ = ["optimality_rows", "format_optimality_markdown", "DEFAULT_HORIZONS_S"]

DEFAULT_HORIZONS_S = (1.0, 5.0, 20.0, 60.0)


def optimality_rows(configs: Sequence[str], horizons_s: Sequence[float] = DEFAULT_HORIZONS_S,
                    controllers: Sequence[str] = CONTROLLERS) -> list[dict]:
    """The rows of :func:`gcs.optimal_affine.optimality_table` for each config, as dicts.

    Parameters
    ----------
    configs : sequence of str
        Config names or paths.
    horizons_s : sequence of float
    controllers : sequence of str

    Returns
    -------
    list of dict
        Fields of :class:`gcs.optimal_affine.GapRow`.
    """

    rows = []
    for name in configs:
        rows += [asdict(r) for r in optimality_table(load_config(name), horizons_s, controllers)]
    return rows


def format_optimality_markdown(rows: Sequence[dict]) -> str:
    """One Markdown table per experiment and convention: J_controller / J_optimal per horizon."""
    what = {"compensated": "u = thrust − m g (what `nlsoc` minimises)",
            "literal": "u = thrust (the printed law, `nlsoc-literal`)"}
    keys: list[tuple[str, str]] = []
    for r in rows:
        if (r["experiment"], r["convention"]) not in keys:
            keys.append((r["experiment"], r["convention"]))
    out = []
    for exp, conv in keys:
        sel = [r for r in rows if r["experiment"] == exp and r["convention"] == conv]
        ctls = list(dict.fromkeys(r["controller"] for r in sel))
        horizons = list(dict.fromkeys(r["horizon_s"] for r in sel))
        out.append(f"#### `{exp}`: eq. 17 with {what.get(conv, conv)}")
        out.append("")
        out.append("| horizon [s] | J_optimal | " + " | ".join(f"{c} J/J_opt" for c in ctls)
                   + " | thrust-floor steps |")
        out.append("|---:|---:|" + "---:|" * len(ctls) + "---|")
        for h in horizons:
            by = {r["controller"]: r for r in sel if r["horizon_s"] == h}
            j_opt = next(iter(by.values()))["J_optimal"]
            floors = ", ".join(f"{c} {by[c]['thrust_floor_steps']}" for c in ctls if by[c]["thrust_floor_steps"])
            out.append(f"| {h:g} | {j_opt:.6g} | " + " | ".join(f"{by[c]['ratio']:.5g}" for c in ctls) +
                       f" | {floors or 'none'} |")
        out.append("")
    return "\n".join(out).rstrip() + "\n"
