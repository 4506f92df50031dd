"""Every number of a config and of a vehicle file is finite and within its range of the one table.

The table-driven test sets each key of ``gcs.config.bounds.BOUNDS`` (found in, or added to,
the bundled configs) to nan, +-inf, +-1e300 and 1e-300, and expects a ConfigError naming
that key and giving the allowed range; a last test checks that no key of the table went
untested.
"""

from __future__ import annotations

import copy
import math
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from gcs.config import BOUNDS, PhaseConfig, bound_for, load_config, parse_config
from quadrotor.errors import ConfigError
from gcs.metrics import controller_cost, flight_metrics
from gcs.mission import Mission
from gcs.sim import SimError, SimOptions, check_run, run_experiment, simulate
from sitl.copter.vehicle_file import VEHICLE_BOUNDS, load_vehicle, parse_vehicle

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"
NAMES = ("outdoor-circle", "indoor-4dof", "outdoor-altitude")
DOCS = {n: tomllib.loads((CONFIGS / f"{n}.toml").read_text()) for n in NAMES}
BAD = (math.nan, math.inf, -math.inf, 1e300, -1e300, 1e-300)

# Keys the bundled configs leave out, with a valid value to put there (the bad one replaces it).
ABSENT = {
    "sim.wind.direction_deg": 90.0, "sim.wind.vertical_m_s": 0.0, "estimator.disturbance_time_constant_s": 2.0,
    **{f"flight.{k}": v for k, v in {
        "telemetry_rate_hz": 100.0, "telemetry_stale_s": 0.3, "max_tilt_deg": 35.0, "fence_half_width_m": 20.0,
        "ceiling_m": 10.0, "rate_gain_1_s": [65.0, 65.0, 80.0], "inertia_kg_m2": [0.01, 0.01, 0.018],
        "max_torque_nm": [1.9, 1.9, 0.2], "position_std_m": 0.05, "velocity_std_m_s": 0.05,
        "landing_speed_m_s": 0.5, "min_battery_v": 10.5, "land_timeout_s": 30.0,
        "rate_integral_max_rad": [0.1, 0.1, 0.2], "rate_response_s": 0.04, "tracking_lost_m": 1.0,
        "tracking_lost_s": 2.0}.items()},
}


def _number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _cases():
    """(config, path to the value, index inside a list or None, the key the error must name)."""
    out = []
    for name, doc in DOCS.items():
        def walk(node, path, key, name=name):
            for k, v in node.items():
                p, kk = path + (k,), f"{key}.{k}" if key else k
                if isinstance(v, dict):
                    if v.get("same_as") is None:  # a same_as subsystem has no matrices of its own
                        walk(v, p, kk, name)
                elif k == "phases":
                    for i, ph in enumerate(v):
                        walk(ph, p + (i,), f"{kk}[{i}]", name)
                elif _number(v):
                    out.append((name, p, None, kk))
                elif isinstance(v, list) and v and all(_number(x) for x in v):
                    out.append((name, p, len(v) - 1, kk))
                elif isinstance(v, list) and v and all(isinstance(r, list) for r in v):
                    out.append((name, p, (len(v) - 1, 0), kk))
        walk(doc, (), "")
    for key in ABSENT:
        out.append(("outdoor-circle", tuple(key.split(".")), None if _number(ABSENT[key]) else 0, key))
    return out


CASES = _cases()


def _set(doc, path, index, value):
    node = doc
    for p in path[:-1]:
        node = node.setdefault(p, {}) if isinstance(p, str) else node[p]
    if index is None:
        node[path[-1]] = value
        return
    if path[-1] not in node:
        node[path[-1]] = copy.deepcopy(ABSENT[".".join(path)])
    target = node[path[-1]]
    if isinstance(index, tuple):
        target[index[0]][index[1]] = value
    else:
        target[index] = value


@pytest.mark.parametrize("bad", BAD, ids=repr)
@pytest.mark.parametrize("name,path,index,key", CASES, ids=[f"{c[0]}:{c[3]}" for c in CASES])
def test_every_number_rejects_non_finite_and_absurd_values(name, path, index, key, bad):
    doc = copy.deepcopy(DOCS[name])
    _set(doc, path, index, bad)
    bound = bound_for(key)
    if bad == 1e-300 and bound.lo <= 1e-300:
        # A tiny positive value is in range here: the config loads, or fails on the same key
        # for another reason (an R of 1e-300 is not positive definite).
        try:
            parse_config(doc, "bad.toml")
        except ConfigError as exc:
            assert exc.key == key, str(exc)
        return
    with pytest.raises(ConfigError) as info:
        parse_config(doc, "bad.toml")
    exc = info.value
    assert exc.key == key and exc.source == "bad.toml", str(exc)
    assert "allowed [" in exc.reason and (bound.unit in exc.reason), exc.reason
    assert str(exc).startswith(f"bad.toml: {key}: must be "), str(exc)


def test_every_key_of_the_table_is_exercised():
    tested = {re.sub(r"\[\d+\]", "[]", k) for _, _, _, k in CASES} | {"--duration"}
    untested = set(BOUNDS) - tested
    # Only matrices the bundled configs do not write (same_as subsystems, absent printed variants)
    # go untested here; they share the one matrix-entry bound with those that are.
    assert all(k.startswith(("loc.", "nlsoc.")) for k in untested), sorted(untested)
    assert {bound_for(k) for k in BOUNDS if k.startswith(("loc.", "nlsoc."))} == {bound_for("loc.z.Q")}
    assert "loc.z.Q" in tested and "nlsoc.z_psi.Q_printed" in tested


def test_the_reported_cases():
    circle = DOCS["outdoor-circle"]
    cases = [
        (("mission", "phases", 1, "center_m"), [math.nan, 0.0], "mission.phases[1].center_m", "must be finite"),
        (("flight",), {"telemetry_rate_hz": 1e-40}, "flight.telemetry_rate_hz", "at least 1 Hz"),
        (("flight",), {"telemetry_rate_hz": 1e300}, "flight.telemetry_rate_hz", "at most 1000 Hz"),
        (("sim", "sensors", "altitude_noise_std_m"), 1e300, "sim.sensors.altitude_noise_std_m", "at most 10 m"),
        (("estimator", "accel_noise_std_m_s2"), 1e300, "estimator.accel_noise_std_m_s2", "at most 1000 m/s^2"),
        (("vehicle", "mass_kg"), 1e-300, "vehicle.mass_kg", "at least 0.01 kg"),
        (("sim", "plant_substep_s"), 1e-300, "sim.plant_substep_s", "at least 1e-05 s"),
        (("vehicle", "mass_kg"), 10 ** 400, "vehicle.mass_kg", "at most 100 kg"),
        (("sim", "runs"), 10 ** 9, "sim.runs", "at most 10000"),
        (("pd", "kp_z"), 1e8, "pd.kp_z", "at most 1e+07"),
        (("loc", "z", "Q"), [1e13, 1.0], "loc.z.Q", "at most 1e+12"),
    ]
    for path, value, key, words in cases:
        doc = copy.deepcopy(circle)
        _set(doc, path, None, value)
        with pytest.raises(ConfigError) as info:
            parse_config(doc, "c.toml")
        assert info.value.key == key and words in info.value.reason, str(info.value)


@pytest.mark.parametrize("flight,ok", [({"telemetry_rate_hz": 10.0}, True), ({"telemetry_rate_hz": 9.0}, False),
                                       ({"telemetry_stale_s": 0.03}, True), ({"telemetry_stale_s": 0.02}, False),
                                       ({"telemetry_rate_hz": 1.0, "telemetry_stale_s": 3.0}, True)])
def test_telemetry_rate_must_fit_three_messages_into_the_stale_timeout(flight, ok):
    doc = copy.deepcopy(DOCS["outdoor-circle"])
    doc["flight"] = flight
    if ok:
        parse_config(doc, "c.toml")
        return
    with pytest.raises(ConfigError) as info:
        parse_config(doc, "c.toml")
    assert info.value.key == "flight.telemetry_rate_hz" and "at least 3 messages" in info.value.reason


def test_cross_checks_of_substep_drag_and_phase_length():
    def reject(mutations, key, words):
        doc = copy.deepcopy(DOCS["outdoor-altitude"])
        for path, value in mutations:
            _set(doc, path, None, value)
        with pytest.raises(ConfigError) as info:
            parse_config(doc, "a.toml")
        assert info.value.key == key and words in info.value.reason, str(info.value)

    # ts / substep at most 10000: with ts = 1 s the sub-step must be >= 1e-4 s.
    ok = copy.deepcopy(DOCS["outdoor-altitude"])
    for path, value in ((("experiment", "ts_s"), 1.0), (("experiment", "horizon_s"), 600.0),
                        (("mission", "phases", 0, "duration_s"), 10.0), (("sim", "plant_substep_s"), 1e-4)):
        _set(ok, path, None, value)
    assert parse_config(ok, "a.toml").sim.plant_substep_s == 1e-4
    reject([(("experiment", "ts_s"), 1.0), (("sim", "plant_substep_s"), 5e-5)], "sim.plant_substep_s", "at most 10000")
    reject([(("sim", "plant_substep_s"), 0.02)], "sim.plant_substep_s", "longer than the control period")
    # A drag time constant shorter than the plant sub-step would not integrate stably.
    reject([(("vehicle", "mass_kg"), 0.05), (("vehicle", "drag_n_per_m_s"), 100.0)], "vehicle.drag_n_per_m_s",
           "shorter than sim.plant_substep_s")
    reject([(("mission", "phases", 1, "duration_s"), 0.005)], "mission.phases[1].duration_s",
           "shorter than one control period")


def test_messages_say_range_and_unit():
    doc = copy.deepcopy(DOCS["outdoor-circle"])
    doc["flight"] = {"max_tilt_deg": 95.0}
    with pytest.raises(ConfigError) as info:
        parse_config(doc, "c.toml")
    assert str(info.value) == ("c.toml: flight.max_tilt_deg: must be at most 89 deg, got 95; allowed [1, 89] deg "
                               "(the tilt limit; at 90 deg thrust has no vertical part)")


# --------------------------------------------------------------------------- TOML nesting

def test_deeply_nested_arrays_are_a_config_error_not_a_traceback(tmp_path):
    text = (CONFIGS / "outdoor-circle.toml").read_text()
    bad = tmp_path / "deep.toml"
    bad.write_text(text.replace("mass_kg = 1.0", "mass_kg = " + "[" * 500 + "]" * 500))
    with pytest.raises(ConfigError) as info:
        load_config(bad)
    assert info.value.source == str(bad) and "nested too deeply" in info.value.reason
    p = subprocess.run([sys.executable, "-m", "gcs.cli", "sim", "--config", str(bad), "--no-log"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert p.stderr.startswith(f"gcs: error: {bad}: not valid TOML"), p.stderr
    # Nesting tomllib does parse is rejected with a short message.
    shallow = tmp_path / "shallow.toml"
    shallow.write_text(text.replace("mass_kg = 1.0", "mass_kg = " + "[" * 50 + "1" + "]" * 50))
    with pytest.raises(ConfigError) as info:
        load_config(shallow)
    assert info.value.key == "vehicle.mass_kg" and len(str(info.value)) < 300


def test_deeply_nested_vehicle_file_is_a_vehicle_config_error(tmp_path):
    bad = tmp_path / "deep.toml"
    bad.write_text("[vehicle]\nmass_kg = " + "[" * 600 + "]" * 600 + "\n")
    with pytest.raises(ConfigError, match="nested too deeply"):
        load_vehicle(bad)


# --------------------------------------------------------------------------- durations

def test_duration_shorter_than_one_control_period_is_refused(circle):
    with pytest.raises(ConfigError) as info:
        circle.with_duration(0.001)
    assert info.value.key == "--duration"
    assert info.value.reason.startswith("must be at least one control period (0.01 s)")
    for bad in (math.nan, math.inf, -1.0, 1e300, "10", True):
        with pytest.raises(ConfigError) as info:
            circle.with_duration(bad)
        assert info.value.key == "--duration", bad
    assert [p.duration_s for p in circle.with_duration(0.01).mission] == [0.01]
    # A cut that would leave a phase shorter than one period drops it.
    assert [p.duration_s for p in circle.with_duration(8.005).mission] == [8.0]
    assert [p.kind for p in circle.with_duration(8.5).mission] == ["takeoff", "circle"]


def test_cli_fly_refuses_a_duration_below_one_period_before_connecting():
    p = subprocess.run([sys.executable, "-m", "gcs.cli", "fly", "--duration", "0.001", "--no-log"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert "--duration: must be at least one control period (0.01 s)" in p.stderr


@pytest.mark.parametrize("steps", [1, 2])
def test_metrics_of_flights_of_one_or_two_steps(circle, steps):
    cfg = circle.with_duration(steps * 0.01)
    run = simulate(cfg, "loc", options=SimOptions(duration_s=steps * 0.01))
    assert run.record.command.shape[0] == steps
    assert set(run.metrics) >= {"J", "J_u", "J_e", "steady_state_error_m", "overshoot_m", "rms_error_m"}
    assert all(math.isfinite(v) for v in run.metrics.values()), run.metrics
    # A hold window between two samples (no sample inside) measures the last sample before its end.
    mission = Mission([PhaseConfig("takeoff", 0.011, z_m=1.5), PhaseConfig("hold", 0.005)])
    m = flight_metrics(run.record, cfg, mission, controller_cost("loc", cfg))
    assert all(math.isfinite(v) for v in m.values()), m
    last = steps - 1
    assert m["steady_state_error_m"] == pytest.approx(run.record.ref[last, 2] - run.record.state[last, 2])


def test_sim_refuses_huge_runs_and_durations_up_front(indoor):
    assert check_run(indoor) == (10, 60.0)
    with pytest.raises(SimError, match="--runs: must be a whole number from 1 to 10000"):
        run_experiment(indoor, ["pd"], runs=10 ** 12)
    for d in (1e12, math.nan, math.inf, 0.004, 10 ** 400):
        with pytest.raises(SimError, match="--duration: must be a number of seconds"):
            check_run(indoor, 1, SimOptions(duration_s=d))


# --------------------------------------------------------------------------- vehicle files

MINIMAL = {"vehicle": {"mass_kg": 1.0, "inertia_kg_m2": [0.01, 0.01, 0.02]},
           "rotors": {"arm_length_m": 0.2, "max_thrust_n": 6.0}}
VECTORS = ("control.rate_p_1_s", "control.rate_i_1_s2")


@pytest.mark.parametrize("bad", BAD, ids=repr)
@pytest.mark.parametrize("key", sorted(VEHICLE_BOUNDS))
def test_every_vehicle_number_rejects_non_finite_and_absurd_values(key, bad):
    section, name = key.split(".")
    doc = copy.deepcopy(MINIMAL)
    b = VEHICLE_BOUNDS[key]
    value = [bad, 1.0, 1.0] if key in VECTORS or key == "vehicle.inertia_kg_m2" else bad
    if b.integer and bad == 1e-300:
        value = 0
    doc.setdefault(section, {})[name] = value
    if bad == 1e-300 and b.lo <= 1e-300 and not b.integer:
        try:
            parse_vehicle(doc, "v.toml")
        except ConfigError as exc:
            assert exc.key.startswith(section), str(exc)
        return
    with pytest.raises(ConfigError) as info:
        parse_vehicle(doc, "v.toml")
    assert info.value.key == key, str(info.value)
    assert "allowed [" in info.value.reason or "positive definite" in info.value.reason, str(info.value)


def test_vehicle_rates_the_physics_cannot_integrate_are_refused():
    def reject(changes, key, words):
        doc = copy.deepcopy(MINIMAL)
        for (section, name), value in changes.items():
            doc.setdefault(section, {})[name] = value
        with pytest.raises(ConfigError) as info:
            parse_vehicle(doc, "v.toml")
        assert info.value.key == key and words in info.value.reason, str(info.value)

    reject({("vehicle", "mass_kg"): 1e-300}, "vehicle.mass_kg", "at least 0.01 kg")
    # 99 N/(m/s) on 0.1 kg: a 1 ms drag time constant, as short as the physics step.
    reject({("vehicle", "mass_kg"): 0.1, ("drag", "linear_n_per_m_s"): 99.0}, "drag.linear_n_per_m_s",
           "integrates stably")
    reject({("drag", "rotational_n_m_s"): 9.0}, "drag.rotational_n_m_s", "integrates stably")
    reject({("vehicle", "inertia_kg_m2"): [1e-6, 1e-6, 1e-6]}, "vehicle.inertia_kg_m2", "inertia too small")
    assert parse_vehicle(copy.deepcopy(MINIMAL), "v.toml").mass_kg == 1.0
    assert load_vehicle("talon-550").mass_kg == 1.6  # the bundled vehicles are in range
