"""What this ``gcs fly`` offers: its option strings, read from its argument parser.

The campaign adapts its command lines to the flight stack it finds: ``--log`` (MCAP
log of the flight), ``--duration`` (cut the mission, then land) and ``--rig`` (the
indoor 4-DOF rig) are used when ``gcs fly`` has them and worked around (no log; a
shortened derived config) or refused (indoor flights) when it does not.
"""

from __future__ import annotations

import argparse
from functools import lru_cache

__all__ = ["fly_options", "FlyCapabilities", "fly_capabilities"]


@lru_cache(maxsize=1)
def fly_options() -> frozenset[str]:
    """Every option string of ``gcs fly`` (``--log``, ``-q``, ...), from :func:`gcs.cli.build_parser`."""
    from gcs.cli import build_parser

    parser = build_parser()
    for action in parser._actions:  # argparse keeps its subparsers here; there is no public accessor
        if isinstance(action, argparse._SubParsersAction) and "fly" in action.choices:
            fly = action.choices["fly"]
            return frozenset(s for a in fly._actions for s in a.option_strings)
    return frozenset()


class FlyCapabilities:
    """The options of ``gcs fly`` the campaign cares about.

    Parameters
    ----------
    options : iterable of str
        Option strings (default: this installation's, :func:`fly_options`).
    """

    def __init__(self, options: frozenset[str] | set[str] | None = None) -> None:
        self.options = frozenset(fly_options() if options is None else options)

    @property
    def log(self) -> bool:
        """``gcs fly --log PATH`` exists."""
        return "--log" in self.options

    @property
    def duration(self) -> bool:
        """``gcs fly --duration SECONDS`` exists."""
        return "--duration" in self.options

    @property
    def rig(self) -> bool:
        """``gcs fly --rig 4dof`` exists (the indoor experiment)."""
        return "--rig" in self.options

    def __repr__(self) -> str:
        return f"FlyCapabilities(log={self.log}, duration={self.duration}, rig={self.rig})"


def fly_capabilities() -> FlyCapabilities:
    """This installation's :class:`FlyCapabilities`."""
    return FlyCapabilities()
