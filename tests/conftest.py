"""Shared fixtures: the bundled configs, loaded once per session."""

import os
import tempfile
from pathlib import Path

import pytest

from gcs.config import load_config

ROOT = Path(__file__).resolve().parents[1]
# Parameter journals of flights against external vehicles (gcs.vehicles.params) go to a folder of this
# test session, never to the user's ~/.local/state/gcs; subprocesses inherit it.
os.environ.setdefault("GCS_STATE_DIR", tempfile.mkdtemp(prefix="gcs-test-state-"))
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
