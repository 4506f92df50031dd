"""Fixtures of the SITL tests: servers on ephemeral ports and a small pymavlink ground station."""

from __future__ import annotations

import threading

import pytest
from sitl_testkit import Gcs

from sitl.copter.server import SitlServer
from sitl.net.udp import UdpTransport


@pytest.fixture
def make_server():
    """Factory of started servers (UDP, ephemeral port, lockstep by default); all stopped afterwards."""
    servers: list[SitlServer] = []

    def make(lockstep: bool = True, transport=None, **kwargs) -> SitlServer:
        srv = SitlServer(transport or UdpTransport(("127.0.0.1", 0)), lockstep=lockstep, **kwargs)
        servers.append(srv)
        return srv.start()

    yield make
    for srv in servers:
        srv.stop()


@pytest.fixture
def make_gcs():
    """Factory of connected :class:`Gcs` clients (heartbeat received); all closed afterwards."""
    clients: list[Gcs] = []

    def make(server_or_string, hello: bool = True, **kwargs) -> Gcs:
        cs = server_or_string if isinstance(server_or_string, str) else server_or_string.connection_string
        g = Gcs(cs, hello=hello, **kwargs)
        clients.append(g)
        assert g.wait_heartbeat() is not None, "no heartbeat from the SITL"
        return g

    yield make
    for g in clients:
        g.close()


def _server_threads() -> set[threading.Thread]:
    return {t for t in threading.enumerate() if t.name == "sitl-server"}


@pytest.fixture(autouse=True)
def no_leaked_server_threads():
    """Every test stops the servers it started (module fixtures' servers are checked at the end)."""
    before = _server_threads()
    yield
    leaked = _server_threads() - before
    assert not leaked, f"server threads left running: {leaked}"


@pytest.fixture(scope="session", autouse=True)
def no_server_threads_at_the_end():
    yield
    assert not _server_threads(), "server threads left running after the SITL tests"
