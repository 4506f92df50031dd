"""The simulated ArduCopter: plant, sensors, battery, autopilot emulation, its MAVLink side and its server.

Layers, each importing only those before it: vehicle parameters (``vehicle``, ``vehicle_file``);
physics (``rigid_body``, ``mixer``, ``battery``, ``world``); the autopilot (``sensors``, ``params``,
``modes``, ``targets``, ``arming``, ``control``, ``autopilot``); ``simulation`` (one tick of
everything); MAVLink (``telemetry``, ``streams``, ``dispatch``); ``server``.
"""
