"""Firmware.from_messages: what the autopilot says it is (AUTOPILOT_VERSION), and our own SITL's mark."""

from __future__ import annotations

import dataclasses

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.vehicles.firmware import BUILTIN_SITL_MARK, CAP_SET_ACTUATOR_TARGET, CAP_SET_ATTITUDE_TARGET, Firmware

ARDUPILOT, PX4 = 3, 12
MAV = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)


def sw_version(major: int, minor: int, patch: int, kind: int = 255) -> int:
    """``flight_sw_version``: major << 24 | minor << 16 | patch << 8 | FIRMWARE_VERSION_TYPE."""
    return (major << 24) | (minor << 16) | (patch << 8) | kind


def version_msg(capabilities: int = CAP_SET_ATTITUDE_TARGET, sw: int = sw_version(4, 5, 7),
                custom=(0,) * 8, wire: bool = True):
    msg = MAV.autopilot_version_encode(capabilities, sw, 0, 0, 0, list(custom), [0] * 8, [0] * 8, 0x1234, 0x5678,
                                       0, [0] * 18)
    if not wire:
        return msg
    (parsed,) = mavlink.MAVLink(None).parse_buffer(msg.pack(MAV))
    return parsed


def test_no_version_message_knows_only_the_family():
    fw = Firmware.from_messages(ARDUPILOT, None)
    assert fw == Firmware(ARDUPILOT)
    assert fw.version is None
    assert fw.capabilities is None
    assert fw.builtin_sitl is False
    assert fw.takes_actuator_targets() is None
    assert fw.describe() == "ArduPilot"
    assert Firmware.from_messages(PX4).describe() == "PX4"


@pytest.mark.parametrize("wire", [True, False])
def test_version_and_capabilities(wire):
    fw = Firmware.from_messages(ARDUPILOT, version_msg(CAP_SET_ATTITUDE_TARGET | 2, sw_version(4, 5, 7), wire=wire))
    assert fw.autopilot == ARDUPILOT
    assert fw.version == (4, 5, 7)
    assert fw.capabilities == CAP_SET_ATTITUDE_TARGET | 2
    assert fw.builtin_sitl is False
    assert fw.describe() == "ArduPilot 4.5.7"


def test_version_ignores_the_release_type_byte():
    for kind in (0, 64, 128, 192, 255):  # dev, alpha, beta, rc, official
        assert Firmware.from_messages(ARDUPILOT, version_msg(sw=sw_version(4, 8, 0, kind))).version == (4, 8, 0)
    assert Firmware.from_messages(PX4, version_msg(sw=sw_version(1, 14, 3))).describe() == "PX4 1.14.3"
    assert Firmware.from_messages(PX4, version_msg(sw=sw_version(255, 255, 255))).version == (255, 255, 255)


def test_unknown_autopilot_family():
    assert Firmware.from_messages(8).describe() == "autopilot 8"
    assert Firmware.from_messages(8, version_msg(sw=sw_version(2, 0, 1))).describe() == "autopilot 8 2.0.1"


@pytest.mark.parametrize(("caps", "expected"), [
    (CAP_SET_ACTUATOR_TARGET, True),
    (CAP_SET_ACTUATOR_TARGET | CAP_SET_ATTITUDE_TARGET | 0xFFFF_0000, True),
    (CAP_SET_ATTITUDE_TARGET, False),
    (0, False),
    (0xFFFF_FFFF & ~CAP_SET_ACTUATOR_TARGET, False),
])
def test_takes_actuator_targets(caps, expected):
    assert Firmware.from_messages(ARDUPILOT, version_msg(caps)).takes_actuator_targets() is expected


def test_capability_constants():
    assert CAP_SET_ATTITUDE_TARGET == mavlink.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    assert CAP_SET_ACTUATOR_TARGET == 1024
    assert BUILTIN_SITL_MARK == b"gcssitl\0"
    assert len(BUILTIN_SITL_MARK) == 8


@pytest.mark.parametrize("wire", [True, False])
def test_builtin_sitl_mark(wire):
    fw = Firmware.from_messages(ARDUPILOT, version_msg(custom=BUILTIN_SITL_MARK, sw=sw_version(4, 8, 0, 0),
                                                       wire=wire))
    assert fw.builtin_sitl is True
    assert fw.describe() == "ArduPilot 4.8.0 (built-in SITL)"


@pytest.mark.parametrize("custom", [
    (0,) * 8,
    b"gcssitl1",
    b"GCSSITL\0",
    b"gcssit\0\0",
    bytes.fromhex("a1b2c3d4e5f60718"),  # a git hash, as ArduPilot sends
])
def test_other_custom_versions_are_not_the_builtin_sitl(custom):
    assert Firmware.from_messages(ARDUPILOT, version_msg(custom=custom)).builtin_sitl is False


def test_firmware_is_frozen():
    fw = Firmware.from_messages(ARDUPILOT, version_msg())
    with pytest.raises(dataclasses.FrozenInstanceError):
        fw.autopilot = PX4  # type: ignore[misc]


# --------------------------------------------------------------------------- our own SITL's answer
@pytest.fixture(scope="module")
def sim():
    from sitl.copter.simulation import Simulation
    from sitl.copter.vehicle_file import load_vehicle
    return Simulation(load_vehicle(), seed=1)


def test_builtin_sitl_answer_is_marked(sim):
    from sitl.copter.telemetry import autopilot_version

    msg = autopilot_version(sim)
    assert msg.get_type() == "AUTOPILOT_VERSION"
    for m in (msg, mavlink.MAVLink(None).parse_buffer(msg.pack(MAV))[0]):  # as built, and off the wire
        fw = Firmware.from_messages(mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, m)
        assert fw.builtin_sitl is True
        assert fw.takes_actuator_targets() is True
        assert fw.capabilities & CAP_SET_ATTITUDE_TARGET
        assert fw.version is not None and fw.version[0] == 4
        assert fw.describe().startswith("ArduPilot 4.") and fw.describe().endswith("(built-in SITL)")
