"""The rig's serial protocol: framing, escaping, round trips, and a decoder that survives anything."""

from __future__ import annotations

import struct
from itertools import pairwise

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadrotor import rig_protocol as rp
from quadrotor.errors import ProtocolError, QuadrotorError

f32 = st.floats(width=32, allow_nan=False)
u8 = st.integers(0, 0xFF)
u16 = st.integers(0, 0xFFFF)
u32 = st.integers(0, 0xFFFFFFFF)
flags = st.integers(0, 0xFFFF).map(rp.RigFlags)

STRATEGIES = {
    rp.Control: st.builds(rp.Control, u16, f32, f32, f32, f32),
    rp.ControlPwm: st.builds(rp.ControlPwm, u16, st.tuples(*[st.integers(0, rp.PWM_MAX)] * 4)),
    rp.Arm: st.builds(rp.Arm, u8),
    rp.Disarm: st.builds(rp.Disarm, u8),
    rp.Heartbeat: st.builds(rp.Heartbeat, u32),
    rp.Telemetry: st.builds(rp.Telemetry, u32, f32, f32, f32, f32, f32, f32, f32, u16, flags, u16),
    rp.Status: st.builds(rp.Status, u32, st.sampled_from(rp.RigState), u8, u8, u8, u8, flags,
                         u32, u32, u32, u32, u32, u32, u32, u16, u16, u32),
    rp.Ack: st.builds(rp.Ack, st.sampled_from([rp.Arm.TYPE, rp.Disarm.TYPE]), u8, st.sampled_from(rp.AckResult)),
}
any_message = st.one_of(*STRATEGIES.values())


def unescape(body: bytes) -> bytes:
    out, esc = bytearray(), False
    for b in body:
        if esc:
            out.append(b ^ 0x20)
            esc = False
        elif b == 0x7D:
            esc = True
        else:
            out.append(b)
    return bytes(out)


def raw_frame(data: bytes, length: int | None = None, checksum: int | None = None) -> bytes:
    """A frame around arbitrary frame data (type + payload), optionally with a wrong length or checksum."""
    n = len(data) if length is None else length
    c = 0xFF - (sum(data) & 0xFF) if checksum is None else checksum
    return bytes([0x7E]) + rp.escape(bytes([n >> 8, n & 0xFF]) + data + bytes([c]))


def test_every_type_is_covered_and_ids_are_unique():
    assert set(STRATEGIES) == set(rp.MESSAGE_TYPES.values())
    assert set(rp.TO_RIG) | set(rp.TO_PC) == set(rp.MESSAGE_TYPES.values())
    assert all(c.TYPE & 0x80 for c in rp.TO_PC) and not any(c.TYPE & 0x80 for c in rp.TO_RIG)


@pytest.mark.parametrize("cls, payload, frame", [
    (rp.Control, 18, 23), (rp.ControlPwm, 10, 15), (rp.Arm, 1, 6), (rp.Disarm, 1, 6), (rp.Heartbeat, 4, 9),
    (rp.Telemetry, 38, 43), (rp.Status, 47, 52), (rp.Ack, 3, 8),
])
def test_documented_sizes(cls, payload, frame):
    assert cls.STRUCT.size == payload and rp.frame_size(cls) == frame


@pytest.mark.parametrize("cls", list(STRATEGIES), ids=lambda c: c.NAME)
@settings(max_examples=150, deadline=None)
@given(data=st.data())
def test_round_trip_of_every_type(cls, data):
    msg = data.draw(STRATEGIES[cls])
    wire = rp.encode(msg)
    # Structure: start, then no raw special byte; unescaped length, data, checksum consistent.
    assert wire[0] == 0x7E and not any(b in (0x7E, 0x11, 0x13) for b in wire[1:])
    body = unescape(wire[1:])
    n = (body[0] << 8) | body[1]
    assert n == len(body) - 3 == 1 + cls.STRUCT.size and body[2] == cls.TYPE
    assert (sum(body[2:]) & 0xFF) == 0xFF
    dec = rp.RigDecoder()
    assert dec.feed(wire) == [msg]
    assert dec.counters.frames == 1 and dec.counters.errors == 0 and dec.counters.discarded_bytes == 0


def test_little_endian_layout_of_control():
    wire = rp.encode(rp.Control(0x0102, 9.81, 1.0, -2.0, 0.0))
    body = unescape(wire[1:])
    assert body[:3] == bytes([0x00, 0x13, 0x01])   # length 19 (escaped on the wire: 0x13 is special)
    assert wire[1:5] == bytes([0x00, 0x7D, 0x33, 0x01])
    assert body[3:5] == bytes([0x02, 0x01])
    assert struct.unpack("<4f", body[5:21]) == pytest.approx((9.81, 1.0, -2.0, 0.0), rel=1e-6)


@pytest.mark.parametrize("special", [0x7E, 0x7D, 0x11, 0x13])
def test_each_special_byte_is_escaped_and_decoded(special):
    msg = rp.Heartbeat(special * 0x01010101)     # all four payload bytes special
    wire = rp.encode(msg)
    assert wire.count(bytes([0x7D, special ^ 0x20])) >= 4
    assert bytes([special]) not in wire[1:] or special == 0x7D
    assert rp.RigDecoder().feed(wire) == [msg]
    # Fed one byte at a time, the escapes are split across calls.
    dec = rp.RigDecoder()
    out = [m for i in range(len(wire)) for m in dec.feed(wire[i:i + 1])]
    assert out == [msg]


def test_checksum_that_is_special_is_escaped():
    # Search a message whose checksum byte is special; it must be escaped and still decode.
    for seq in range(256):
        wire = rp.encode(rp.Arm(seq))
        if wire[-2] == 0x7D:
            assert rp.RigDecoder().feed(wire) == [rp.Arm(seq)]
            return
    pytest.fail("no Arm frame with an escaped checksum")


@settings(max_examples=100, deadline=None)
@given(msgs=st.lists(any_message, min_size=1, max_size=8), cuts=st.lists(st.integers(0, 400), max_size=10))
def test_any_chunking_gives_the_same_messages(msgs, cuts):
    stream = b"".join(rp.encode(m) for m in msgs)
    points = sorted({min(c, len(stream)) for c in cuts} | {0, len(stream)})
    dec = rp.RigDecoder()
    out = [m for a, b in pairwise(points) for m in dec.feed(stream[a:b])]
    assert out == msgs and dec.counters.errors == 0


@settings(max_examples=300, deadline=None)
@given(garbage=st.binary(max_size=200), msg=any_message, prefix=st.lists(any_message, max_size=2))
def test_after_garbage_the_next_valid_frame_is_decoded(garbage, msg, prefix):
    dec = rp.RigDecoder()
    stream = b"".join(rp.encode(m) for m in prefix) + garbage + rp.encode(msg)
    out = dec.feed(stream)
    assert out[:len(prefix)] == prefix and out[-1] == msg


@settings(max_examples=300, deadline=None)
@given(data=st.binary(max_size=600), chunk=st.integers(1, 64))
def test_random_bytes_never_raise(data, chunk):
    dec = rp.RigDecoder()
    for i in range(0, len(data), chunk):
        for m in dec.feed(data[i:i + chunk]):
            assert type(m) in rp.MESSAGE_TYPES.values()
    c = dec.counters
    assert min(c.as_dict().values()) >= 0


@settings(max_examples=300, deadline=None)
@given(msgs=st.lists(any_message, min_size=2, max_size=6), flips=st.lists(st.integers(0, 10_000), max_size=6),
       cut=st.integers(0, 10_000), follow=any_message)
def test_mutated_streams_never_raise_and_resynchronise(msgs, flips, cut, follow):
    stream = bytearray(b"".join(rp.encode(m) for m in msgs))
    for f in flips:
        stream[(f // 8) % len(stream)] ^= 1 << (f % 8)
    del stream[cut % len(stream):(cut % len(stream)) + (cut % 7)]     # lose some bytes too
    dec = rp.RigDecoder()
    out = dec.feed(bytes(stream)) + dec.feed(rp.encode(follow))
    assert out and out[-1] == follow
    # Messages that came through intact are a subset of what was sent, or (rarely) a checksum collision.
    assert dec.counters.frames == len(out)


def test_single_bit_flips_are_always_detected():
    msg = rp.Control(7, 9.81, 0.5, -0.5, 0.0)
    wire = rp.encode(msg)
    for bit in range(8 * len(wire)):
        bad = bytearray(wire)
        bad[bit // 8] ^= 1 << (bit % 8)
        dec = rp.RigDecoder()
        out = dec.feed(bytes(bad)) + dec.feed(rp.encode(rp.Arm(1)))
        assert msg not in out and out[-1] == rp.Arm(1)
        assert all(m == rp.Arm(1) for m in out)


def test_checksum_errors_are_counted():
    dec = rp.RigDecoder()
    good = rp.encode(rp.Arm(3))
    data = bytes([rp.Arm.TYPE, 3])
    bad = raw_frame(data, checksum=(0xFF - sum(data) + 1) & 0xFF)
    assert dec.feed(bad + good + bad) == [rp.Arm(3)]
    assert dec.counters.checksum_errors == 2 and dec.counters.frames == 1


def test_length_errors_are_counted():
    dec = rp.RigDecoder()
    too_short = raw_frame(bytes([rp.Control.TYPE]) + bytes(10))           # good checksum, 10 of 18 bytes
    too_long = raw_frame(bytes([rp.Arm.TYPE]) + bytes(5))                 # 5 of 1
    beyond_max = bytes([0x7E, 0x01, 0x00]) + bytes(20)                   # length 256 > 64: hunts again
    zero = bytes([0x7E, 0x00, 0x00, 0xFF])
    out = dec.feed(too_short + too_long + beyond_max + zero + rp.encode(rp.Disarm(9)))
    assert out == [rp.Disarm(9)]
    c = dec.counters
    assert c.length_errors == 4 and c.checksum_errors == 0 and c.discarded_bytes >= 20


def test_unknown_and_unaccepted_types_are_counted():
    dec = rp.RigDecoder(rp.TO_RIG)
    stream = raw_frame(bytes([0x42, 1, 2, 3])) + rp.encode(rp.Telemetry(0, *[0.0] * 7, 0, 0, 0)) \
        + rp.encode(rp.Heartbeat(5))
    assert dec.feed(stream) == [rp.Heartbeat(5)]
    assert dec.counters.unknown_types == 2


def test_invalid_values_are_counted():
    dec = rp.RigDecoder()
    pwm = raw_frame(bytes([rp.ControlPwm.TYPE]) + struct.pack("<H4H", 1, 0, 1024, 0, 0))
    status = raw_frame(bytes([rp.Status.TYPE]) + struct.pack("<IBBBBBH7IHHI", 0, 9, 1, 1, 0, 0, 0, *[0] * 10))
    ack = raw_frame(bytes([rp.Ack.TYPE, 3, 1, 77]))
    assert dec.feed(pwm + status + ack) == []
    assert dec.counters.invalid_values == 3


def test_a_start_byte_inside_a_frame_truncates_it():
    good = rp.encode(rp.Heartbeat(1))
    dec = rp.RigDecoder()
    assert dec.feed(good[:6] + good) == [rp.Heartbeat(1)]
    assert dec.counters.truncated_frames == 1
    # An escape followed by a start byte: the start wins.
    dec = rp.RigDecoder()
    assert dec.feed(good[:4] + b"\x7d" + good) == [rp.Heartbeat(1)]


def test_leading_garbage_is_counted_as_discarded():
    dec = rp.RigDecoder()
    assert dec.feed(b"hello" + rp.encode(rp.Arm(1))) == [rp.Arm(1)]
    assert dec.counters.discarded_bytes == 5


@pytest.mark.parametrize("msg, words", [
    (rp.ControlPwm(1, (0, 1024, 0, 0)), "pwm[1]"),
    (rp.ControlPwm(1, (0, 0, 0)), "4 values"),
    (rp.Control(70000, 1.0), "seq"),
    (rp.Control(1, 1e39), "float32"),
    (rp.Control(1, "x"), "number"),  # type: ignore[arg-type]
    (rp.Arm(256), "uint8"),
    (rp.Heartbeat(-1), "uint32"),
    (rp.Telemetry(0, *[0.0] * 7, 70000, 0, 0), "altitude_mm"),
])
def test_encoder_refuses_what_does_not_fit(msg, words):
    with pytest.raises(ProtocolError, match=words.replace("[", r"\[")) as e:
        rp.encode(msg)
    assert isinstance(e.value, QuadrotorError) and isinstance(e.value, ValueError)


def test_nan_and_inf_are_carried():
    wire = rp.encode(rp.Control(1, float("nan"), float("inf"), -float("inf"), 0.0))
    (m,) = rp.RigDecoder().feed(wire)
    assert m.thrust_n != m.thrust_n and m.roll_accel_rad_s2 == float("inf")


def test_flags_and_enums_decode_as_their_types():
    t = rp.RigDecoder().feed(rp.encode(rp.Telemetry(1, *[0.0] * 7, 40, rp.RigFlags.ARMED | rp.RigFlags.LANDED, 3)))[0]
    assert isinstance(t.flags, rp.RigFlags) and rp.RigFlags.LANDED in t.flags and t.altitude_m == pytest.approx(0.04)
    a = rp.RigDecoder().feed(rp.encode(rp.Ack(rp.Arm.TYPE, 1, rp.AckResult.DENIED_NOT_LANDED)))[0]
    assert a.result is rp.AckResult.DENIED_NOT_LANDED
