"""Ground-station flight controller for quadrotors (NLSOC, LOC, PD)."""

__version__ = "0.1.0"
