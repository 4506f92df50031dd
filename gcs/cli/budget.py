"""``gcs link-budget``: does the 100 Hz exchange fit a serial link (exit 1 when it does not)."""

from __future__ import annotations

import argparse

from gcs.cli.args import positive_float, positive_int
from gcs.link.budget import compute_budget, control_streams, format_budget, suggest_fixes
from quadrotor.errors import ConfigError

__all__ = ["add_budget_parser", "cmd_link_budget"]


def add_budget_parser(sub) -> None:
    b = sub.add_parser("link-budget", help="bytes per second each way of the 100 Hz exchange over a serial link",
                       description="Compute the MAVLink 2 link budget of the control exchange at a baud rate: "
                                   "telemetry down, setpoints up, housekeeping both ways.")
    b.add_argument("--baud", type=positive_int, default=57600, help="serial baud rate, 8N1 (default 57600)")
    b.add_argument("--rate", type=positive_float, default=100.0, help="control rate [Hz] (default 100)")
    b.add_argument("--telemetry-rate", type=positive_float,
                   help="ATTITUDE/LOCAL_POSITION_NED rate [Hz] (default: --rate)")
    b.add_argument("--output", choices=("attitude", "rates", "actuator"), default="attitude",
                   help="setpoint message (SET_ATTITUDE_TARGET or SET_ACTUATOR_CONTROL_TARGET)")
    b.add_argument("--signed", action="store_true", help="MAVLink 2 signing (+13 bytes a frame)")
    b.add_argument("--air-rate", type=positive_float, metavar="BPS",
                   help="telemetry radio air data rate [bit/s] (half duplex, shared by both directions)")
    b.add_argument("--ecc", action="store_true", help="radio error correction on (halves the air throughput)")
    b.add_argument("--max-utilisation", type=positive_float, default=0.8, help="largest usable share (default 0.8)")


def cmd_link_budget(args: argparse.Namespace) -> int:
    if args.max_utilisation > 1:
        raise ConfigError("--max-utilisation", "", f"must be <= 1, got {args.max_utilisation:g}")
    streams = control_streams(args.rate, args.telemetry_rate, args.output)
    budget = compute_budget(streams, args.baud, signed=args.signed, max_utilisation=args.max_utilisation,
                            air_rate_bps=args.air_rate, ecc=args.ecc)
    print(format_budget(budget))
    if not budget.fits:
        print("configurations that fit:")
        for fix in suggest_fixes(budget, args.rate, args.output):
            print(f"  {fix}")
        return 1
    return 0
