"""``gcs campaign``: plan and seeded draws, flights through the full path, failures, determinism,
Dask against the local pool, the tables and RESULTS.md, and bad input.

The flights are real ``gcs fly --sitl lockstep`` runs with short missions (``--duration``),
so the whole module takes about a minute on two cores.  No assertion depends on timing.
"""

from __future__ import annotations

import dataclasses
import json
import textwrap
from pathlib import Path

import pytest

from gcs.campaign.errors import CampaignError
from gcs.campaign.executors import LocalExecutor
from gcs.campaign.plan import (EXPERIMENTS, CampaignOptions, DisturbanceModel, draw_disturbances, parse_durations,
                               plan_campaign)
from gcs.cli import main
from gcs.control import CONTROLLERS
from gcs.metrics import METRICS

SHORT = "6"  # mission seconds per test flight (then gcs fly lands)
OUTDOOR = ("outdoor-altitude", "outdoor-circle")


def _campaign(capsys, *args: str) -> tuple[int, str, str]:
    code = main(["campaign", *args])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def small_campaign(tmp_path_factory) -> Path:
    """``gcs campaign --experiment all --runs 2`` with short missions."""
    out = tmp_path_factory.mktemp("campaign") / "all"
    code = main(["campaign", "--experiment", "all", "--runs", "2", "--duration", SHORT, "--workers", "2",
                 "--seed", "3", "--out", str(out), "--horizons", "1,5", "-q",
                 "--results", str(out.parent / "docs" / "RESULTS.md")])
    assert code == 0, (out / "runs.json").read_text() if (out / "runs.json").exists() else "no runs.json"
    return out


# --------------------------------------------------------------------------- plan and draws
def test_draws_are_a_pure_function_of_seed_experiment_and_run():
    a = draw_disturbances(5, "outdoor-circle", 3, wind=(2.0, 0.7, 2.0))
    assert a == draw_disturbances(5, "outdoor-circle", 3, wind=(2.0, 0.7, 2.0))
    others = {draw_disturbances(5, "outdoor-circle", r, wind=(2.0, 0.7, 2.0)) for r in range(5)}
    assert len(others) == 5                                   # runs differ
    assert draw_disturbances(6, "outdoor-circle", 3, wind=(2.0, 0.7, 2.0)) != a   # seeds differ
    assert draw_disturbances(5, "outdoor-altitude", 3, wind=(2.0, 0.7, 2.0)) != a  # experiments differ
    speed, direction, gust, tau = a.wind
    assert 1.0 <= speed <= 3.0 and 0 <= direction < 360 and gust == 0.7 and tau == 2.0
    assert all(abs(v) <= 2.0 for v in a.start_attitude_deg[:2]) and abs(a.start_attitude_deg[2]) <= 10.0
    calm = draw_disturbances(5, "outdoor-circle", 3, wind=(2.0, 0.7, 2.0), model=DisturbanceModel(wind_scale=0.0))
    assert calm.wind is None and calm.seed == a.seed          # the seed stream does not depend on the options
    rig = draw_disturbances(5, "indoor-4dof", 3, mavlink=False)
    assert rig.wind is None and rig.start_attitude_deg is None and rig.sitl_args() == ()


def test_every_controller_meets_the_same_disturbances(tmp_path):
    plan = plan_campaign(CampaignOptions(("all",), 3, 11, str(tmp_path)))
    assert len(plan.jobs) == 3 * 3 * len(CONTROLLERS)
    for exp in EXPERIMENTS:
        for run in range(3):
            jobs = [j for j in plan.jobs if j.experiment == exp and j.run == run]
            assert sorted(j.controller for j in jobs) == sorted(CONTROLLERS)
            assert len({j.disturbances for j in jobs}) == 1
            strip = [dataclasses.replace(j.spec, controller="", log_path=None) for j in jobs]
            assert len(set(map(repr, strip))) == 1, strip          # the specs differ in the controller only
    assert plan == plan_campaign(CampaignOptions(("all",), 3, 11, str(tmp_path)))
    indoor = next(j for j in plan.jobs if j.experiment == "indoor-4dof")
    assert indoor.spec.vehicle == "rig" and indoor.spec.sitl_args == () and indoor.argv[:3] == ("fly", "--rig", "4dof")
    alt = next(j for j in plan.jobs if j.experiment == "outdoor-altitude")
    assert alt.spec.duration_s == 120.0 and alt.duration_s == 120.0
    assert alt.argv[alt.argv.index("--duration") + 1] == "120"
    circle = next(j for j in plan.jobs if j.experiment == "outdoor-circle")
    assert circle.spec.duration_s is None and "--duration" not in circle.argv   # the whole 60 s mission
    assert circle.spec.lockstep and circle.spec.builtin and circle.spec.log and circle.spec.log_path.endswith(".mcap")
    assert {"--sitl", "lockstep"} <= set(circle.argv) and "--log" in circle.argv


def test_parse_durations():
    assert parse_durations(["10"]) == {"*": 10.0}
    assert parse_durations(["outdoor-altitude=30", "5"]) == {"outdoor-altitude": 30.0, "*": 5.0}
    for bad in ("x", "nowhere=3", "outdoor-circle=-1", "0"):
        with pytest.raises(CampaignError):
            parse_durations([bad])


# --------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("args, words", [
    (["--experiment", "mars"], "unknown experiment 'mars'"),
    (["--runs", "0"], "--runs: must be >= 1"),
    (["--controllers", "lqg"], "unknown controller 'lqg'"),
    (["--duration", "-4"], "--duration"),
    (["--scheduler", "tcp://127.0.0.1:1"], "only with --executor dask"),
    (["--workers", "0"], "--workers: must be >= 1"),
])
def test_bad_input_is_one_line(capsys, tmp_path, args, words):
    code, out, err = _campaign(capsys, *args, "--out", str(tmp_path / "x"), "-q")
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gcs: error: ") and words in lines[0], err
    assert not (tmp_path / "x" / "runs.json").exists()


def test_bad_option_value_is_one_line(capsys):
    with pytest.raises(SystemExit) as exc:  # argparse's own errors exit from parse_args, as for every subcommand
        main(["campaign", "--wind-scale", "-1"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and len(err.strip().splitlines()) == 1
    assert err.startswith("gcs campaign: error: argument --wind-scale: must be >= 0")


# --------------------------------------------------------------------------- optimality
def test_optimality_only(capsys, tmp_path):
    code, out, err = _campaign(capsys, "--optimality-only", "--experiment", "outdoor-altitude", "--horizons", "1,5",
                               "--out", str(tmp_path))
    assert code == 0, err
    doc = json.loads((tmp_path / "optimality.json").read_text())
    rows = doc["rows"]
    assert {r["controller"] for r in rows} == set(CONTROLLERS)
    assert {r["convention"] for r in rows} == {"compensated", "literal"}
    assert {r["horizon_s"] for r in rows} == {1.0, 5.0}
    assert all(r["ratio"] >= 1.0 - 1e-9 for r in rows)
    assert "J/J_opt" in out and (tmp_path / "optimality.md").exists()
    code, out, err = _campaign(capsys, "--optimality-only", "--experiment", "outdoor-circle", "--out", str(tmp_path))
    assert code == 2 and "no" in err and "optimality" in err


# --------------------------------------------------------------------------- flights
def test_small_campaign_end_to_end(small_campaign):
    out = small_campaign
    runs = json.loads((out / "runs.json").read_text())
    flown = list(EXPERIMENTS)
    assert len(runs) == len(flown) * 2 * len(CONTROLLERS)
    assert all(r["status"] == "ok" and r["exit_code"] == 0 for r in runs), [r["detail"] for r in runs]
    for r in runs:
        assert Path(r["log_path"]).stat().st_size > 0 and Path(r["summary_path"]).exists()
        assert Path(r["output_path"]).exists()
        assert r["flown_s"] == pytest.approx(float(SHORT))
    tables = json.loads((out / "tables.json").read_text())
    numbers = {t["number"] for t in tables["tables"]}
    assert {1, 2, 3, 4, 5} <= numbers
    for exp in flown:
        block = tables["aggregate"]["experiments"][exp]["controllers"]
        for ctl in CONTROLLERS:
            m = block[ctl]["metrics"]
            assert block[ctl]["ok"] == 2 and set(m) <= set(METRICS) and {"J_u", "J_e", "rms_error_m"} <= set(m)
            assert all(v["n"] == 2 and v["std"] >= 0 for v in m.values())
        assert "J" not in block["pd"]["metrics"] and "J" in block["nlsoc"]["metrics"]
    md = (out / "tables.md").read_text()
    assert "### Table 2" in md and "### Table 4" in md and "paper NLSOC sim" in md and "±" in md
    campaign = json.loads((out / "campaign.json").read_text())
    assert campaign["timing"]["vehicle_s"] == pytest.approx(sum(r["flown_s"] for r in runs))
    assert campaign["plan"]["jobs"][0]["argv"][:2] == ["gcs", "fly"]
    figs = sorted(p.relative_to(out).as_posix() for p in (out / "figures").rglob("*.png"))
    for exp in flown:
        for name in [*CONTROLLERS, "overlay_altitude", "overlay_control", "overlay_track", "overlay_attitude",
                     "overlay_velocity"]:
            assert f"figures/{exp}/{name}.png" in figs
    opt = json.loads((out / "optimality.json").read_text())
    assert {r["experiment"] for r in opt["rows"]} == {"indoor-4dof", "outdoor-altitude"}


def test_results_md_generated(small_campaign):
    out = small_campaign
    text = (out / "RESULTS.md").read_text()
    assert text == (out.parent / "docs" / "RESULTS.md").read_text()   # --results copies it
    for heading in ("## Tables 1–5", "### Table 2", "### Table 4", "## The paper's trends", "### Why they differ",
                    "## Optimality gap of the altitude subproblem", "## Failed runs", "## Figures"):
        assert heading in text
    checks = json.loads((out / "trends.json").read_text())
    claims = {(c["experiment"], c["claim"]) for c in checks}
    assert ("outdoor-circle", "NLSOC has the lowest tracking error") in claims
    for c in checks:
        assert c["ours"] in (True, False)                    # every controller has numbers
        values = c["our_values"]
        if c["claim"] == "NLSOC has the lowest tracking error":
            assert c["ours"] == (values["nlsoc"] < min(values["loc"], values["pd"]))
            assert c["paper"] is True                           # the paper's own columns say so
    assert "| outdoor-circle | 4 | NLSOC has the lowest tracking error | `J_e` | yes |" in text
    assert "None: every run completed." in text


def test_same_seed_same_tables(small_campaign, tmp_path):
    """A second campaign with the same seed, run 0 of every experiment (the rig included): each
    flight's numbers equal the first campaign's — the draws depend on (seed, experiment, run)
    only and lockstep flights do not depend on wall time."""
    out = tmp_path / "again"
    assert main(["campaign", "--experiment", "all", "--runs", "1", "--controllers", "loc,nlsoc",
                 "--duration", SHORT, "--workers", "2", "--seed", "3", "--out", str(out), "--no-figures", "-q",
                 "--horizons", "1"]) == 0

    def key(r):
        return (r["experiment"], r["controller"], r["run"])

    first = {key(r): r for r in json.loads((small_campaign / "runs.json").read_text())}
    again = json.loads((out / "runs.json").read_text())
    assert len(again) == 3 * 2
    for r in again:
        assert r["metrics"] == first[key(r)]["metrics"], key(r)


def test_dask_and_local_give_identical_tables(small_campaign, tmp_path):
    """The fixture's campaign ran on the local pool; the same campaign (two of its controllers) on a
    local Dask cluster of two worker processes gives the same tables."""
    pytest.importorskip("distributed")
    ctls = ("nlsoc", "pd")
    out = tmp_path / "dask"
    assert main(["campaign", "--experiment", "outdoor-altitude", "--runs", "2", "--controllers", ",".join(ctls),
                 "--duration", SHORT, "--workers", "2", "--seed", "3", "--no-figures", "-q", "--horizons", "1,5",
                 "--out", str(out), "--executor", "dask"]) == 0
    runs = json.loads((out / "runs.json").read_text())
    assert len(runs) == 4 and all(r["status"] == "ok" for r in runs)
    local = json.loads((small_campaign / "tables.json").read_text())
    dask = json.loads((out / "tables.json").read_text())
    lb, db = (d["aggregate"]["experiments"]["outdoor-altitude"]["controllers"] for d in (local, dask))
    assert db == {c: lb[c] for c in ctls}
    lt, dt = ({t["number"]: t for t in d["tables"]} for d in (local, dask))
    for n in (2, 3):
        assert [{**r, "ours": {c: r["ours"][c] for c in ctls}} for r in lt[n]["rows"]] == dt[n]["rows"]


FAULTS = textwrap.dedent("""
    import os, signal, time

    def die(spec, **kwargs):
        os._exit(9)

    def hang(spec, **kwargs):
        time.sleep(3600)

    def hang_hard(spec, **kwargs):
        signal.signal(signal.SIGALRM, signal.SIG_IGN)
        time.sleep(3600)

    def boom(spec, **kwargs):
        raise RuntimeError("deliberate")
""")


def test_failed_runs_are_reported_and_the_rest_complete(tmp_path, monkeypatch):
    from gcs.campaign.campaign import execute, write_outputs

    (tmp_path / "faults").mkdir()
    (tmp_path / "faults" / "campaign_faults.py").write_text(FAULTS)
    monkeypatch.setenv("PYTHONPATH", str(tmp_path / "faults"))
    out = tmp_path / "out"
    plan = plan_campaign(CampaignOptions(("outdoor-circle",), 3, 2, str(out), controllers=("pd", "loc"),
                                         durations={"*": 3.0}))
    jobs = list(plan.jobs)
    # run 0: pd flies with a bad option (a config error, exit 2); loc's worker dies.  run 1: pd hangs, loc raises.
    # run 2: pd ignores the deadline signal (killed by the pool), loc flies normally.
    jobs[0] = dataclasses.replace(jobs[0], spec=dataclasses.replace(jobs[0].spec, stale_timeout_s=-1.0))
    jobs[1] = dataclasses.replace(jobs[1], entry="campaign_faults:die")
    jobs[2] = dataclasses.replace(jobs[2], entry="campaign_faults:hang", timeout_s=1.0)
    jobs[3] = dataclasses.replace(jobs[3], entry="campaign_faults:boom")
    jobs[4] = dataclasses.replace(jobs[4], entry="campaign_faults:hang_hard", timeout_s=1.0)
    assert [(j.controller, j.run) for j in jobs] == [("pd", 0), ("loc", 0), ("pd", 1), ("loc", 1), ("pd", 2),
                                                     ("loc", 2)]
    with LocalExecutor(2, grace_s=2.0) as ex:
        results = execute(jobs, ex)
    status = {r.key: r.status for r in results}
    assert status == {"outdoor-circle/pd/run00": "failed", "outdoor-circle/loc/run00": "crashed",
                      "outdoor-circle/pd/run01": "timeout", "outdoor-circle/loc/run01": "crashed",
                      "outdoor-circle/pd/run02": "timeout", "outdoor-circle/loc/run02": "ok"}
    bad = results[0]
    assert bad.exit_code == 2 and "telemetry_stale_s" in bad.detail and Path(bad.output_path).exists()
    assert "RuntimeError: deliberate" in Path(results[3].output_path).read_text()   # the traceback is kept
    assert "timed out" in Path(results[2].output_path).read_text()
    plan = dataclasses.replace(plan, jobs=tuple(jobs))
    files = write_outputs(out, plan, results, {"command": "test", "plan": plan.to_json()}, figures=False,
                          horizons_s=(1.0,))
    agg = json.loads(Path(files["tables.json"]).read_text())["aggregate"]
    ctl = agg["experiments"]["outdoor-circle"]["controllers"]
    assert ctl["loc"]["ok"] == 1 and ctl["loc"]["failed"] == 2 and ctl["loc"]["metrics"]["J_e"]["n"] == 1
    assert ctl["pd"]["ok"] == 0 and ctl["pd"]["metrics"] == {}
    assert [f["key"] for f in agg["failed"]] == sorted(k for k, s in status.items() if s != "ok")
    report = Path(files["RESULTS.md"]).read_text()
    for key, s in status.items():
        if s != "ok":
            assert f"| {key} | {s} |" in report


def test_cli_failed_flights_exit_1_and_are_listed(capsys, tmp_path):
    # A stale timeout that parses but that the config refuses (fewer than 3 messages): each flight fails (exit 2).
    code, out, err = _campaign(capsys, "--experiment", "outdoor-circle", "--runs", "1", "--controllers", "pd",
                               "--duration", "2", "--workers", "1", "--fly-arg=--stale-timeout=0.004", "--no-figures",
                               "--out", str(tmp_path), "-q")
    assert code == 1
    assert "failed run outdoor-circle/pd/run00: failed" in err and "1 flights (1 failed)" in out
    assert "| outdoor-circle/pd/run00 | failed | 2 |" in (tmp_path / "RESULTS.md").read_text()


def test_cli_bad_fly_args_are_refused_before_anything_flies(capsys, tmp_path):
    code, out, err = _campaign(capsys, "--experiment", "outdoor-circle", "--runs", "1", "--controllers", "pd",
                               "--fly-arg=--output=bogus", "--out", str(tmp_path), "-q")
    assert code == 2 and "--fly-arg" in err and not (tmp_path / "runs").exists()
    code, out, err = _campaign(capsys, "--experiment", "outdoor-circle", "--runs", "1", "--fly-arg=--seed=3",
                               "--out", str(tmp_path), "-q")
    assert code == 2 and "the campaign sets seed" in err


def test_indoor_campaign(small_campaign):
    """The fixture's campaign flew the indoor rig too (``gcs fly --rig 4dof``): Table 1."""
    tables = json.loads((small_campaign / "tables.json").read_text())
    assert 1 in [t["number"] for t in tables["tables"]]
    block = tables["aggregate"]["experiments"]["indoor-4dof"]["controllers"]
    assert all(c["ok"] == 2 for c in block.values())
    jobs = json.loads((small_campaign / "campaign.json").read_text())["plan"]["jobs"]
    indoor = [j for j in jobs if j["experiment"] == "indoor-4dof"]
    assert len(indoor) == 2 * len(CONTROLLERS) and all(j["argv"][1:4] == ["fly", "--rig", "4dof"] for j in indoor)
