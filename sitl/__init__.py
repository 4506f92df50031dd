"""Simulated vehicles: the reduced plant of the paper, sensors and wind.

The physics here never imports a link and never imports ``gcs`` internals.
"""

__version__ = "0.1.0"
