"""Allowed ranges of the numbers read from files and options: one :class:`Bound` per key.

The ground station's experiment configs (``gcs.config.bounds``) and the simulator's vehicle
files (``sitl.vehicle_params``) both check every number they read against such a table, so
that no NaN, infinity or physically absurd value gets past loading.
"""

from __future__ import annotations

import math
import reprlib
from dataclasses import dataclass
from typing import Any

__all__ = ["Bound", "OutOfBounds", "short_repr", "MASS_KG", "GRAVITY_M_S2", "INERTIA_KG_M2", "DRAG_N_PER_M_S",
           "NOISE_M", "ATTITUDE_NOISE_RAD", "RATE_NOISE_RAD_S"]


class OutOfBounds(ValueError):
    """A value is not a finite number in its :class:`Bound` (the message says why)."""


_REPR = reprlib.Repr()
_REPR.maxlevel, _REPR.maxlist, _REPR.maxdict, _REPR.maxstring, _REPR.maxother = 3, 6, 4, 40, 40


def short_repr(value: Any) -> str:
    """``repr(value)`` cut short (deeply nested or huge values make no message unreadable)."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 10 ** 30:
        return f"a {'negative ' if value < 0 else ''}{len(str(abs(value)))}-digit integer"
    return _REPR.repr(value)


def _fmt(x: float) -> str:
    return str(x) if isinstance(x, int) else f"{x:g}"


@dataclass(frozen=True)
class Bound:
    """The closed range ``[lo, hi]`` a number read from a file must lie in, with its unit and why.

    Attributes
    ----------
    lo, hi : float
        Smallest and largest allowed value.
    unit : str
        SI unit of the value ("" for none), shown in messages.
    why : str
        What the range stands for, shown in messages.
    integer : bool
        Only whole numbers (TOML integers) are allowed.
    """

    lo: float
    hi: float
    unit: str = ""
    why: str = ""
    integer: bool = False

    def describe(self) -> str:
        """``"allowed [lo, hi] unit (why)"``."""
        unit = f" {self.unit}" if self.unit else ""
        return f"allowed [{_fmt(self.lo)}, {_fmt(self.hi)}]{unit} ({self.why})"

    def check(self, value: Any) -> float | int:
        """``value`` as a float (an int for integer bounds) when it is a finite number in range.

        Raises
        ------
        OutOfBounds
            Not a number, not finite, or out of range; the message gives the allowed range.
        """
        kind = "an integer" if self.integer else "a number"
        if (isinstance(value, bool) or not isinstance(value, (int, float))
                or (self.integer and not isinstance(value, int))):
            raise OutOfBounds(f"must be {kind}, got {short_repr(value)}; {self.describe()}")
        unit = f" {self.unit}" if self.unit else ""
        try:
            v = value if self.integer else float(value)
        except OverflowError:
            raise OutOfBounds(f"must be at most {_fmt(self.hi)}{unit}, got {short_repr(value)}; "
                              f"{self.describe()}") from None
        if not math.isfinite(v):
            raise OutOfBounds(f"must be finite, got {v!r}; {self.describe()}")
        if v < self.lo:
            if self.integer:
                head = f"must be >= {_fmt(self.lo)}"
            elif self.lo > 0 >= v:
                head = "must be > 0"
            elif self.lo == 0:
                head = "must be >= 0"
            else:
                head = f"must be at least {_fmt(self.lo)}{unit}"
            raise OutOfBounds(f"{head}, got {_fmt(v)}; {self.describe()}")
        if v > self.hi:
            raise OutOfBounds(f"must be at most {_fmt(self.hi)}{unit}, got {_fmt(v)}; {self.describe()}")
        return v


# Ranges both the experiment configs and the simulator's vehicle files read.
MASS_KG = Bound(0.01, 100.0, "kg", "a quadrotor of 10 g to 100 kg")
GRAVITY_M_S2 = Bound(1.0, 30.0, "m/s^2", "surface gravity; Earth 9.81")
INERTIA_KG_M2 = Bound(1e-6, 1e3, "kg m^2", "a principal moment of inertia")
DRAG_N_PER_M_S = Bound(0.0, 100.0, "N/(m/s)", "linear air drag")
NOISE_M = Bound(0.0, 10.0, "m", "sensor noise or resolution; 0 = none")
ATTITUDE_NOISE_RAD = Bound(0.0, 0.5, "rad", "IMU attitude noise; 0 = none")
RATE_NOISE_RAD_S = Bound(0.0, 10.0, "rad/s", "gyro noise; 0 = none")
