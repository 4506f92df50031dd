"""Simulated vehicles: the reduced plant of the paper, the 6-DOF SITL, sensors and wind.

The physics never imports a link and never imports ``gcs`` internals.

Modules of the networked SITL (``sitl`` command, :class:`sitl.server.SitlServer`):

* plant: :mod:`sitl.rigid_body` (6-DOF, NED/FRD, motors, ground contact),
  :mod:`sitl.mixer`, :mod:`quadrotor.plant` (paper model, z up), :mod:`quadrotor.frames`
  (the one paper/NED conversion), :mod:`sitl.world` (plant + wind + battery),
  :mod:`sitl.battery`, :mod:`sitl.vehicle_params` (vehicle TOML files);
* autopilot: :mod:`sitl.ned_sensors`, :mod:`sitl.control`, :mod:`sitl.autopilot`,
  :mod:`sitl.params`, :mod:`sitl.simulation` (one tick of everything);
* link: :mod:`sitl.telemetry`, :mod:`sitl.streams`, :mod:`sitl.dispatch`,
  :mod:`sitl.endpoint`, :mod:`quadrotor.mavlink.signing`, :mod:`sitl.links` (one link per peer),
  :mod:`sitl.transport`, :mod:`sitl.radio`, :mod:`quadrotor.clock`, :mod:`sitl.server`,
  :mod:`sitl.options`, :mod:`sitl.cli`.
"""

__version__ = "0.1.0"
