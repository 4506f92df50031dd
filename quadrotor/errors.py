"""The exception base shared by ``gcs`` and ``sitl``, and the errors both raise.

Every error a user can cause derives from :class:`QuadrotorError`; the command lines print its
message on one line and exit with its ``exit_code``, without a traceback.
"""

from __future__ import annotations

__all__ = ["QuadrotorError", "ConfigError", "ProtocolError"]


class QuadrotorError(Exception):
    """Base class of every error raised on purpose by ``gcs`` or ``sitl``."""

    exit_code = 1


class ConfigError(QuadrotorError, ValueError):
    """A configuration file, vehicle file or option is invalid (exit code 2).

    The message names the source, the key and the reason, e.g.
    ``configs/x.toml: nlsoc.z_psi.Q: not symmetric (Q[3,4] = 17000 != Q[4,3] = 17500)``.
    """

    exit_code = 2

    def __init__(self, source: str, key: str, reason: str) -> None:
        self.source = source
        self.key = key
        self.reason = reason
        where = f"{source}: {key}" if key else source
        super().__init__(f"{where}: {reason}")


class ProtocolError(QuadrotorError, ValueError):
    """A message cannot be encoded for the rig's serial link (a field does not fit its wire type).

    Decoding never raises: bad input is counted by :class:`quadrotor.rig_protocol.RigDecoder`.
    """

    exit_code = 2
