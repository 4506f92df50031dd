"""What the ground station (``gcs``) and the simulator (``sitl``) share, importing neither.

State and command types, the paper's reduced model (eq. 1) and its plant, sensors and wind,
frame conversions, clocks, the bounds of every number read from a file, the rig's wire
protocol, MAVLink signing, framing and ArduCopter's modes, and the exception base.
"""
