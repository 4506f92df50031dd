"""Simulated flights logged at every tick, and the review tools on them: metrics equal the run's."""

import json
import math
import re
import struct
import sys
from itertools import pairwise

import numpy as np
import pytest

from gcs.cli import main
from gcs.config import load_config
from gcs.control import make_controller
from gcs.errors import LogError
from gcs.log.writer import FlightLog
from gcs.log import topics as T
from gcs.log.mcap.reader import read_log
from gcs.log.meta import write_run_header
from gcs.log.records import Tick
from gcs.log.review import compare_logs, export_csv, log_info, log_metrics
from gcs.log.review.flights import logged_metrics, split_flights
from gcs.log.sink import BackgroundSink
from gcs.metrics import controller_cost, summarize
from gcs.model import SUBSYSTEMS
from gcs.sim import SimOptions, simulate

CONTROLLERS = ("nlsoc", "loc", "pd")
DURATION_S = 5.0


@pytest.fixture(scope="module")
def circle_cfg():
    return load_config("outdoor-circle")


@pytest.fixture(scope="module")
def sim_log(tmp_path_factory, circle_cfg):
    """Two runs of three controllers (sensor noise on) in one log, and the runs themselves."""
    path = tmp_path_factory.mktemp("simlog") / "sim.mcap"
    runs = []
    designed = {n: make_controller(n, circle_cfg) for n in CONTROLLERS}
    with FlightLog(path) as log:
        write_run_header(log, circle_cfg, CONTROLLERS, designed, source="sim")
        for name in CONTROLLERS:
            for i in range(2):
                runs.append(simulate(circle_cfg, name, run=i, options=SimOptions(duration_s=DURATION_S),
                                     designed=designed[name], log=log))
    return path, runs


def test_metrics_from_the_log_equal_the_run(sim_log):
    path, runs = sim_log
    rows = logged_metrics(read_log(path))
    assert [(r["controller"], r["run"]) for r in rows] == [(r.controller, r.run) for r in runs]
    for row, run in zip(rows, runs):
        assert row["metrics"] == run.metrics  # exact, not approximately
        assert row["in_run"] == run.metrics and not row["partial"]
        assert row["steps"] == run.record.command.shape[0]


def test_logged_series_are_the_flown_ones(sim_log):
    path, runs = sim_log
    log = read_log(path)
    flights = split_flights(log)
    assert [f.controller for f in flights] == [r.controller for r in runs]
    ts_ns = 10_000_000
    for fl, run in zip(flights, runs):
        k = run.record.command.shape[0]
        assert fl.steps == k and fl.ts_s == 0.01 and fl.source == "sim"
        truth = [m for t, m in log.decoded(T.TRUTH) if fl.start_ns <= t < (fl.end_ns or 1 << 62)]
        assert len(truth) == k + 1
        assert np.array_equal([[m[f] for f in T.STATE_FIELDS] for m in truth], run.record.state)
    # Flights follow each other on the time line; ticks are ts apart.
    for a, b in pairwise(flights):
        assert b.start_ns == a.start_ns + a.steps * ts_ns + 1_000_000_000
    times = [t for t, _ in log.decoded(T.COMMAND)][:600]
    assert np.all(np.diff(times[:int(DURATION_S * 100)]) == ts_ns)
    # Horizon: the PD flights say so, the finite-horizon ones count down.
    modes = {m["mode"] for _, m in log.decoded(T.HORIZON)}
    assert modes == {"horizon", "pd"}
    first = log.decoded(T.HORIZON)[:2]
    assert first[0][1] == {"k": 0, "steps_to_go": 6000, "mode": "horizon"} and first[1][1]["steps_to_go"] == 5999
    # Phase changes are events at their times.
    events = log.decoded(T.EVENTS)
    phases = [(t, m["phase"]) for t, m in events if m["kind"] == "phase" and t < flights[1].start_ns]
    assert phases == [(0, "takeoff")]  # the circle starts at 8 s, after these 5 s flights
    kinds = [m["kind"] for _, m in events]
    assert kinds.count("flight_start") == kinds.count("flight_end") == len(runs)
    # The error is reference - estimate.
    est = log.decoded(T.STATE)[100][1]
    ref = log.decoded(T.REFERENCE)[100][1]
    err = log.decoded(T.ERROR)[100][1]
    assert err["z"] == ref["z"] - est["z"]


def test_stage_costs_add_up_to_J(sim_log, circle_cfg):
    path, runs = sim_log
    log = read_log(path)
    flights = split_flights(log)
    for fl, run in zip(flights, runs):
        costs = [m for t, m in log.decoded(T.COST) if fl.start_ns <= t < (fl.end_ns or 1 << 62)]
        if run.controller == "pd":
            assert costs == []
            continue
        spec = controller_cost(run.controller, circle_cfg)
        k = run.record.command.shape[0]
        assert len(costs) == k and spec.horizon_steps > k
        idx = list(SUBSYSTEMS["z" if spec.kind == "loc" else "z_psi"])
        x = run.record.state[k, idx] - run.record.ref[k, idx]
        if spec.kind != "loc":
            x[2] = (x[2] + math.pi) % (2 * math.pi) - math.pi
        total = sum(c["stage_cost"] for c in costs) + 0.5 * x @ spec.H @ x
        assert total == pytest.approx(run.metrics["J"], rel=1e-9)
        assert all(c["stage_cost"] == pytest.approx(c["state_cost"] + c["input_cost"]) for c in costs)


def test_attachments_and_metadata(sim_log, circle_cfg):
    path, _ = sim_log
    log = read_log(path, None)
    md = log.metadata_dict("flight")
    assert md["controller"] == "nlsoc,loc,pd" and md["experiment"] == "outdoor-circle" and md["source"] == "sim"
    import gcs
    assert md["software_version"] == gcs.__version__ and md["start_time_utc"].endswith("+00:00")
    assert json.loads(log.attachment("config.json").data) == json.loads(json.dumps(dict(circle_cfg.raw)))
    assert log.attachment("config.toml").data.startswith(b"#") or b"[experiment]" in log.attachment("config.toml").data
    loc = json.loads(log.attachment("gains/loc.json").data)
    assert loc["kind"] == "loc" and loc["horizon_steps"] == 6000 and len(loc["tables"]["z"][0]) == 2
    assert loc["fallback"]["kind"] == "pd"
    assert json.loads(log.attachment("gains/nlsoc.json").data)["subsystems"]["z_psi"]["Q"]
    assert json.loads(log.attachment("gains/pd.json").data)["gains"]["kp_z"] > 0


def test_background_writer_writes_the_same_log(tmp_path, circle_cfg, sim_log):
    _, runs = sim_log
    path = tmp_path / "bg.mcap"
    with BackgroundSink(path, overflow="wait") as log:
        write_run_header(log, circle_cfg, ["loc"], {})
        bg_run = simulate(circle_cfg, "loc", run=1, options=SimOptions(duration_s=DURATION_S), log=log)
    assert log.stats["flights"] == 1 and log.stats["bytes"] == path.stat().st_size
    rows = logged_metrics(read_log(path))
    assert rows[0]["metrics"] == bg_run.metrics == runs[3].metrics


def test_background_writer_reports_failures(tmp_path):
    path = tmp_path / "bad.mcap"
    log = BackgroundSink(path, overflow="wait")
    with pytest.raises(TypeError, match="not a log record"):
        log.put_many(["not a record"])  # refused here, before it travels
    with pytest.raises(LogError, match="log writer failed: ValueError: expected 12 values"):
        log.put_many([Tick(0, 0, (1.0, 2.0), (0.0,) * 12, (0.0,) * 4, None, 0, "pd")])  # fails in the writer
        log.close()
    assert read_log(path, None).message_count == 0  # the file was finished nonetheless
    blocker = tmp_path / "f"
    blocker.write_text("")
    with pytest.raises(LogError, match="cannot create the log directory"):
        BackgroundSink(blocker / "x.mcap", overflow="wait")


def test_gcs_sim_logs_and_gcs_log_metrics_recomputes_its_table(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    args = ["sim", "--config", "indoor-4dof", "--controller", "all", "--runs", "2", "--duration", "2", "--json"]
    assert main(args) == 0
    out, err = capsys.readouterr()
    sim_doc = json.loads(out)
    files = list((tmp_path / "logs").glob("*.mcap"))
    assert len(files) == 1, "one file per gcs sim invocation"
    assert re.fullmatch(r"\d{8}T\d{6}Z_all_indoor-4dof\.mcap", files[0].name)
    assert main(["log", "metrics", str(files[0]), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["results"] == sim_doc["results"]  # exactly the figures gcs sim printed
    assert len(doc["flights"]) == 8 and all(f["in_run_match"] for f in doc["flights"])
    # --log PATH and --no-log
    assert main(args[:-1] + ["-q", "--log", str(tmp_path / "mine" / "x.mcap")]) == 0
    assert (tmp_path / "mine" / "x.mcap").is_file()
    assert main(args + ["--no-log"]) == 0
    assert len(list((tmp_path / "logs").glob("*.mcap"))) == 1
    # An option the simulation rejects leaves no empty log behind.
    capsys.readouterr()
    assert main(["sim", "--config", "indoor-4dof", "--wind", "--duration", "1", "--log", str(tmp_path / "w.mcap")]) == 2
    assert not (tmp_path / "w.mcap").exists()


def test_info(sim_log):
    path, runs = sim_log
    info = log_info(path)
    assert not info["truncated"] and info["experiment"] == "outdoor-circle"
    assert info["controllers"] == list(CONTROLLERS)
    assert [f["controller"] for f in info["flights"]] == [r.controller for r in runs]
    chans = {c["topic"]: c for c in info["channels"]}
    assert chans[T.STATE]["messages"] == 6 * 500 and chans[T.STATE]["rate_hz"] == pytest.approx(100.0)
    assert chans[T.TRUTH]["messages"] == 6 * 501
    assert {e["kind"] for e in info["events"]} == {"flight_start", "phase", "flight_end"}


def test_cli_info_metrics_compare_export(sim_log, tmp_path, capsys):
    path, runs = sim_log
    assert main(["log", "info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "status      complete" in out and "/control/state" in out and "flight_start" in out
    assert main(["log", "metrics", str(path)]) == 0
    out = capsys.readouterr().out
    assert "equal to the in-run metrics" in out and "RMS position error [m]" in out
    assert main(["log", "compare", str(path), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc["groups"]) == set(CONTROLLERS)
    assert main(["log", "export", str(path), "--csv", str(tmp_path / "csv")]) == 0
    assert (tmp_path / "csv" / "control_state.csv").is_file()


def test_compare_across_files_and_controllers(tmp_path, circle_cfg, sim_log):
    _, runs = sim_log
    paths = []
    for name in ("loc", "pd"):
        p = tmp_path / f"{name}.mcap"
        with FlightLog(p) as log:
            write_run_header(log, circle_cfg, [name])
            for i in range(2):
                simulate(circle_cfg, name, run=i, options=SimOptions(duration_s=DURATION_S), log=log)
        paths.append(p)
    doc = compare_logs(paths)
    assert doc["groups"] == {"loc": {"controller": "loc", "experiment": "outdoor-circle", "flights": 2},
                             "pd": {"controller": "pd", "experiment": "outdoor-circle", "flights": 2}}
    for name in ("loc", "pd"):
        assert doc["results"][name] == summarize([r.metrics for r in runs if r.controller == name])
    assert "J" in doc["results"]["loc"] and "J" not in doc["results"]["pd"]
    # Different experiments are told apart.
    other = tmp_path / "indoor.mcap"
    indoor = load_config("indoor-4dof")
    with FlightLog(other) as log:
        write_run_header(log, indoor, ["pd"])
        simulate(indoor, "pd", options=SimOptions(duration_s=1.0), log=log)
    doc = compare_logs(paths + [other])
    assert set(doc["groups"]) == {"loc @ outdoor-circle", "pd @ outdoor-circle", "pd @ indoor-4dof"}


def test_export_csv(sim_log, tmp_path):
    path, _ = sim_log
    res = export_csv(path, tmp_path / "csv")
    log = read_log(path, None)
    by_topic = {c["topic"]: c for c in res["channels"]}
    assert set(by_topic) == set(log.counts)
    for topic, c in by_topic.items():
        assert c["rows"] == log.counts[topic]
    lines = (tmp_path / "csv" / "control_state.csv").read_text().splitlines()
    assert lines[0] == "log_time_ns,t_s,flight," + ",".join(T.STATE_FIELDS)
    assert len(lines) == 1 + log.counts[T.STATE]
    horizon = (tmp_path / "csv" / "control_horizon.csv").read_text().splitlines()
    assert horizon[1] == "0,0.000000000,0,0,6000,horizon"


def test_plot_writes_a_png_with_the_panels(sim_log, tmp_path):
    pytest.importorskip("matplotlib")
    from gcs.log.review.plot import PANELS, plot_log

    path, _ = sim_log
    out = tmp_path / "flight.png"
    res = plot_log(path, out, flight=2)
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", data[16:24])
    assert (width, height) == (1300, 1200) and len(data) > 50_000
    assert [t.split(" (")[0] for t in res["panels"]] == list(PANELS)
    assert res["flight"] == "#2 loc run 0"
    with pytest.raises(LogError, match="no flight 9"):
        plot_log(path, out, flight=9)


def test_plot_without_matplotlib_is_a_clear_error(sim_log, tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "matplotlib.figure", None)
    path, _ = sim_log
    assert main(["log", "plot", str(path), "-o", str(tmp_path / "x.png")]) == 1
    err = capsys.readouterr().err
    assert "needs matplotlib" in err and "pip install matplotlib" in err and err.count("\n") == 1


def test_tools_on_a_truncated_sim_log(sim_log, tmp_path, capsys):
    path, runs = sim_log
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:int(len(data) * 0.55)])
    info = log_info(cut)
    assert info["truncated"] and info["problem"]
    doc = log_metrics(cut)
    assert doc["truncated"] and 1 <= len(doc["flights"]) < len(runs)
    complete = [f for f in doc["flights"] if not f["partial"]]
    for f in complete:
        assert f["metrics"] == runs[f["flight"]].metrics
    assert doc["flights"][-1]["partial"]
    for args in (["info"], ["metrics"], ["compare"], ["export", "--csv", str(tmp_path / "csv")]):
        assert main(["log", args[0], str(cut)] + args[1:]) == 0
        err = capsys.readouterr().err
        assert "is TRUNCATED" in err, args


def test_flight_log_metrics_use_the_estimate_and_the_limited_command(tmp_path, circle_cfg, sim_log):
    # A gcs fly style log: no truth; the loop logs the estimate, and the envelope's output.
    from gcs.metrics import FlightRecord, flight_metrics
    from gcs.mission import Mission

    _, runs = sim_log
    rec = runs[2].record  # loc run 0
    k = rec.command.shape[0]
    path = tmp_path / "fly.mcap"
    with FlightLog(path) as log:
        write_run_header(log, circle_cfg, ["loc"], source="flight")
        log.flight_start(5_000, controller="loc", experiment="outdoor-circle", ts_s=0.01)
        for i in range(k):
            t = 5_000 + i * 10_000_000
            log.control_tick(t, state=rec.state[i], reference=rec.ref[i], command=rec.command[i] * 2.0,
                             command_limited=rec.command[i], k=i, steps_to_go=int(rec.steps_to_go[i]))
    rows = logged_metrics(read_log(path))
    assert len(rows) == 1 and rows[0]["controller"] == "loc" and rows[0]["in_run"] is None
    expect = FlightRecord(0.01, rec.state[:k], rec.ref[:k], rec.command[:k - 1], rec.steps_to_go[:k - 1])
    mission = Mission(circle_cfg.mission, zero_velocity=circle_cfg.experiment.zero_velocity_reference)
    assert rows[0]["metrics"] == flight_metrics(expect, circle_cfg, mission, controller_cost("loc", circle_cfg))


def test_streamed_metrics_equal_the_in_memory_ones(sim_log, tmp_path, circle_cfg):
    from gcs.log.review.stream import stream_metrics

    path, runs = sim_log
    _, rows = stream_metrics(path)
    assert rows == logged_metrics(read_log(path))
    # Messages out of flight order: the stream notices and reads the log whole.
    rec = runs[0].record
    odd = tmp_path / "odd.mcap"
    with FlightLog(odd) as log:
        write_run_header(log, circle_cfg, ["nlsoc"])
        log.flight_start(10**9, controller="nlsoc", ts_s=0.01)
        for i in range(50):
            log.control_tick(10**9 + i * 10**7, state=rec.state[i], reference=rec.ref[i], command=rec.command[i],
                             k=i, truth=rec.state[i])
        log.write_values(T.TRUTH, 5 * 10**8, rec.state[0])  # before the flight began
    _, rows = stream_metrics(odd)
    assert rows == logged_metrics(read_log(odd)) and rows[0]["steps"] == 49
