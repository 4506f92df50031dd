"""The SITL's exception hierarchy.

Every error a user can cause derives from :class:`SitlError`; the ``sitl``
command prints its message on one line and exits with ``exit_code`` without a
traceback.
"""

from __future__ import annotations

__all__ = ["SitlError", "VehicleConfigError", "TransportError", "UsageError", "ProtocolError"]


class SitlError(Exception):
    """Base class of every error raised on purpose by ``sitl``."""

    exit_code = 1


class VehicleConfigError(SitlError, ValueError):
    """A vehicle parameter file or value is invalid.

    The message names the source, the key and the reason, e.g.
    ``configs/vehicles/x.toml: rotors.max_thrust_n: must be > 0, got -1.0``.
    """

    exit_code = 2

    def __init__(self, source: str, key: str, reason: str) -> None:
        self.source = source
        self.key = key
        self.reason = reason
        where = f"{source}: {key}" if key else source
        super().__init__(f"{where}: {reason}")


class UsageError(SitlError, ValueError):
    """A command-line option or constructor argument is invalid."""

    exit_code = 2


class TransportError(SitlError, OSError):
    """An endpoint cannot be opened (port in use, no pseudo-terminal, ...)."""

    exit_code = 1


class ProtocolError(SitlError, ValueError):
    """A message cannot be encoded for the rig's serial link (a field does not fit its wire type).

    Decoding never raises: bad input is counted by :class:`sitl.rig_protocol.RigDecoder`.
    """

    exit_code = 2
