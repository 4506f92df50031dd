from pathlib import Path
import copy
import subprocess
import sys
import tomllib

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from gcs.config import bundled_configs, load_config, parse_config
from quadrotor.errors import ConfigError

CONFIGS = Path(__file__).resolve().parents[1] / "configs"


@pytest.fixture(scope="module")
def raw():
    with open(CONFIGS / "outdoor-altitude.toml", "rb") as fh:
        return tomllib.load(fh)


def reject(raw_doc, key, reason):
    with pytest.raises(ConfigError) as info:
        parse_config(raw_doc, "bad.toml")
    msg = str(info.value)
    assert msg.startswith("bad.toml: "), msg
    assert info.value.key == key, msg
    assert reason in msg, msg
    return msg


def mutate(raw_doc, path, value=...):
    doc = copy.deepcopy(raw_doc)
    node = doc
    for p in path[:-1]:
        node = node[p]
    if value is ...:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return doc


def test_bundled_configs_load():
    assert bundled_configs() == ["indoor-4dof", "outdoor-altitude", "outdoor-circle"]
    for name in bundled_configs():
        c = load_config(name)
        assert c.experiment.ts_s == 0.01
        assert set(c.loc) == {"z", "psi", "y_phi", "x_theta"}
        assert set(c.nlsoc) == {"z_psi", "y_phi", "x_theta"}


def test_paper_values(indoor, outdoor, circle):
    assert indoor.experiment.horizon_steps == 4000 and indoor.experiment.after_horizon == "pd"
    assert outdoor.experiment.horizon_s == 600.0 and circle.experiment.horizon_s == 60.0
    assert indoor.mission[0].z_m == 0.30 and indoor.mission[0].duration_s == 15.0
    q, r, h = indoor.loc["z"].resolved("corrected")
    np.testing.assert_array_equal(q, np.diag([0.56, 8.0]))
    assert r[0, 0] == 375.0
    assert outdoor.pd.kp_z == 42 and outdoor.pd.kp_x == 31 and outdoor.pd.kd_phi == 63
    assert circle.mission[1].kind == "circle" and circle.mission[1].radius_m == 1.0


def test_corrected_matrices_are_marked_and_printed_ones_selectable(outdoor):
    zp = outdoor.nlsoc["z_psi"]
    assert "Q" in zp.printed and "erratum 7" in zp.note
    q, _, _ = zp.resolved("corrected")
    qp, _, _ = zp.resolved("printed")
    assert q[3, 2] == 17000 and qp[3, 2] == 17500
    printed = outdoor.with_matrices("printed")
    assert printed.experiment.matrices == "printed"


@pytest.mark.parametrize("path,value,key,reason", [
    (("experiment", "bogus"), 1, "experiment.bogus", "unknown key"),
    (("bogus",), {}, "bogus", "unknown key"),
    (("experiment", "ts_s"), 0.0, "experiment.ts_s", "must be > 0"),
    (("experiment", "ts_s"), -0.01, "experiment.ts_s", "must be > 0"),
    (("experiment", "ts_s"), "fast", "experiment.ts_s", "must be a number"),
    (("experiment", "horizon_s"), 0.001, "experiment.horizon_s", "shorter than one step"),
    (("experiment", "after_horizon"), "hover", "experiment.after_horizon", "must be one of"),
    (("experiment", "name"), ..., "experiment.name", "missing"),
    (("experiment", "acceleration_reference"), "yes", "experiment.acceleration_reference", "must be"),
    (("nlsoc", "z_psi", "R"), [0.47, -0.5], "nlsoc.z_psi.R", "not positive definite"),
    (("nlsoc", "z_psi", "Q"), [[1.0, 2.0], [2.0, 1.0]], "nlsoc.z_psi.Q", "wrong shape: expected 4x4, got 2x2"),
    (("loc", "z", "Q"), [[1.0, 2.0], [3.0, 1.0]], "loc.z.Q", "not symmetric"),
    (("loc", "z", "H"), [[1.0, 2.0], [2.0, 1.0]], "loc.z.H", "indefinite"),
    (("loc", "z", "Q"), [[1.0, 0.0], [0.0]], "loc.z.Q", "wrong shape"),
    (("loc", "z", "bogus"), 1.0, "loc.z.bogus", "unknown key"),
    (("loc", "psi"), ..., "loc.psi", "missing"),
    (("pd", "kp_z"), -1.0, "pd.kp_z", "must be >= 0"),
    (("vehicle", "max_thrust_n"), 5.0, "vehicle.max_thrust_n", "cannot lift"),
    (("sim", "sensors", "altitude"), "lidar", "sim.sensors.altitude", "must be one of"),
    (("sim", "runs"), 0, "sim.runs", "must be >= 1"),
])
def test_rejections_name_the_key(raw, path, value, key, reason):
    reject(mutate(raw, path, value), key, reason)


@pytest.mark.parametrize("section", ["experiment", "vehicle", "mission", "loc", "nlsoc", "pd"])
def test_missing_sections(raw, section):
    reject(mutate(raw, (section,)), section, "missing section")


def test_printed_q_rejected_unless_printed_mode_is_asked_for(raw):
    doc = copy.deepcopy(raw)
    zp = doc["nlsoc"]["z_psi"]
    zp["Q"] = zp.pop("Q_printed")
    zp["corrected"] = []
    reject(doc, "nlsoc.z_psi.Q", "not symmetric (Q[3,4] = 17000 != Q[4,3] = 17500)")
    # Asking for the printed matrices flies Q_printed unchecked ...
    ok = mutate(raw, ("experiment", "matrices"), "printed")
    assert parse_config(ok, "ok.toml").experiment.matrices == "printed"
    # ... but every matrix without a printed variant is still checked.
    bad = mutate(ok, ("nlsoc", "z_psi", "H"), [[-4200.0, 3800.0, 0, 0], [3800.0, 4300.0, 0, 0],
                                               [0, 0, 17500.0, 16000.0], [0, 0, 16000.0, 17500.0]])
    reject(bad, "nlsoc.z_psi.H", "indefinite")


def test_paths_never_fall_back_to_bundled_configs(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        load_config(tmp_path / "outdoor-altitude.toml")
    assert load_config("outdoor-altitude.toml").experiment.name == "outdoor-altitude"


def test_horizon_and_duration_in_whole_steps(raw):
    reject(mutate(raw, ("experiment", "horizon_s"), 600.005), "experiment.horizon_s", "whole number of steps")
    reject(mutate(raw, ("experiment", "horizon_s"), 1e9), "experiment.horizon_s", "at most")
    reject(mutate(raw, ("experiment", "duration_s"), 0.001), "experiment.duration_s", "shorter than one step")


def test_same_as_and_mirror_errors(raw):
    reject(mutate(raw, ("loc", "x_theta", "same_as"), "z"), "loc.x_theta.same_as", "must be one of")
    reject(mutate(raw, ("loc", "x_theta", "mirror"), True), "loc.x_theta.mirror", "only NLSOC mirrors")


def test_non_utf8_file_is_a_config_error(tmp_path):
    bad = tmp_path / "bin.toml"
    bad.write_bytes(b"\xff\xfe[experiment]\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(bad)


def test_corrected_list_needs_the_printed_matrix(raw):
    reject(mutate(raw, ("nlsoc", "z_psi", "Q_printed")), "nlsoc.z_psi.Q_printed", "missing")


def test_mission_phase_errors(raw):
    phases = copy.deepcopy(raw["mission"]["phases"])
    phases[0]["kind"] = "loop"
    reject(mutate(raw, ("mission", "phases"), phases), "mission.phases[0].kind", "must be one of")
    reject(mutate(raw, ("mission", "phases"), [{"kind": "hold", "duration_s": 1.0}]),
           "mission.phases[0].kind", "needs a takeoff")
    reject(mutate(raw, ("mission", "phases"), [{"kind": "takeoff", "duration_s": -1.0, "z_m": 1.0}]),
           "mission.phases[0].duration_s", "must be > 0")


def test_load_config_errors(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[experiment\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(bad)
    with pytest.raises(ConfigError, match="no such file"):
        load_config(tmp_path / "missing.toml")


@settings(max_examples=40, deadline=None)
@given(st.dictionaries(st.sampled_from(["experiment", "vehicle", "mission", "loc", "nlsoc", "pd", "sim", "x"]),
                       st.one_of(st.integers(), st.text(max_size=3),
                                 st.dictionaries(st.text(max_size=3), st.integers(), max_size=2)),
                       max_size=8))
def test_garbage_documents_raise_config_errors_only(doc):
    with pytest.raises(ConfigError):
        parse_config(doc, "fuzz.toml")


def test_cli_exits_nonzero_with_the_key_and_no_traceback(tmp_path):
    text = (CONFIGS / "outdoor-altitude.toml").read_text().replace("ts_s = 0.01", "ts_s = -0.01")
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    p = subprocess.run([sys.executable, "-m", "gcs.cli", "sim", "--config", str(bad), "--duration", "1"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2
    assert "experiment.ts_s" in p.stderr and str(bad) in p.stderr
    assert "Traceback" not in p.stderr


def test_the_package_keeps_every_public_name_of_gcs_config():
    import gcs.config as config

    used = ("Config", "PhaseConfig", "PdGains", "AFTER_HORIZON", "MATRIX_MODES", "bundled_configs", "load_config",
            "parse_config", "resolve_config_path", "MatrixSet", "ExperimentConfig", "SimConfig", "EstimatorConfig",
            "FlightConfig", "PHASE_KINDS", "LOC_SUBSYSTEMS", "NLSOC_SUBSYSTEMS", "MAX_HORIZON_STEPS")
    assert set(used) <= set(config.__all__)
    assert all(callable(getattr(config, n)) or getattr(config, n) is not None for n in config.__all__)
    assert config.MAX_HORIZON_STEPS == 10_000_000 and config.LOC_SUBSYSTEMS["y_phi"] == (4, 1)
