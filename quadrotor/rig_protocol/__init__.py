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

    from quadrotor import rig_protocol as rp

    port.write(rp.encode(rp.Arm(seq=1)))
    dec = rp.RigDecoder(rp.TO_PC)              # accept only rig -> PC types
    for msg in dec.feed(port.read(4096)):      # any chunking; never raises
        if isinstance(msg, rp.Telemetry):
            ...
    dec.counters.checksum_errors               # what was dropped, and why
"""

from quadrotor.rig_protocol.framing import DecoderCounters, RigDecoder, encode, escape
from quadrotor.rig_protocol.messages import (CUTOFF_CAUSES, ESCAPE, MAX_FRAME_DATA, MESSAGE_TYPES, PROTOCOL_VERSION,
                                             PWM_MAX, SPECIAL_BYTES, START, TO_PC, TO_RIG, XOR, Ack, AckResult, Arm,
                                             Control, ControlPwm, Disarm, Heartbeat, Message, MessageBase, RigFlags,
                                             RigState, Status, Telemetry, frame_size)

__all__ = [
    "START", "ESCAPE", "XOR", "SPECIAL_BYTES", "MAX_FRAME_DATA", "PROTOCOL_VERSION", "PWM_MAX",
    "RigFlags", "CUTOFF_CAUSES", "RigState", "AckResult",
    "Control", "ControlPwm", "Arm", "Disarm", "Heartbeat", "Telemetry", "Status", "Ack",
    "Message", "MessageBase", "MESSAGE_TYPES", "TO_RIG", "TO_PC", "frame_size",
    "encode", "escape", "DecoderCounters", "RigDecoder",
]
