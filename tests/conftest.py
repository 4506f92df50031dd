"""Shared fixtures: the bundled configs, loaded once per session."""

from pathlib import Path

import pytest

from gcs.config import load_config

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"


@pytest.fixture(scope="session")
def indoor():
    return load_config(CONFIGS / "indoor-4dof.toml")


@pytest.fixture(scope="session")
def outdoor():
    return load_config(CONFIGS / "outdoor-altitude.toml")


@pytest.fixture(scope="session")
def circle():
    return load_config(CONFIGS / "outdoor-circle.toml")
