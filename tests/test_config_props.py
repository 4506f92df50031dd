"""Property: a mutated bundled config loads into a Config of finite floats, or is a ConfigError.

Random keys of the bundled documents are replaced by random floats (nan and inf included),
integers (huge ones included), strings, lists and nested lists, or tables; keys are added
and removed.  Whatever the mutation, parsing either gives a Config whose every float
(recursively through dataclasses, tuples and mappings) is finite, or raises ConfigError;
nothing else.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import tomllib
from collections.abc import Mapping
from pathlib import Path

from hypothesis import HealthCheck, event, given, settings, strategies as st

from gcs.config import Config, parse_config
from quadrotor.errors import ConfigError

CONFIGS = Path(__file__).resolve().parents[1] / "configs"
DOCS = [tomllib.loads(p.read_text()) for p in sorted(CONFIGS.glob("*.toml"))]

scalars = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-300, -1e-300, 1e300, -1e300, 0.01, 1.0, 100.0, 1e7, 1e12, 1e13]),
    st.integers(min_value=-(2 ** 70), max_value=2 ** 70),
    st.sampled_from([0, 1, -1, 10 ** 400]),
    st.booleans(),
    st.text(max_size=4),
)
values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=5),
                                                      st.dictionaries(st.text(max_size=4), inner, max_size=3)),
                      max_leaves=12)


def _nested(depth: int) -> list:
    v: list = [1.0]
    for _ in range(depth):
        v = [v]
    return v


deep_lists = st.integers(min_value=1, max_value=200).map(_nested)
names = st.sampled_from(["mass_kg", "ts_s", "z_m", "Q", "R", "runs", "seed", "telemetry_rate_hz", "center_m",
                         "bogus", "duration_s", "ceiling_m", "kind", "same_as", "wind", "sensors", "flight"])


def _paths(node, path=()):
    """Every path into a document (table keys and list indices), the root excluded."""
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for k, v in items:
        yield path + (k,)
        yield from _paths(v, path + (k,))


def _tables(node, path=()):
    if isinstance(node, dict):
        yield path
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for k, v in items:
        yield from _tables(v, path + (k,))


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _at(doc, path):
    for p in path:
        doc = doc[p]
    return doc


@st.composite
def mutated(draw):
    doc = copy.deepcopy(draw(st.sampled_from(DOCS)))
    for _ in range(draw(st.integers(min_value=1, max_value=3))):
        op = draw(st.sampled_from(["scale", "scale", "number", "number", "replace", "delete", "add"]))
        if op in ("scale", "number"):  # a number (or an entry of a vector or matrix) changes
            spots = [p for p in _paths(doc) if _is_number(_at(doc, p))]
            if spots:
                path = draw(st.sampled_from(spots))
                old = _at(doc, path[:-1])[path[-1]]
                scale = op == "scale" and abs(old) < 1e300  # nan fails the comparison: replaced, not scaled
                new = old * draw(st.floats(min_value=0.5, max_value=2.0)) if scale else draw(scalars)
                _at(doc, path[:-1])[path[-1]] = new
            continue
        if op == "add":
            table = _at(doc, draw(st.sampled_from(list(_tables(doc)))))
            table[draw(names)] = draw(st.one_of(values, deep_lists))
            continue
        paths = list(_paths(doc))
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = _at(doc, path[:-1])
        if op == "delete":
            del parent[path[-1]]
        else:
            parent[path[-1]] = draw(st.one_of(values, deep_lists))
    return doc


def _floats(obj, where="config"):
    """(where, value) of every float inside a Config (dataclasses, tuples, lists, mappings)."""
    if isinstance(obj, float):
        yield where, obj
    elif dataclasses.is_dataclass(obj):
        for f in dataclasses.fields(obj):
            if f.name != "raw":
                yield from _floats(getattr(obj, f.name), f"{where}.{f.name}")
    elif isinstance(obj, (tuple, list)):
        for i, v in enumerate(obj):
            yield from _floats(v, f"{where}[{i}]")
    elif isinstance(obj, Mapping):
        for k, v in obj.items():
            yield from _floats(v, f"{where}.{k}")


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated())
def test_mutated_configs_load_finite_or_raise_config_error(doc):
    try:
        config = parse_config(doc, "fuzz.toml")
    except ConfigError as exc:
        event("ConfigError")
        assert str(exc).startswith("fuzz.toml"), str(exc)
        assert len(str(exc)) < 1000, "messages stay short whatever the value"
        return
    event("loaded")
    assert isinstance(config, Config)
    bad = [(w, v) for w, v in _floats(config) if not math.isfinite(v)]
    assert not bad, bad


def test_the_unmutated_documents_load():
    for doc in DOCS:
        config = parse_config(copy.deepcopy(doc), "ok.toml")
        assert all(math.isfinite(v) for _, v in _floats(config))
