"""The paper's trends, checked on its own simulation numbers and on ours.

Each check is a statement about the three controllers the paper flew (``nlsoc``,
``loc``, ``pd``; the literal NLSOC law is ours only) on one experiment and one metric,
evaluated twice from numbers: on the paper's simulation column
(:mod:`gcs.campaign.paper`, None where the paper prints nothing) and on the campaign's
means (or standard deviations, for the dispersion checks).  Nothing here is prose
written in advance: ``paper`` and ``ours`` are computed booleans (None when a value is
missing, e.g. every run of a controller failed).

Checks per experiment (``err`` is the paper's error metric: ``J_e_setpoint`` indoors,
Table 1's definition, ``J_e`` outdoors; ``energy`` the paper's energy metric, ``J_u``
indoors and ``J_u_all`` outdoors, and ``J_u_hover`` — the thrust beyond hover, which is
what differs between controllers — for ours only):

* NLSOC lowest ``err``; LOC lowest energy; PD highest energy;
* the full ranking of ``err`` equals the paper's;
* NLSOC has the smallest standard deviation of ``err`` over the runs (Tables 3, 5; the
  paper's numbers are lost, its text claims it).
"""

from __future__ import annotations

from collections.abc import Sequence

from gcs.campaign.paper import PAPER_CONTROLLERS, PAPER_TABLES

__all__ = ["trend_checks", "format_trends_markdown", "ERROR_METRIC", "ENERGY_METRIC"]

#: The paper's error metric per experiment (our key).
ERROR_METRIC = {"indoor-4dof": "J_e_setpoint", "outdoor-altitude": "J_e", "outdoor-circle": "J_e"}
#: The paper's energy metric per experiment (our key).
ENERGY_METRIC = {"indoor-4dof": "J_u", "outdoor-altitude": "J_u_all", "outdoor-circle": "J_u_all"}

_TABLE_OF = {"indoor-4dof": 1, "outdoor-altitude": 2, "outdoor-circle": 4}
_STD_TABLE_OF = {"outdoor-altitude": 3, "outdoor-circle": 5}


def _paper_values(experiment: str, metric: str) -> dict | None:
    t = PAPER_TABLES.get(_TABLE_OF.get(experiment, 0))
    if t is None:
        return None
    for row in t.rows:
        if row.metric == metric:
            return dict(row.sim)
    return None


def _ours(agg: dict, experiment: str, metric: str, what: str = "mean") -> dict | None:
    block = agg["experiments"].get(experiment)
    if block is None:
        return None
    return {c: (block["controllers"].get(c, {}).get("metrics", {}).get(metric) or {}).get(what)
            for c in PAPER_CONTROLLERS}


def _complete(values: dict | None) -> bool:
    return values is not None and all(values.get(c) is not None for c in PAPER_CONTROLLERS)


def _lowest(values: dict | None, who: str) -> bool | None:
    if not _complete(values):
        return None
    return all(values[who] < values[c] for c in PAPER_CONTROLLERS if c != who)


def _highest(values: dict | None, who: str) -> bool | None:
    if not _complete(values):
        return None
    return all(values[who] > values[c] for c in PAPER_CONTROLLERS if c != who)


def _ranking(values: dict | None) -> list[str] | None:
    if not _complete(values):
        return None
    return sorted(PAPER_CONTROLLERS, key=lambda c: values[c])


def _agree(a: bool | None, b: bool | None) -> bool | None:
    return None if a is None or b is None else a == b


def trend_checks(agg: dict, experiments: Sequence[str]) -> list[dict]:
    """The checks (see the module docstring) for ``experiments``.

    Returns
    -------
    list of dict
        ``{"experiment", "table", "claim", "metric", "paper": bool | None, "ours": bool | None,
        "agree": bool | None, "paper_values": {ctl: v} | None, "our_values": {ctl: v} | None}``.
    """
    checks: list[dict] = []

    def add(exp, table, claim, metric, paper, ours, pv, ov) -> None:
        checks.append({"experiment": exp, "table": table, "claim": claim, "metric": metric, "paper": paper,
                       "ours": ours, "agree": _agree(paper, ours), "paper_values": pv, "our_values": ov})

    for exp in experiments:
        if exp not in agg["experiments"]:
            continue
        table = _TABLE_OF.get(exp)
        err, energy = ERROR_METRIC[exp], ENERGY_METRIC[exp]
        pe, oe = _paper_values(exp, err), _ours(agg, exp, err)
        add(exp, table, "NLSOC has the lowest tracking error", err, _lowest(pe, "nlsoc"), _lowest(oe, "nlsoc"), pe, oe)
        pu, ou = _paper_values(exp, energy), _ours(agg, exp, energy)
        oh = _ours(agg, exp, "J_u_hover")
        add(exp, table, "LOC uses the least energy", energy, _lowest(pu, "loc"), _lowest(ou, "loc"), pu, ou)
        add(exp, table, "LOC uses the least energy (thrust beyond hover)", "J_u_hover", _lowest(pu, "loc"),
            _lowest(oh, "loc"), pu, oh)
        add(exp, table, "PD uses the most energy", energy, _highest(pu, "pd"), _highest(ou, "pd"), pu, ou)
        add(exp, table, "PD uses the most energy (thrust beyond hover)", "J_u_hover", _highest(pu, "pd"),
            _highest(oh, "pd"), pu, oh)
        rp, ro = _ranking(pe), _ranking(oe)
        add(exp, table, "tracking-error ranking " + (" < ".join(c.upper() for c in rp) if rp else "(paper: n/a)"),
            err, None if rp is None else True, None if rp is None or ro is None else ro == rp, pe, oe)
        if exp in _STD_TABLE_OF:
            os_ = _ours(agg, exp, err, "std")
            add(exp, _STD_TABLE_OF[exp], "NLSOC has the smallest error dispersion over the runs", err + " (std)",
                True, _lowest(os_, "nlsoc"), None, os_)
    return checks


def _yn(v: bool | None) -> str:
    return "n/a" if v is None else ("yes" if v else "no")


def _vals(v: dict | None) -> str:
    if not v:
        return "-"
    return " / ".join("-" if v.get(c) is None else f"{v[c]:.4g}" for c in PAPER_CONTROLLERS)


def format_trends_markdown(checks: list[dict]) -> str:
    """The checks as one Markdown table."""
    out = ["| experiment | table | paper's trend | metric | holds in the paper's simulation | holds here | "
           "agree | paper NLSOC / LOC / PD | ours NLSOC / LOC / PD |",
           "|---|---:|---|---|---|---|---|---:|---:|"]
    for c in checks:
        paper = _yn(c["paper"]) + (" (text)" if c["paper_values"] is None and c["paper"] is not None else "")
        out.append(f"| {c['experiment']} | {c['table']} | {c['claim']} | `{c['metric']}` | {paper} | "
                   f"{_yn(c['ours'])} | {_yn(c['agree'])} | {_vals(c['paper_values'])} | {_vals(c['our_values'])} |")
    return "\n".join(out) + "\n"
