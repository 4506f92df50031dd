"""What the autopilot says it is: AUTOPILOT_VERSION, asked for once before arming.

:class:`Firmware` is what the session knows of the firmware it flies: its family (HEARTBEAT
``autopilot``), version, capabilities, and whether it is this project's own simulator (the
built-in ``sitl`` marks its AUTOPILOT_VERSION with :data:`BUILTIN_SITL_MARK` in
``flight_custom_version``).  Decisions that depend on the firmware (refusing an output it
cannot take, estimating offsets a real autopilot leaves) read it here, not from guesses.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["BUILTIN_SITL_MARK", "CAP_SET_ACTUATOR_TARGET", "CAP_SET_ATTITUDE_TARGET", "Firmware"]

#: ``flight_custom_version`` of the built-in SITL's AUTOPILOT_VERSION (8 bytes).
BUILTIN_SITL_MARK = b"gcssitl\0"
#: MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET.
CAP_SET_ATTITUDE_TARGET = 64
#: MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE: integer parameters are the float field's bytes.
CAP_PARAM_ENCODE_BYTEWISE = 16
#: MAV_PROTOCOL_CAPABILITY_SET_ACTUATOR_TARGET (1024; "RESERVED3" in newer dialects): the
#: autopilot takes SET_ACTUATOR_CONTROL_TARGET.  ArduCopter does not (it has no handler).
CAP_SET_ACTUATOR_TARGET = 1024


@dataclass(frozen=True)
class Firmware:
    """The autopilot's identity.

    Attributes
    ----------
    autopilot : int
        HEARTBEAT ``autopilot`` (MAV_AUTOPILOT: 3 ArduPilot, 12 PX4).
    version : tuple of int or None
        (major, minor, patch) from ``flight_sw_version``; None without an AUTOPILOT_VERSION.
    capabilities : int or None
        MAV_PROTOCOL_CAPABILITY bits; None without an AUTOPILOT_VERSION (nothing known).
    builtin_sitl : bool
        This project's own simulator.
    """

    autopilot: int
    version: tuple[int, int, int] | None = None
    capabilities: int | None = None
    builtin_sitl: bool = False

    @classmethod
    def from_messages(cls, autopilot: int, version_msg=None) -> Firmware:
        """From the HEARTBEAT's ``autopilot`` and an AUTOPILOT_VERSION message (or None)."""
        if version_msg is None:
            return cls(int(autopilot))
        sw = int(version_msg.flight_sw_version)
        custom = bytes(int(b) & 0xFF for b in version_msg.flight_custom_version)
        return cls(int(autopilot), ((sw >> 24) & 0xFF, (sw >> 16) & 0xFF, (sw >> 8) & 0xFF),
                   int(version_msg.capabilities), custom == BUILTIN_SITL_MARK)

    def takes_actuator_targets(self) -> bool | None:
        """Whether SET_ACTUATOR_CONTROL_TARGET is handled (None: unknown)."""
        if self.capabilities is None:
            return None
        return bool(self.capabilities & CAP_SET_ACTUATOR_TARGET)

    def params_bytewise(self) -> bool:
        """Integer parameters travel bytewise (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE; PX4 when unknown)."""
        if self.capabilities is None:
            return self.autopilot == 12
        return bool(self.capabilities & CAP_PARAM_ENCODE_BYTEWISE)

    def describe(self) -> str:
        family = {3: "ArduPilot", 12: "PX4"}.get(self.autopilot, f"autopilot {self.autopilot}")
        ver = "" if self.version is None else " " + ".".join(map(str, self.version))
        return f"{family}{ver}" + (" (built-in SITL)" if self.builtin_sitl else "")
