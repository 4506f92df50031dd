"""Experiment configs shipped with the package as ``gcs.configs`` (see pyproject.toml)."""
