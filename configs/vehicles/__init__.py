"""Vehicle parameter files shipped with the package as ``sitl.vehicles`` (see pyproject.toml)."""
