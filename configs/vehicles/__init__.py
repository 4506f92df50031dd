"""Vehicle parameter files shipped with the package as ``sitl.vehicles`` (see pyproject.toml).

Load them with :func:`sitl.vehicle_params.load_vehicle` by name (``"quad-1kg"``,
``"talon-550"``) or by path.
"""
