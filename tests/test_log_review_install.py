"""The review works after the main install (``pip install -e .``): what ``gcs log`` imports is a main dependency.

Issue 15 item 5: ``gcs log plot`` needed the ``[plot]`` extra.  These read pyproject.toml, so they fail
when a package the review tools import is moved back into an extra.
"""

from __future__ import annotations

import ast
import re
import sys
import tomllib
from importlib import metadata
from pathlib import Path

from gcs.log.review import plot

ROOT = Path(__file__).resolve().parents[1]
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
#: Imports of the log tools that are optional on purpose (each in an extra), with the feature that needs them.
OPTIONAL = {"jsonschema": "gcs log channels --validate (a clear error without it)",
            "foxglove": "gcs fly --live (the [live] extra; a warning without it, the flight and its log go on)"}


def _name(requirement: str) -> str:
    """The normalised distribution name of a requirement string (PEP 503)."""
    return re.sub(r"[-_.]+", "-", re.match(r"\s*([A-Za-z0-9][A-Za-z0-9._-]*)", requirement).group(1)).lower()


MAIN = {_name(r) for r in PROJECT["dependencies"]}


def _installed_with(names: set[str]) -> set[str]:
    """``names`` and what they require in turn (not their extras): what the main install brings."""
    out, todo = set(), list(names)
    while todo:
        name = todo.pop()
        if name in out:
            continue
        out.add(name)
        try:
            reqs = metadata.requires(name) or []
        except metadata.PackageNotFoundError:
            continue
        todo += [_name(r) for r in reqs if "extra ==" not in r.replace("extra==", "extra ==")]
    return out


def _imports(path: Path) -> set[str]:
    """Top-level names of every module ``path`` imports (at module level or inside functions)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module.split(".")[0])
    return out


def test_matplotlib_is_a_main_dependency_not_only_an_extra():
    assert "matplotlib" in MAIN, "gcs log plot must work after `pip install -e .`: matplotlib in [project].dependencies"


def test_every_third_party_import_of_the_review_tools_is_a_main_dependency():
    dists = metadata.packages_distributions()
    files = sorted((ROOT / "gcs" / "log").rglob("*.py")) + [ROOT / "gcs" / "campaign" / "figures.py"]
    seen = {}
    for f in files:
        for mod in _imports(f) - set(sys.stdlib_module_names) - {"gcs", "quadrotor", "sitl", "__future__"}:
            seen.setdefault(mod, set()).add(f.relative_to(ROOT).as_posix())
    assert "matplotlib" in seen  # the scan sees the lazy import in gcs/log/review/plot.py
    brought = _installed_with(MAIN)
    missing = {}
    for mod, where in seen.items():
        names = {_name(d) for d in dists.get(mod, [mod])}
        if not names & brought and mod not in OPTIONAL:
            missing[mod] = sorted(where)
    assert not missing, f"imported by the review tools but not brought by [project].dependencies: {missing}"
    extras = {_name(r) for reqs in PROJECT.get("optional-dependencies", {}).values() for r in reqs}
    for mod in OPTIONAL:
        assert {_name(d) for d in dists.get(mod, [mod])} & extras, f"{mod} ({OPTIONAL[mod]}) is in no extra"


def test_no_message_sends_the_user_to_the_plot_extra():
    assert "[plot]" not in plot.MATPLOTLIB_HINT and "pip install matplotlib" in plot.MATPLOTLIB_HINT
    for f in [*sorted((ROOT / "gcs").rglob("*.py")), *sorted((ROOT / "docs").glob("*.md")), ROOT / "README.md"]:
        assert "[plot]" not in f.read_text(), f
