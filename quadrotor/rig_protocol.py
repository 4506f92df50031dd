"""Wire format of the 4-DOF rig's serial link (XBee API mode 2 framing).

Shared by the rig emulator (:mod:`sitl.rig`) and the ground station; it
imports nothing but the standard library.  ``docs/rig-protocol.md`` has the
same tables with the link budget and the rig's behaviour.

Framing
-------
``0x7E | length (uint16, big-endian) | frame data | checksum``, where the
frame data is ``type (uint8) | payload`` and ``length`` counts the frame data
(type byte included).  ``checksum = 0xFF - (sum(frame data) & 0xFF)``, so the
sum of the frame data and the checksum is ``0xFF (mod 256)``.  Escaping (API
mode 2): every byte after the start delimiter (length, frame data, checksum)
that is 0x7E, 0x7D, 0x11 or 0x13 is sent as ``0x7D, byte ^ 0x20``; the length
and the checksum are computed on the unescaped bytes.  An unescaped 0x7E
always starts a new frame, which is how a receiver resynchronises.

Payloads are **little-endian** and packed (no padding); ``f32`` is IEEE 754
binary32.  Type ids with bit 7 set go from the rig to the PC.

==========  ====  ===========  =====================================================  =======  =====
message     type  direction    payload (little-endian, in order)                      payload  frame
==========  ====  ===========  =====================================================  =======  =====
CONTROL     0x01  PC -> rig    seq u16, thrust_n f32, roll_accel_rad_s2 f32,          18       23
                               pitch_accel_rad_s2 f32, yaw_accel_rad_s2 f32
CONTROL_PWM 0x02  PC -> rig    seq u16, pwm[4] u16 (10-bit: 0..1023, motors 1..4)     10       15
ARM         0x03  PC -> rig    seq u8 (echoed by ACK)                                 1        6
DISARM      0x04  PC -> rig    seq u8 (echoed by ACK)                                 1        6
HEARTBEAT   0x05  PC -> rig    time_us u32 (PC clock; echoed by STATUS)               4        9
TELEMETRY   0x81  rig -> PC    time_us u32, roll_rad f32, pitch_rad f32, yaw_rad f32, 38       43
                               roll_rate_rad_s f32, pitch_rate_rad_s f32,
                               yaw_rate_rad_s f32, x_m f32, altitude_mm u16,
                               flags u16, control_seq u16
STATUS      0x82  rig -> PC    time_us u32, state u8, protocol_version u8,            47       52
                               fw_major u8, fw_minor u8, fw_patch u8, flags u16,
                               rx_frames u32, rx_checksum_errors u32,
                               rx_length_errors u32, rx_unknown_types u32,
                               rx_invalid_values u32, rx_truncated_frames u32,
                               rx_discarded_bytes u32, cutoffs u16,
                               watchdog_trips u16, heartbeat_echo_us u32
ACK         0x83  rig -> PC    acked_type u8, seq u8, result u8                       3        8
==========  ====  ===========  =====================================================  =======  =====

"frame" is the unescaped size on the wire (payload + 5); escaping adds one
byte per special byte.  ``time_us`` is the sender's clock in microseconds,
modulo 2**32 (wraps after 71.6 min).  ``seq`` fields wrap.

Field meanings: ``thrust_n`` is the collective thrust [N] along the body z
axis; the three accelerations are the angular accelerations of the paper's
reduced model (unit inertia) [rad/s^2]; ``altitude_mm`` is the ultrasonic
reading [mm] (4 cm steps); ``x_m`` the measured position along the rig's x
rail [m]; ``flags`` is a :class:`RigFlags` bitfield, ``state`` a
:class:`RigState`, ``result`` an :class:`AckResult`; ``control_seq`` is the
sequence number of the last CONTROL / CONTROL_PWM the rig received.

Usage::

    from sitl import rig_protocol as rp

    port.write(rp.encode(rp.Arm(seq=1)))
    dec = rp.RigDecoder(rp.TO_PC)              # accept only rig -> PC types
    for msg in dec.feed(port.read(4096)):      # any chunking; never raises
        if isinstance(msg, rp.Telemetry):
            ...
    dec.counters.checksum_errors               # what was dropped, and why
"""

from __future__ import annotations

import enum
import math
import operator
import re
import struct
from dataclasses import dataclass, fields
from typing import ClassVar, Iterable, Union

from quadrotor.errors import ProtocolError

__all__ = [
    "START", "ESCAPE", "XOR", "SPECIAL_BYTES", "MAX_FRAME_DATA", "PROTOCOL_VERSION", "PWM_MAX",
    "RigFlags", "CUTOFF_CAUSES", "RigState", "AckResult",
    "Control", "ControlPwm", "Arm", "Disarm", "Heartbeat", "Telemetry", "Status", "Ack",
    "Message", "MESSAGE_TYPES", "TO_RIG", "TO_PC", "frame_size",
    "encode", "escape", "DecoderCounters", "RigDecoder",
]

START = 0x7E
ESCAPE = 0x7D
XOR = 0x20
#: Bytes escaped after the start delimiter (API mode 2).
SPECIAL_BYTES = (0x7E, 0x7D, 0x11, 0x13)
#: Largest frame data (type + payload) a receiver accepts [bytes]; longer lengths are errors.
MAX_FRAME_DATA = 64
#: Sent in STATUS; bumped on any incompatible change of this module's tables.
PROTOCOL_VERSION = 1
#: Largest 10-bit PWM value.
PWM_MAX = 1023


class RigFlags(enum.IntFlag):
    """Status bits of TELEMETRY and STATUS (``flags``, uint16)."""

    ARMED = 1 << 0             #: motors enabled and following the PC's commands
    CUTOFF = 1 << 1            #: safety cut-off tripped: motors off, latched until DISARM
    CUT_VELOCITY_Z = 1 << 2    #: cause: |vz| above the limit
    CUT_VELOCITY_X = 1 << 3    #: cause: |vx| above the limit
    CUT_ANGULAR_RATE = 1 << 4  #: cause: |roll rate| or |pitch rate| above the limit
    CUT_ALTITUDE = 1 << 5      #: cause: altitude above the limit
    CUT_COMMAND = 1 << 6       #: cause: a CONTROL demand outside the limits (or not finite)
    WATCHDOG = 1 << 7          #: no CONTROL for the watchdog timeout: controlled descent
    LANDED = 1 << 8            #: resting on the ground
    ALT_OUT_OF_RANGE = 1 << 9  #: ultrasonic below its minimum or above its maximum range
    ROLL_AT_STOP = 1 << 10     #: roll is on its mechanical stop (+-15 deg)
    PITCH_AT_STOP = 1 << 11    #: pitch is on its mechanical stop (+-60 deg)
    MOTOR_SATURATED = 1 << 12  #: a motor demand was clipped to 0 or full thrust this tick
    PWM_MODE = 1 << 13         #: the last control frame was CONTROL_PWM


#: The cause bits of a cut-off.
CUTOFF_CAUSES = (RigFlags.CUT_VELOCITY_Z | RigFlags.CUT_VELOCITY_X | RigFlags.CUT_ANGULAR_RATE
                 | RigFlags.CUT_ALTITUDE | RigFlags.CUT_COMMAND)


class RigState(enum.IntEnum):
    """The rig's state (STATUS ``state``)."""

    DISARMED = 0   #: motors off; ARM accepted when landed
    ARMED = 1      #: following CONTROL / CONTROL_PWM
    CUTOFF = 2     #: safety cut-off latched; DISARM clears it
    DESCENT = 3    #: link watchdog: controlled descent, then disarm on the ground


class AckResult(enum.IntEnum):
    """ACK ``result``."""

    ACCEPTED = 0            #: done (also when already in the requested state)
    DENIED_NOT_LANDED = 1   #: ARM refused: not resting on the ground
    DENIED_CUTOFF = 2       #: ARM refused: the cut-off is latched; send DISARM first


def _u(bits: int, name: str, value: object) -> int:
    try:
        v = operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        raise ProtocolError(f"{name}: expected an integer, got {value!r}") from None
    if not 0 <= v < (1 << bits):
        raise ProtocolError(f"{name}: {v!r} does not fit in uint{bits}")
    return v


_F32_MAX = struct.unpack("<f", b"\xff\xff\x7f\x7f")[0]


def _f32(name: str, value: object) -> float:
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ProtocolError(f"{name}: expected a number, got {value!r}") from None
    if math.isfinite(v) and abs(v) > _F32_MAX:
        # struct would round values just above the maximum to inf or raise; refuse them.
        raise ProtocolError(f"{name}: {v!r} is out of float32 range")
    return v


class _Message:
    """Base of the message dataclasses: packing from the class's struct and field kinds."""

    TYPE: ClassVar[int]
    NAME: ClassVar[str]
    STRUCT: ClassVar[struct.Struct]
    #: Field name -> "f32" or "uN"; the order of the struct.
    KINDS: ClassVar[tuple[tuple[str, str], ...]]
    __slots__ = ()

    def pack(self) -> bytes:
        """The payload (without type byte); :class:`ProtocolError` if a field does not fit."""
        vals = []
        for name, kind in self.KINDS:
            v = getattr(self, name)
            vals.append(_f32(name, v) if kind == "f32" else _u(int(kind[1:]), name, v))
        return self.STRUCT.pack(*vals)

    @classmethod
    def unpack(cls, payload: bytes | bytearray | memoryview) -> "_Message":
        """Message from a payload of exactly ``STRUCT.size`` bytes; ValueError if a field is invalid."""
        return cls(*cls.STRUCT.unpack(payload))


def _kinds(*items: str) -> tuple[tuple[str, str], ...]:
    return tuple(tuple(i.split(":")) for i in items)  # type: ignore[misc]


@dataclass(frozen=True, slots=True)
class Control(_Message):
    """PC -> rig: thrust and angular-acceleration demand, applied until the next one.

    Attributes
    ----------
    seq : int
        uint16, echoed in TELEMETRY ``control_seq``.
    thrust_n : float
        Collective thrust [N].
    roll_accel_rad_s2, pitch_accel_rad_s2, yaw_accel_rad_s2 : float
        Angular accelerations of the reduced model [rad/s^2] (yaw is locked on the rig:
        the yaw demand is only checked against the limits).
    """

    TYPE: ClassVar[int] = 0x01
    NAME: ClassVar[str] = "CONTROL"
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<H4f")
    KINDS: ClassVar = _kinds("seq:u16", "thrust_n:f32", "roll_accel_rad_s2:f32", "pitch_accel_rad_s2:f32",
                             "yaw_accel_rad_s2:f32")
    seq: int
    thrust_n: float
    roll_accel_rad_s2: float = 0.0
    pitch_accel_rad_s2: float = 0.0
    yaw_accel_rad_s2: float = 0.0


@dataclass(frozen=True, slots=True)
class ControlPwm(_Message):
    """PC -> rig: the four motors' 10-bit PWM values, applied until the next control frame.

    Attributes
    ----------
    seq : int
        uint16, echoed in TELEMETRY ``control_seq``.
    pwm : tuple of 4 int
        Motors 1..4, each 0..1023 (0 = off, 1023 = full thrust); larger values are invalid.
    """

    TYPE: ClassVar[int] = 0x02
    NAME: ClassVar[str] = "CONTROL_PWM"
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<H4H")
    KINDS: ClassVar = _kinds("seq:u16")
    seq: int
    pwm: tuple[int, int, int, int]

    def pack(self) -> bytes:
        seq = _u(16, "seq", self.seq)
        try:
            pwm = tuple(self.pwm)
        except TypeError:
            raise ProtocolError(f"pwm: expected 4 integers, got {self.pwm!r}") from None
        if len(pwm) != 4:
            raise ProtocolError(f"pwm: expected 4 values, got {len(pwm)}")
        vals = [_u(16, f"pwm[{i}]", v) for i, v in enumerate(pwm)]
        for i, v in enumerate(vals):
            if v > PWM_MAX:
                raise ProtocolError(f"pwm[{i}]: {v!r} is not a 10-bit value (0..{PWM_MAX})")
        return self.STRUCT.pack(seq, *vals)

    @classmethod
    def unpack(cls, payload: bytes | bytearray | memoryview) -> "ControlPwm":
        seq, *pwm = cls.STRUCT.unpack(payload)
        if max(pwm) > PWM_MAX:
            raise ValueError(f"PWM value above {PWM_MAX}: {pwm}")
        return cls(seq, tuple(pwm))  # type: ignore[arg-type]


@dataclass(frozen=True, slots=True)
class Arm(_Message):
    """PC -> rig: arm the motors (accepted only when landed); answered by ACK with ``seq``."""

    TYPE: ClassVar[int] = 0x03
    NAME: ClassVar[str] = "ARM"
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<B")
    KINDS: ClassVar = _kinds("seq:u8")
    seq: int = 0


@dataclass(frozen=True, slots=True)
class Disarm(_Message):
    """PC -> rig: stop the motors at once (also in the air) and clear a latched cut-off."""

    TYPE: ClassVar[int] = 0x04
    NAME: ClassVar[str] = "DISARM"
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<B")
    KINDS: ClassVar = _kinds("seq:u8")
    seq: int = 0


@dataclass(frozen=True, slots=True)
class Heartbeat(_Message):
    """PC -> rig: a ping; the rig answers with STATUS echoing ``time_us`` [µs, uint32]."""

    TYPE: ClassVar[int] = 0x05
    NAME: ClassVar[str] = "HEARTBEAT"
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<I")
    KINDS: ClassVar = _kinds("time_us:u32")
    time_us: int = 0


@dataclass(frozen=True, slots=True)
class Telemetry(_Message):
    """Rig -> PC, every 5 ms (200 Hz): IMU, ultrasonic altitude, x, flags.

    Attributes
    ----------
    time_us : int
        Rig time of the sample [µs], uint32 (wraps).
    roll_rad, pitch_rad, yaw_rad : float
        IMU Euler angles [rad] (yaw is locked: noise around 0).
    roll_rate_rad_s, pitch_rate_rad_s, yaw_rate_rad_s : float
        IMU Euler-angle rates [rad/s].
    x_m : float
        Position along the x rail [m] (the PC differentiates it for vx).
    altitude_mm : int
        Ultrasonic altitude [mm], uint16, a multiple of the 40 mm resolution (see :attr:`altitude_m`).
    flags : int
        :class:`RigFlags`.
    control_seq : int
        ``seq`` of the last CONTROL / CONTROL_PWM received (0 before the first).
    """

    TYPE: ClassVar[int] = 0x81
    NAME: ClassVar[str] = "TELEMETRY"
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<I7fHHH")
    KINDS: ClassVar = _kinds("time_us:u32", "roll_rad:f32", "pitch_rad:f32", "yaw_rad:f32", "roll_rate_rad_s:f32",
                             "pitch_rate_rad_s:f32", "yaw_rate_rad_s:f32", "x_m:f32", "altitude_mm:u16",
                             "flags:u16", "control_seq:u16")
    time_us: int
    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    roll_rate_rad_s: float
    pitch_rate_rad_s: float
    yaw_rate_rad_s: float
    x_m: float
    altitude_mm: int
    flags: int
    control_seq: int

    @classmethod
    def unpack(cls, payload: bytes | bytearray | memoryview) -> "Telemetry":
        v = cls.STRUCT.unpack(payload)
        return cls(*v[:9], RigFlags(v[9]), v[10])

    @property
    def altitude_m(self) -> float:
        """Ultrasonic altitude [m]."""
        return self.altitude_mm * 1e-3


@dataclass(frozen=True, slots=True)
class Status(_Message):
    """Rig -> PC, once a second of rig time, in answer to HEARTBEAT and to a new peer.

    Attributes
    ----------
    time_us : int
        Rig time [µs], uint32.
    state : int
        :class:`RigState`.
    protocol_version : int
        :data:`PROTOCOL_VERSION` of the rig.
    fw_major, fw_minor, fw_patch : int
        Firmware version.
    flags : int
        :class:`RigFlags` (as in TELEMETRY).
    rx_frames, rx_checksum_errors, rx_length_errors, rx_unknown_types, rx_invalid_values, \
rx_truncated_frames, rx_discarded_bytes : int
        The rig's decoder counters (:class:`DecoderCounters`), uint32.
    cutoffs, watchdog_trips : int
        Safety cut-offs and link-watchdog trips since power-up, uint16.
    heartbeat_echo_us : int
        ``time_us`` of the last HEARTBEAT received (0 before the first), for round-trip times.
    """

    TYPE: ClassVar[int] = 0x82
    NAME: ClassVar[str] = "STATUS"
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<IBBBBBH7IHHI")
    KINDS: ClassVar = _kinds("time_us:u32", "state:u8", "protocol_version:u8", "fw_major:u8", "fw_minor:u8",
                             "fw_patch:u8", "flags:u16", "rx_frames:u32", "rx_checksum_errors:u32",
                             "rx_length_errors:u32", "rx_unknown_types:u32", "rx_invalid_values:u32",
                             "rx_truncated_frames:u32", "rx_discarded_bytes:u32", "cutoffs:u16",
                             "watchdog_trips:u16", "heartbeat_echo_us:u32")
    time_us: int
    state: int
    protocol_version: int
    fw_major: int
    fw_minor: int
    fw_patch: int
    flags: int
    rx_frames: int
    rx_checksum_errors: int
    rx_length_errors: int
    rx_unknown_types: int
    rx_invalid_values: int
    rx_truncated_frames: int
    rx_discarded_bytes: int
    cutoffs: int
    watchdog_trips: int
    heartbeat_echo_us: int

    @classmethod
    def unpack(cls, payload: bytes | bytearray | memoryview) -> "Status":
        v = list(cls.STRUCT.unpack(payload))
        v[1] = RigState(v[1])          # ValueError on an unknown state
        v[6] = RigFlags(v[6])
        return cls(*v)


@dataclass(frozen=True, slots=True)
class Ack(_Message):
    """Rig -> PC: answer to ARM / DISARM.

    Attributes
    ----------
    acked_type : int
        Type id of the command (``Arm.TYPE`` or ``Disarm.TYPE``).
    seq : int
        The command's ``seq``.
    result : int
        :class:`AckResult`.
    """

    TYPE: ClassVar[int] = 0x83
    NAME: ClassVar[str] = "ACK"
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<BBB")
    KINDS: ClassVar = _kinds("acked_type:u8", "seq:u8", "result:u8")
    acked_type: int
    seq: int
    result: int

    @classmethod
    def unpack(cls, payload: bytes | bytearray | memoryview) -> "Ack":
        t, seq, result = cls.STRUCT.unpack(payload)
        return cls(t, seq, AckResult(result))


Message = Union[Control, ControlPwm, Arm, Disarm, Heartbeat, Telemetry, Status, Ack]

#: Type id -> message class.
MESSAGE_TYPES: dict[int, type[_Message]] = {
    c.TYPE: c for c in (Control, ControlPwm, Arm, Disarm, Heartbeat, Telemetry, Status, Ack)}
#: What the rig accepts (PC -> rig) and what the PC accepts (rig -> PC).
TO_RIG: tuple[type[_Message], ...] = (Control, ControlPwm, Arm, Disarm, Heartbeat)
TO_PC: tuple[type[_Message], ...] = (Telemetry, Status, Ack)


def _check_consistency() -> None:
    for cls in MESSAGE_TYPES.values():
        names = [f.name for f in fields(cls)]  # type: ignore[arg-type]
        if cls is not ControlPwm and names != [k for k, _ in cls.KINDS]:
            raise AssertionError(f"{cls.__name__}: fields and KINDS differ")
        if 1 + cls.STRUCT.size > MAX_FRAME_DATA:
            raise AssertionError(f"{cls.__name__}: payload too long")


_check_consistency()


def frame_size(cls: type[_Message]) -> int:
    """Unescaped size of a frame of this type on the wire [bytes]."""
    return 1 + 2 + 1 + cls.STRUCT.size + 1


_SPECIAL_RE = re.compile(b"[\x7e\x7d\x11\x13]")
_ESCAPED = {b: bytes((ESCAPE, b ^ XOR)) for b in SPECIAL_BYTES}


def escape(data: bytes) -> bytes:
    """API-mode-2 escaping of the bytes after the start delimiter."""
    if _SPECIAL_RE.search(data) is None:
        return data
    return _SPECIAL_RE.sub(lambda m: _ESCAPED[m.group()[0]], data)


def encode(msg: Message) -> bytes:
    """The escaped frame of a message.

    Raises
    ------
    ProtocolError
        A field does not fit its wire type (e.g. PWM above 1023, seq above 65535,
        a float beyond float32 range).
    """
    try:
        payload = msg.pack()
    except (struct.error, OverflowError) as exc:
        raise ProtocolError(f"{type(msg).__name__}: {exc}") from None
    data = bytes((msg.TYPE,)) + payload
    n = len(data)
    checksum = 0xFF - (sum(data) & 0xFF)
    return bytes((START,)) + escape(bytes((n >> 8, n & 0xFF)) + data + bytes((checksum,)))


@dataclass
class DecoderCounters:
    """What a :class:`RigDecoder` accepted and dropped.

    Attributes
    ----------
    frames : int
        Valid messages returned.
    checksum_errors : int
        Complete frames whose checksum did not match.
    length_errors : int
        Length field 0 or above :data:`MAX_FRAME_DATA`, or a payload too long / too
        short for its type (checksum good).
    unknown_types : int
        Good frames of a type this decoder does not accept.
    invalid_values : int
        Good frames with an impossible field (PWM above 1023, unknown state or result).
    truncated_frames : int
        Frames cut short by a new start delimiter.
    discarded_bytes : int
        Bytes skipped while hunting for a start delimiter.
    """

    frames: int = 0
    checksum_errors: int = 0
    length_errors: int = 0
    unknown_types: int = 0
    invalid_values: int = 0
    truncated_frames: int = 0
    discarded_bytes: int = 0

    @property
    def errors(self) -> int:
        """Frames dropped for any reason."""
        return (self.checksum_errors + self.length_errors + self.unknown_types + self.invalid_values
                + self.truncated_frames)

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


_HUNT, _FRAME = 0, 1


class RigDecoder:
    """Incremental decoder of the byte stream; never raises on any bytes.

    Parameters
    ----------
    accept : iterable of message classes or None
        Types to return (e.g. :data:`TO_PC` on the ground station); other types,
        known or not, count as ``unknown_types``.  None: all.
    max_frame_data : int
        Largest accepted length field [bytes].

    Notes
    -----
    Escapes split across :meth:`feed` calls are handled.  A checksum, length or
    value error drops the frame and the decoder hunts for the next unescaped
    0x7E; an unescaped 0x7E inside a frame aborts it (``truncated_frames``) and
    starts a new one, so the frame after any garbage is decoded.
    """

    def __init__(self, accept: Iterable[type[_Message]] | None = None, max_frame_data: int = MAX_FRAME_DATA) -> None:
        classes = MESSAGE_TYPES.values() if accept is None else accept
        self._types: dict[int, type[_Message]] = {c.TYPE: c for c in classes}
        self._max = int(max_frame_data)
        self.counters = DecoderCounters()
        self._state = _HUNT
        self._esc = False
        self._buf = bytearray()
        self._need = 2

    def reset(self) -> None:
        """Forget a partial frame (counters are kept)."""
        self._state = _HUNT
        self._esc = False
        self._buf.clear()

    def _start(self) -> None:
        self._state = _FRAME
        self._esc = False
        self._buf.clear()
        self._need = 2  # the length field first

    def feed(self, data: bytes | bytearray | memoryview) -> list[Message]:
        """Messages completed by ``data`` (in order)."""
        out: list[Message] = []
        data = bytes(data)
        n = len(data)
        i = 0
        buf = self._buf
        c = self.counters
        while i < n:
            if self._state == _HUNT:
                j = data.find(START, i)
                if j < 0:
                    c.discarded_bytes += n - i
                    break
                c.discarded_bytes += j - i
                i = j + 1
                self._start()
                continue
            b = data[i]
            if b == START:
                c.truncated_frames += 1
                i += 1
                self._start()
                continue
            if self._esc:
                self._esc = False
                buf.append(b ^ XOR)
                i += 1
            elif b == ESCAPE:
                self._esc = True
                i += 1
                continue
            else:
                # Copy the run of plain bytes up to what the frame still needs.
                end = min(n, i + self._need - len(buf))
                k = data.find(START, i, end)
                if k >= 0:
                    end = k
                k = data.find(ESCAPE, i, end)
                if k >= 0:
                    end = k
                buf += data[i:end]
                i = end
            if len(buf) < self._need:
                continue
            if self._need == 2:
                length = (buf[0] << 8) | buf[1]
                if length == 0 or length > self._max:
                    c.length_errors += 1
                    self._state = _HUNT
                    continue
                self._need = 3 + length
                continue
            msg = self._finish(buf)
            self._state = _HUNT
            if msg is not None:
                out.append(msg)
        return out

    def _finish(self, buf: bytearray) -> Message | None:
        c = self.counters
        if sum(buf[2:]) & 0xFF != 0xFF:
            c.checksum_errors += 1
            return None
        cls = self._types.get(buf[2])
        if cls is None:
            c.unknown_types += 1
            return None
        if len(buf) - 4 != cls.STRUCT.size:
            c.length_errors += 1
            return None
        try:
            msg = cls.unpack(bytes(buf[3:-1]))
        except ValueError:
            c.invalid_values += 1
            return None
        c.frames += 1
        return msg  # type: ignore[return-value]
