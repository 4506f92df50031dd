"""Property tests (hypothesis) of the ground station's decoders on hostile bytes.

* ``gcs.link.mavlink.MavlinkLink`` on a real UDP socket pair (the link on ``udpin:``, a plain
  socket as the vehicle): random datagrams, random bytes around valid frames, structurally valid
  frames of every message id with random payloads (good CRC), lone 0xFD bytes.  ``drain()``
  never raises anything but its documented ``LinkError``; garbled bytes are counted
  (``counters.bad_data``); and, UDP being datagrams, a valid datagram that follows any garbage
  datagram is received (a partial frame must not swallow the next datagram).
* The rig decoder (``quadrotor.rig_protocol.RigDecoder``, which ``gcs.link.rig.RigLink`` feeds): on
  any byte stream, in any chunking, it never raises, and its counts add up: every unescaped
  start delimiter opens exactly one frame, which ends as a message or as exactly one counted
  error (after a final delimiter closes the last one).  ``RigLink`` on pyserial's ``loop://``
  never raises anything but ``LinkError``.
"""

from __future__ import annotations

import os
import random
import socket
import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

os.environ.setdefault("MAVLINK20", "1")

from gcs.link.mavlink import LinkError, MavlinkLink, mavlink
from quadrotor import rig_protocol as rp

SETTINGS = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                             HealthCheck.function_scoped_fixture])
MSG_IDS = sorted(mavlink.mavlink_map)


# ----------------------------------------------------------------------------- MAVLink over UDP
class UdpPair:
    """Our link on udpin (signed with ``key`` if given) plus a plain socket standing for the vehicle."""

    def __init__(self, key: bytes | None = None) -> None:
        self.link = MavlinkLink("udpin:127.0.0.1:0", target_system=1, target_component=1, signing_key=key)
        self.addr = self.link.conn.port.getsockname()
        self.vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.vehicle.bind(("127.0.0.1", 0))
        self.vmav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        if key is not None:
            self.vmav.signing.secret_key, self.vmav.signing.sign_outgoing = key, True
            self.vmav.signing.timestamp = int((time.time() - 1420070400) * 100_000)

    def heartbeat(self, custom_mode: int) -> bytes:
        f = bytes(self.vmav.heartbeat_encode(2, 3, 0, custom_mode, 0).pack(self.vmav))
        self.vmav.seq = (self.vmav.seq + 1) & 0xFF
        return f

    def send(self, datagrams) -> None:
        for d in datagrams:
            if d:
                self.vehicle.sendto(d, self.addr)

    def drain_all(self, settle_s: float = 0.003) -> list:
        """Drain until nothing came for ``settle_s`` (loopback delivers at once)."""
        out = []
        idle_until = time.monotonic() + settle_s
        while time.monotonic() < idle_until:
            got = self.link.drain()  # may raise LinkError only (the property)
            if got:
                out += got
                idle_until = time.monotonic() + settle_s
            else:
                self.link.wait_readable(0.005)
        return out

    def resync(self) -> None:
        """Flush whatever partial frame the parser holds (a test's own cleanup, between examples)."""
        self.link.conn.mav.buf = bytearray()
        self.link.conn.mav.buf_index = 0
        self.link.conn.mav.expected_length = mavlink.HEADER_LEN_V1 + 2
        self.link.conn.mav.have_prefix_error = False
        self.link._pending = []

    def close(self) -> None:
        self.vehicle.close()
        self.link.close()


@pytest.fixture(scope="module", params=["unsigned", "signed"])
def pair(request):
    p = UdpPair(None if request.param == "unsigned" else bytes(range(32)))
    # the link learns the vehicle's address from a first valid frame
    p.send([p.heartbeat(0)])
    p.drain_all(0.2)
    yield p
    p.close()


def _drain_never_raises_but_linkerror(pair: UdpPair) -> list:
    try:
        return pair.drain_all()
    except LinkError:
        return []


def _valid_frame(mid: int, payload: bytes, sysid: int = 1, compid: int = 1, seq: int = 0,
                 signature: bytes | None = None) -> bytes:
    """A MAVLink 2 frame of message ``mid`` with ``payload`` (trailing zeros cut, as MAVLink 2 does) and a
    good CRC (with the message's CRC_EXTRA); ``signature``: 13 bytes appended with the signed flag set."""
    cls = mavlink.mavlink_map[mid]
    payload = payload.rstrip(b"\x00") or b"\x00"
    flags = 1 if signature is not None else 0
    hdr = bytes((0xFD, len(payload), flags, 0, seq & 0xFF, sysid, compid, mid & 0xFF, (mid >> 8) & 0xFF, mid >> 16))
    crc = mavlink.x25crc(hdr[1:] + payload)
    crc.accumulate(bytes((cls.crc_extra,)))
    return hdr + payload + crc.crc.to_bytes(2, "little") + (signature or b"")


@SETTINGS
@given(st.lists(st.binary(min_size=1, max_size=600), min_size=1, max_size=8))
def test_random_datagrams_never_raise_and_are_counted(pair, datagrams):
    before = pair.link.counters.bad_data
    pair.send(datagrams)
    _drain_never_raises_but_linkerror(pair)
    if not any(b in (0xFD, 0xFE) for d in datagrams for b in d):
        assert pair.link.counters.bad_data > before, "garbled bytes (no frame start at all) were not counted"
    pair.resync()


@SETTINGS
@given(st.sampled_from(MSG_IDS), st.binary(min_size=0, max_size=255), st.sampled_from([0, 1, 2, 255]),
       st.sampled_from([0, 1, 190]), st.none() | st.binary(min_size=13, max_size=13))
def test_valid_frames_with_random_payloads_never_raise(pair, mid, payload, sysid, compid, signature):
    """Structurally valid frames (good CRC) of every known message with arbitrary payload bytes: strings that
    are not UTF-8, NaN floats, enums out of range, short (MAVLink 2 truncated) payloads; some with a random
    signature (a forgery, any timestamp)."""
    cls = mavlink.mavlink_map[mid]
    payload = payload[:cls.unpacker.size]
    pair.send([_valid_frame(mid, payload, sysid, compid, signature=signature)])
    _drain_never_raises_but_linkerror(pair)
    pair.resync()


@SETTINGS
@given(st.binary(min_size=0, max_size=300), st.binary(min_size=0, max_size=300), st.integers(1, 5000))
def test_garbage_around_frames_in_one_datagram_never_raises(pair, pre, post, mode):
    pair.send([pre + pair.heartbeat(mode) + post])
    _drain_never_raises_but_linkerror(pair)
    pair.resync()


@SETTINGS
@given(st.lists(st.one_of(st.binary(min_size=1, max_size=400), st.just(b"\xfd"), st.just(b"\xfe"),
                          st.binary(min_size=1, max_size=40).map(lambda b: b"\xfd" + b)), min_size=1, max_size=4),
       st.integers(1, 60000))
def test_a_valid_datagram_after_garbage_datagrams_is_received(pair, garbage, mode):
    """UDP keeps datagram boundaries: whatever the previous datagrams held, the next one with a whole frame
    is received (a 1-byte 0xFD datagram must not make the link eat the next one)."""
    pair.send(garbage)
    pair.send([pair.heartbeat(mode)])
    got = _drain_never_raises_but_linkerror(pair)
    pair.resync()
    modes = [m.custom_mode for m in got if m.get_type() == "HEARTBEAT"]
    assert mode in modes, (f"the valid HEARTBEAT datagram after {len(garbage)} garbage datagram(s) "
                           f"{[g[:8].hex() for g in garbage]} was lost")


def test_bad_data_is_counted_and_the_link_lives_on(pair):
    """A deterministic run: 200 random datagrams, then the vehicle's frames still arrive."""
    rng = random.Random(3)
    before = pair.link.counters.bad_data
    pair.send([rng.randbytes(rng.randint(1, 1400)) for _ in range(200)])
    _drain_never_raises_but_linkerror(pair)
    assert pair.link.counters.bad_data > before
    pair.send([pair.heartbeat(4242) for _ in range(20)])
    got = _drain_never_raises_but_linkerror(pair)
    pair.resync()
    assert any(m.get_type() == "HEARTBEAT" and m.custom_mode == 4242 for m in got), \
        "20 valid datagrams after the garbage, none received"


# ----------------------------------------------------------------------------- the rig decoder
def _stream_msgs():
    ctrl = st.builds(rp.Control, seq=st.integers(0, 65535), thrust_n=st.floats(width=32, allow_nan=True),
                     roll_accel_rad_s2=st.floats(width=32), pitch_accel_rad_s2=st.floats(width=32),
                     yaw_accel_rad_s2=st.floats(width=32))
    hb = st.builds(rp.Heartbeat, time_us=st.integers(0, 2 ** 32 - 1))
    return st.lists(st.one_of(ctrl, hb), max_size=6)


def _counts_add_up(dec: rp.RigDecoder, stream: bytes, n_out: int) -> None:
    """After one more delimiter: starts == frames + errors; the messages returned == frames."""
    tail = dec.feed(b"\x7e")
    c = dec.counters
    starts = stream.count(0x7E)
    assert not tail
    assert c.frames == n_out
    assert starts == c.frames + c.errors, (f"{starts} start delimiters but {c.frames} frames + {c.errors} errors "
                                           f"({c.as_dict()})")
    assert c.discarded_bytes <= len(stream)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=2000), st.lists(st.integers(1, 64), min_size=1, max_size=20))
def test_rig_decoder_random_bytes_any_chunking_counts_add_up(data, cuts):
    dec = rp.RigDecoder()
    out, i, k = [], 0, 0
    while i < len(data):
        n = cuts[k % len(cuts)]
        out += dec.feed(data[i:i + n])  # never raises (the property)
        i, k = i + n, k + 1
    _counts_add_up(dec, data, len(out))


@settings(max_examples=300, deadline=None)
@given(_stream_msgs(), st.lists(st.tuples(st.integers(0, 10 ** 6), st.integers(0, 255)), max_size=12),
       st.binary(max_size=40))
def test_rig_decoder_mutated_frames_counts_add_up(msgs, edits, garbage):
    frames = bytearray(b"".join(rp.encode(m) for m in msgs) + garbage)
    for pos, val in edits:
        if frames:
            frames[pos % len(frames)] = val
    data = bytes(frames)
    dec = rp.RigDecoder(rp.TO_PC)
    out = dec.feed(data)
    _counts_add_up(dec, data, len(out))


@settings(max_examples=100, deadline=None)
@given(st.lists(st.binary(max_size=300), min_size=1, max_size=6))
def test_rig_link_on_loop_never_raises_but_linkerror(chunks):
    from gcs.link.rig import RigLink

    link = RigLink("loop://", 115200)
    try:
        got = 0
        for c in chunks:
            link.serial.write(c)
            try:
                got += len(link.drain())
            except LinkError:
                pass
        assert link.counters.frames == got
    finally:
        link.close()
