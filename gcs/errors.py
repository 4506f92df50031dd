"""The ground station's exception hierarchy.

Every error the user can cause derives from :class:`GcsError`; the CLI prints
its message and exits non-zero without a traceback.
"""

__all__ = ["GcsError", "ConfigError", "DesignError"]


class GcsError(Exception):
    """Base class of all errors raised on purpose by ``gcs``."""

    exit_code = 1


class ConfigError(GcsError, ValueError):
    """A configuration file or option is invalid.

    The message names the file, the key and the reason, e.g.
    ``configs/x.toml: nlsoc.z_psi.Q: not symmetric (Q[3,4] = 17000 != Q[4,3] = 17500)``.
    """

    exit_code = 2

    def __init__(self, source: str, key: str, reason: str) -> None:
        self.source = source
        self.key = key
        self.reason = reason
        where = f"{source}: {key}" if key else source
        super().__init__(f"{where}: {reason}")


class DesignError(GcsError, ValueError):
    """A controller cannot be designed from the given matrices or model."""


class LogError(GcsError):
    """A flight log cannot be written or read: unwritable directory, full disk,
    missing file, not an MCAP log, or an MCAP log without what a tool needs."""


__all__.append("LogError")
