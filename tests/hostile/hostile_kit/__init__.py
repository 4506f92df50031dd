"""Flights through the hostile proxy: ``gcs fly`` and ``sitl`` as separate processes, and what to check.

:func:`run_flight` starts the proxy (:mod:`mitm`), then ``gcs fly --connect udpin:127.0.0.1:G``
(as a subprocess, output to files), waits until it listens, then ``python -m sitl.cli --udp
127.0.0.1:<proxy> --seed N [--lockstep]``; an optional ``action`` is called every 20 ms while the
flight runs (signals, a second client, ...).  When the ground station has exited (or was killed,
or overran its deadline: a hang), the SITL is stopped with SIGINT and everything is collected in
an :class:`Outcome`.  :func:`problems` lists every broken acceptance rule of the hostile-link
issue; a test asserts that the list is empty, so one failing flight reports all it broke.

``spec`` (what a flight is and what came of it), ``procs`` (command lines, ports, stopping),
``runner`` (one flight), ``actions`` (signals while flying), ``verdict`` (the rules).
"""

from .actions import signal_after_armed, vehicle_down
from .procs import flight_config, free_udp_port, sitl_supports, udp_port_bound
from .runner import log_info, run_flight
from .spec import Outcome, Run, Spec
from .verdict import (CHANGED_RE, DOCUMENTED_CODES, EXIT_CODES, GROUND_M, REGISTRY, check, fence_problems, problems,
                      record, report)

__all__ = ["CHANGED_RE", "DOCUMENTED_CODES", "EXIT_CODES", "GROUND_M", "REGISTRY", "Outcome", "Run", "Spec", "check",
           "fence_problems", "flight_config", "free_udp_port", "log_info", "problems", "record", "report",
           "run_flight", "signal_after_armed", "sitl_supports", "udp_port_bound", "vehicle_down"]
