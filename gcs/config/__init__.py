"""Experiment configuration: TOML files loaded into validated, frozen dataclasses.

A config describes one of the paper's experiments: sampling, horizon, vehicle,
mission phases, the penalty matrices of LOC and NLSOC, the PD gains, and the
simulation's wind, sensors and estimator.  Loading rejects, naming the file,
the key and the reason: unknown keys, missing sections or keys, wrong types
and shapes, every number that is not finite or outside its physical range
(the one table :data:`~gcs.config.bounds.BOUNDS`; the message gives the range
and unit), non-symmetric or indefinite Q/H, R not positive definite, and
inconsistent values (a horizon, duration or phase shorter than one control
period, a plant sub-step longer than it, a ceiling below the mission, a
telemetry rate too slow for the stale timeout, ...).

Matrices may be written as a number (1x1), a flat list (diagonal) or a list
of rows.  Where the paper's printed matrix is wrong (``../shared/paper/NOTES.md``,
erratum 7) the config gives the corrected matrix under its name (``Q``), the
literal printed one under ``<name>_printed`` and lists the name in
``corrected``.  ``[experiment] matrices = "printed"`` (or ``gcs sim
--matrices printed``) selects the printed ones; the symmetry and
definiteness checks of Q and H are then skipped, since the printed matrices
fail them by construction.

The package: :mod:`~gcs.config.bounds` (the ranges), :mod:`~gcs.config.sections`
(the dataclasses), :mod:`~gcs.config.reader` (typed, bounded reading of one
table; matrices) and :mod:`~gcs.config.parse` (files and sections).
"""

from __future__ import annotations

from gcs.config.bounds import BOUNDS, LOC_SUBSYSTEMS, MAX_HORIZON_STEPS, NLSOC_SUBSYSTEMS, bound_for
from gcs.config.parse import bundled_configs, load_config, parse_config, resolve_config_path
from gcs.config.sections import (AFTER_HORIZON, DISTURBANCE_MODES, MATRIX_MODES, PHASE_KINDS, Config,
                                 EstimatorConfig, ExperimentConfig, FlightConfig, Matrix, MatrixSet, PdGains,
                                 PhaseConfig, SimConfig)

__all__ = [
    "Config", "ExperimentConfig", "MatrixSet", "PhaseConfig", "PdGains", "SimConfig",
    "EstimatorConfig", "FlightConfig", "load_config", "parse_config", "resolve_config_path", "bundled_configs",
    "AFTER_HORIZON", "MATRIX_MODES", "PHASE_KINDS", "DISTURBANCE_MODES", "BOUNDS", "bound_for",
    "LOC_SUBSYSTEMS", "NLSOC_SUBSYSTEMS", "MAX_HORIZON_STEPS", "Matrix",
]
