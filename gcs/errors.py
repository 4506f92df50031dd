"""The ground station's exception hierarchy (under :class:`quadrotor.errors.QuadrotorError`).

Every error the user can cause derives from :class:`~quadrotor.errors.QuadrotorError`; the CLI
prints its message and exits with its ``exit_code`` without a traceback.  :class:`ConfigError`
(exit 2) is shared with the simulator.
"""

from quadrotor.errors import ConfigError, QuadrotorError

__all__ = ["GcsError", "ConfigError", "DesignError", "LogError", "PreflightRefused"]


class GcsError(QuadrotorError):
    """Base class of the errors raised on purpose by ``gcs`` (other than :class:`ConfigError`)."""

    exit_code = 1


class DesignError(GcsError, ValueError):
    """A controller cannot be designed from the given matrices or model."""


class LogError(GcsError):
    """A flight log cannot be written or read: unwritable directory, full disk,
    missing file, not an MCAP log, or an MCAP log without what a tool needs."""


class PreflightRefused(GcsError):
    """A preflight check failed; the vehicle was not armed (or was disarmed again on the ground)."""

    exit_code = 7
