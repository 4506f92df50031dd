"""The SITL's exception hierarchy.

Every error a user can cause derives from :class:`SitlError`; the ``sitl``
command prints its message on one line and exits with ``exit_code`` without a
traceback.
"""

from __future__ import annotations

from quadrotor.errors import QuadrotorError

__all__ = ["SitlError", "TransportError", "UsageError"]


class SitlError(QuadrotorError):
    """Base class of every error raised on purpose by ``sitl``."""

    exit_code = 1


class UsageError(SitlError, ValueError):
    """A command-line option or constructor argument is invalid."""

    exit_code = 2


class TransportError(SitlError, OSError):
    """An endpoint cannot be opened (port in use, no pseudo-terminal, ...)."""

    exit_code = 1
