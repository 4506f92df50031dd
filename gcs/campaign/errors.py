"""The campaign's error type (a :class:`gcs.errors.GcsError`: one line on the CLI, exit 2)."""

from __future__ import annotations

from quadrotor.errors import ConfigError

__all__ = ["CampaignError"]


class CampaignError(ConfigError):
    """A campaign cannot be planned or run as asked: unknown experiment, ``--runs 0``,
    an executor that is not installed, an output folder that cannot be written, ...

    Like :class:`gcs.errors.ConfigError`: ``CampaignError(where, key, reason)`` reads
    ``where: key: reason`` (``where: reason`` with an empty key), e.g.
    ``--runs: must be >= 1, got 0``.
    """

    exit_code = 2
