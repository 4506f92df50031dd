"""Argument types of the ``gcs`` command line: every number checked before anything starts (exit 2)."""

from __future__ import annotations

import argparse
import math

__all__ = ["int_range", "positive_int", "nonneg_int", "positive_float", "float_range", "Parser"]


def int_range(lo: int, hi: int | None = None):
    """An argparse type: a whole number in ``lo..hi`` (``hi`` None: no upper bound)."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if v < lo or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(f"must be >= {lo}, got {v}" if hi is None
                                             else f"must be in {lo}..{hi}, got {v}")
        return v
    return parse


positive_int = int_range(1)
nonneg_int = int_range(0)


def positive_float(text: str) -> float:
    """An argparse type: a finite number > 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return v


def float_range(lo: float, hi: float):
    """An argparse type: a finite number in ``lo..hi``."""
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not (math.isfinite(v) and lo <= v <= hi):
            raise argparse.ArgumentTypeError(f"must be in {lo:g}..{hi:g}, got {text}")
        return v
    return parse


class Parser(argparse.ArgumentParser):
    """argparse's own usage errors: exit 2, one line."""

    def error(self, message: str) -> None:
        self.exit(2, f"{self.prog}: error: {message}\n")
