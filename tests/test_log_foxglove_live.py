"""``gcs fly --live``: the log's channels on the Foxglove WebSocket protocol, checked with a ``websockets``
client speaking it (advertise, subscribe, message data)."""

from __future__ import annotations

import asyncio
import json
import math
import socket
import struct
import subprocess
import sys
import time

import jsonschema
import pytest
import websockets

from gcs.cli import main
from gcs.log import foxglove as F
from gcs.log import topics as T
from gcs.log.foxglove_live import LIVE_TOPICS, LiveServer, parse_address, tee
from gcs.log.mcap.reader import read_log
from gcs.log.writer import FlightLog

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
#: Foxglove WS binary opcode of a message (then uint32 subscription id, uint64 log time [ns], payload).
MESSAGE_DATA = 0x01


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


async def _first_message(port: int, topic: str, timeout_s: float, alive=lambda: True) -> tuple[dict, int, bytes]:
    """Connect (retrying while the server starts), wait for ``topic`` to be advertised, subscribe, and return
    ``(its channel, log time, payload)`` of the first message. A connection the server closes first (a
    viewer it dropped) is made again while ``alive()`` and time is left, as Foxglove reconnects."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return await _first_message_once(port, topic, deadline)
        except websockets.exceptions.ConnectionClosed:
            if not alive() or time.monotonic() > deadline:
                raise


async def _first_message_once(port: int, topic: str, deadline: float) -> tuple[dict, int, bytes]:
    while True:
        try:
            ws = await websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS, open_timeout=5)
            break
        except (OSError, websockets.exceptions.WebSocketException):
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.05)
    async with ws:
        assert ws.subprotocol in SUBPROTOCOLS
        channel = None
        while channel is None:
            msg = json.loads(await asyncio.wait_for(ws.recv(), deadline - time.monotonic()))
            if msg.get("op") == "advertise":
                channel = next((c for c in msg["channels"] if c["topic"] == topic), None)
        # A subscription racing the channel's advertisement is refused by the SDK ("unknown channel"):
        # subscribe again (a new id) every second until data comes, as a viewer would.
        sub_id, subscribed_at = 3, -math.inf
        while True:
            if time.monotonic() - subscribed_at > 1.0:
                sub_id += 1
                await ws.send(json.dumps({"op": "subscribe",
                                          "subscriptions": [{"id": sub_id, "channelId": channel["id"]}]}))
                subscribed_at = time.monotonic()
            try:
                msg = await asyncio.wait_for(ws.recv(), min(1.0, deadline - time.monotonic()))
            except TimeoutError:
                if time.monotonic() > deadline:
                    raise
                continue
            if isinstance(msg, bytes) and msg[0] == MESSAGE_DATA:
                sub, t = struct.unpack_from("<IQ", msg, 1)
                assert 3 < sub <= sub_id
                return channel, t, msg[13:]


def test_parse_address():
    assert parse_address("8765") == ("127.0.0.1", 8765)
    assert parse_address("0.0.0.0:9000") == ("0.0.0.0", 9000)
    assert parse_address("[::1]:0") == ("::1", 0)
    for bad in ("x", "70000", "host:", ":5", "-1"):
        with pytest.raises(ValueError, match="HOST:]PORT"):
            parse_address(bad)


def test_a_bad_address_is_a_usage_error_and_live_needs_the_log(capsys):
    with pytest.raises(SystemExit) as e:
        main(["fly", "--live", "nope"])
    assert e.value.code == 2 and "--live" in capsys.readouterr().err
    assert main(["fly", "--live", "8765", "--no-log"]) == 2
    assert "not with --no-log" in capsys.readouterr().err


def test_the_topics_of_every_flight_are_advertised_before_their_first_message():
    live = LiveServer("127.0.0.1", 0, topics=LIVE_TOPICS)
    try:
        async def advertised() -> set[str]:
            async with websockets.connect(f"ws://127.0.0.1:{live.port}", subprotocols=SUBPROTOCOLS,
                                          open_timeout=5) as ws:
                seen: set[str] = set()
                while not set(LIVE_TOPICS) <= seen:
                    m = json.loads(await asyncio.wait_for(ws.recv(), 30))
                    if m.get("op") == "advertise":
                        seen |= {c["topic"] for c in m["channels"]}
                return seen

        seen = asyncio.run(advertised())
    finally:
        live.close()
    assert set(LIVE_TOPICS) <= seen and live.published == 0


def test_a_log_served_live_gives_the_same_messages(tmp_path):
    live = LiveServer("127.0.0.1", 0)
    try:
        log = FlightLog(tmp_path / "x.mcap")
        tee(log, live)
        state = (1.0, 2.0, 3.0, 0, 0, 0, 0.1, 0.0, 0.5, 0, 0, 0)

        async def run() -> tuple[dict, int, bytes]:
            task = asyncio.create_task(_first_message(live.port, T.FOXGLOVE_VEHICLE_POSE, 60))
            k = 0
            while not task.done():  # a flight's log, while the viewer connects and subscribes
                log.add([(T.FOXGLOVE_VEHICLE_POSE, F.pose_json(k * 10_000_000, state)),
                         (T.STATE, b'{"x":1}')], k * 10_000_000)
                k += 1
                await asyncio.sleep(0.01)
            return task.result()

        channel, t, payload = asyncio.run(run())
        log.close()
    finally:
        live.close()
    assert channel["schemaName"] == "foxglove.PoseInFrame" and channel["encoding"] == "json"
    assert channel["schemaEncoding"] == "jsonschema" and json.loads(channel["schema"]) == T.schema_for(
        T.FOXGLOVE_VEHICLE_POSE)[1]
    logged = dict(read_log(tmp_path / "x.mcap").messages[T.FOXGLOVE_VEHICLE_POSE])
    assert logged[t] == payload  # the bytes of the file, at its time
    assert live.failed == 0 and live.published >= 2


def test_gcs_fly_live_serves_the_vehicle_pose(tmp_path):
    port = _free_port()
    log = tmp_path / "live.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "gcs.cli", "fly", "-q", "--sitl", "lockstep", "--controller", "pd",
                             "--duration", "30", "--log", str(log), "--live", f"127.0.0.1:{port}"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        try:
            channel, t, payload = asyncio.run(_first_message(port, T.FOXGLOVE_VEHICLE_POSE, 120,
                                                             alive=lambda: proc.poll() is None))
        except (websockets.exceptions.WebSocketException, OSError, TimeoutError) as exc:
            proc.kill()
            out, err = proc.communicate(timeout=60)
            raise AssertionError(f"no live message ({exc!r}); gcs exit {proc.returncode}, stderr:\n{err}") from exc
        out, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert f"live on ws://127.0.0.1:{port}" in err
    doc = json.loads(payload)
    name, schema = T.schema_for(T.FOXGLOVE_VEHICLE_POSE)
    jsonschema.validators.validator_for(schema)(schema).validate(doc)
    assert channel["schemaName"] == name and doc["frame_id"] == F.WORLD_FRAME
    assert F.stamp(t) == (doc["timestamp"]["sec"], doc["timestamp"]["nsec"])
    assert dict(read_log(log).messages[T.FOXGLOVE_VEHICLE_POSE])[t] == payload  # what the log has


def test_a_taken_port_is_a_warning_not_a_failed_log(tmp_path, capsys):
    from gcs.log.foxglove_live import start_for

    first = LiveServer("127.0.0.1", 0)
    try:
        log = FlightLog(tmp_path / "y.mcap")
        assert start_for(log, f"127.0.0.1:{first.port}") is None
        log.add([(T.STATE, b'{"x":1}')], 5)  # the log goes on, not teed
        log.close()
    finally:
        first.close()
    err = capsys.readouterr().err
    assert "cannot serve" in err and "flying without the live view" in err
    assert read_log(tmp_path / "y.mcap").counts[T.STATE] == 1
