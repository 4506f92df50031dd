"""The rig protocol's messages: type ids, payload layouts (little-endian structs), flags and states.

Each message is a frozen dataclass with its ``TYPE`` byte, its ``STRUCT`` and its fields' wire
kinds (``KINDS``); :meth:`MessageBase.pack` refuses a value that does not fit its wire type.
The framing (start byte, length, escaping, checksum) is :mod:`quadrotor.rig_protocol.framing`.
"""

from __future__ import annotations

import enum
import math
import operator
import struct
from dataclasses import dataclass, fields
from typing import ClassVar

from quadrotor.errors import ProtocolError

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


class MessageBase:
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
    def unpack(cls, payload: bytes | bytearray | memoryview) -> MessageBase:
        """Message from a payload of exactly ``STRUCT.size`` bytes; ValueError if a field is invalid."""
        return cls(*cls.STRUCT.unpack(payload))


def _kinds(*items: str) -> tuple[tuple[str, str], ...]:
    return tuple(tuple(i.split(":")) for i in items)  # type: ignore[misc]


@dataclass(frozen=True, slots=True)
class Control(MessageBase):
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
class ControlPwm(MessageBase):
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
    def unpack(cls, payload: bytes | bytearray | memoryview) -> ControlPwm:
        seq, *pwm = cls.STRUCT.unpack(payload)
        if max(pwm) > PWM_MAX:
            raise ValueError(f"PWM value above {PWM_MAX}: {pwm}")
        return cls(seq, tuple(pwm))  # type: ignore[arg-type]


@dataclass(frozen=True, slots=True)
class Arm(MessageBase):
    """PC -> rig: arm the motors (accepted only when landed); answered by ACK with ``seq``."""

    TYPE: ClassVar[int] = 0x03
    NAME: ClassVar[str] = "ARM"
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<B")
    KINDS: ClassVar = _kinds("seq:u8")
    seq: int = 0


@dataclass(frozen=True, slots=True)
class Disarm(MessageBase):
    """PC -> rig: stop the motors at once (also in the air) and clear a latched cut-off."""

    TYPE: ClassVar[int] = 0x04
    NAME: ClassVar[str] = "DISARM"
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<B")
    KINDS: ClassVar = _kinds("seq:u8")
    seq: int = 0


@dataclass(frozen=True, slots=True)
class Heartbeat(MessageBase):
    """PC -> rig: a ping; the rig answers with STATUS echoing ``time_us`` [µs, uint32]."""

    TYPE: ClassVar[int] = 0x05
    NAME: ClassVar[str] = "HEARTBEAT"
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<I")
    KINDS: ClassVar = _kinds("time_us:u32")
    time_us: int = 0


@dataclass(frozen=True, slots=True)
class Telemetry(MessageBase):
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
    def unpack(cls, payload: bytes | bytearray | memoryview) -> Telemetry:
        v = cls.STRUCT.unpack(payload)
        return cls(*v[:9], RigFlags(v[9]), v[10])

    @property
    def altitude_m(self) -> float:
        """Ultrasonic altitude [m]."""
        return self.altitude_mm * 1e-3


@dataclass(frozen=True, slots=True)
class Status(MessageBase):
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
    def unpack(cls, payload: bytes | bytearray | memoryview) -> Status:
        v = list(cls.STRUCT.unpack(payload))
        v[1] = RigState(v[1])          # ValueError on an unknown state
        v[6] = RigFlags(v[6])
        return cls(*v)


@dataclass(frozen=True, slots=True)
class Ack(MessageBase):
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
    def unpack(cls, payload: bytes | bytearray | memoryview) -> Ack:
        t, seq, result = cls.STRUCT.unpack(payload)
        return cls(t, seq, AckResult(result))


Message = Control | ControlPwm | Arm | Disarm | Heartbeat | Telemetry | Status | Ack

#: Type id -> message class.
MESSAGE_TYPES: dict[int, type[MessageBase]] = {
    c.TYPE: c for c in (Control, ControlPwm, Arm, Disarm, Heartbeat, Telemetry, Status, Ack)}
#: What the rig accepts (PC -> rig) and what the PC accepts (rig -> PC).
TO_RIG: tuple[type[MessageBase], ...] = (Control, ControlPwm, Arm, Disarm, Heartbeat)
TO_PC: tuple[type[MessageBase], ...] = (Telemetry, Status, Ack)


def _check_consistency() -> None:
    for cls in MESSAGE_TYPES.values():
        names = [f.name for f in fields(cls)]  # type: ignore[arg-type]
        if cls is not ControlPwm and names != [k for k, _ in cls.KINDS]:
            raise AssertionError(f"{cls.__name__}: fields and KINDS differ")
        if 1 + cls.STRUCT.size > MAX_FRAME_DATA:
            raise AssertionError(f"{cls.__name__}: payload too long")


_check_consistency()


def frame_size(cls: type[MessageBase]) -> int:
    """Unescaped size of a frame of this type on the wire [bytes]."""
    return 1 + 2 + 1 + cls.STRUCT.size + 1
