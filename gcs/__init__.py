"""Ground-station flight controller for quadrotors (NLSOC, LOC, PD): ``gcs.fly``, ``gcs.simulate``.

The Python API lives in :mod:`gcs.api` (imported on first use, so ``import gcs.config`` stays light).
"""

__version__ = "0.1.0"

_API = ("fly", "simulate", "FlightSpec", "FlightResult")


def __getattr__(name: str):
    if name in _API:
        from gcs import api

        return getattr(api, name)
    raise AttributeError(f"module 'gcs' has no attribute {name!r}")


__all__ = list(_API)
