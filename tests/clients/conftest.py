"""Fixtures of the ground-station client tests (helpers: :mod:`client_kit`)."""

from __future__ import annotations

import pytest
from client_kit import FLIGHT_SPEEDUP, start_sitl


@pytest.fixture
def sitl_port():
    """The SITL in real time."""
    yield from start_sitl()


@pytest.fixture
def fast_sitl_port():
    """The SITL at :data:`FLIGHT_SPEEDUP` times real time (for flights)."""
    yield from start_sitl("--speedup", str(FLIGHT_SPEEDUP))
