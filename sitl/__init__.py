"""Simulated vehicles for the ground station: a MAVLink ArduCopter (:mod:`sitl.copter`) and the
paper's 4-DOF rig (:mod:`sitl.rig`), served over :mod:`sitl.net`.  Never imports ``gcs``."""

__version__ = "0.1.0"
