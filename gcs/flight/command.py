"""``gcs fly`` from the command line: arguments, link, optional built-in SITL, summary."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

from gcs.config import load_config
from gcs.control import CONTROLLERS
from gcs.flight.clock import MonotonicClock
from gcs.flight.embedded import EmbeddedSitl
from gcs.flight.fly import EXIT_CODES, Flight, FlightResult, PreflightRefused, _Interrupts
from gcs.flight.output import OUTPUTS
from gcs.link.budget import compute_budget, control_streams, format_budget, suggest_fixes
from gcs.link.mavlink import LinkError, MavlinkLink, read_signing_key

__all__ = ["add_fly_parser", "cmd_fly", "DEFAULT_FLY_CONFIG"]

DEFAULT_FLY_CONFIG = "outdoor-circle"


def add_fly_parser(sub, positive_int, positive_float) -> None:
    f = sub.add_parser(
        "fly", help="fly a vehicle (or the built-in SITL) with the paper's controllers at 100 Hz over MAVLink",
        description="Preflight, GUIDED_NOGPS, arm, the config's mission at 100 Hz, LAND, disarm. With neither "
                    "--port nor --connect it flies the built-in SITL on loopback. Exit codes: 0 completed, "
                    "2 bad config/option, 3 telemetry lost, 4 geofence, 5 interrupted (landed), 6 link error, "
                    "7 preflight refused, 8 immediate LAND (second Ctrl-C), 9 the vehicle left guided control.")
    f.add_argument("--controller", default="nlsoc", choices=CONTROLLERS, help="controller (default nlsoc)")
    f.add_argument("--config", default=DEFAULT_FLY_CONFIG,
                   help=f"experiment config, path or bundled name (default {DEFAULT_FLY_CONFIG})")
    where = f.add_mutually_exclusive_group()
    where.add_argument("--port", metavar="DEVICE", help="serial device of the telemetry radio, e.g. /dev/ttyUSB0")
    where.add_argument("--connect", metavar="URL", help="pymavlink URL: udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT")
    f.add_argument("--baud", type=positive_int, default=57600, help="serial baud rate (default 57600)")
    f.add_argument("--target-system", type=positive_int, default=1, help="vehicle system id (default 1)")
    f.add_argument("--target-component", type=positive_int, default=1, help="vehicle component id (default 1)")
    f.add_argument("--signing-key", metavar="FILE", help="MAVLink 2 signing key file (32 bytes, 64 hex digits or a passphrase)")
    f.add_argument("--output", choices=OUTPUTS, help="setpoint message (default: the config's [flight] output)")
    f.add_argument("--telemetry-rate", type=positive_float, metavar="HZ", help="ATTITUDE/LOCAL_POSITION_NED rate")
    f.add_argument("--stale-timeout", type=positive_float, metavar="S", help="telemetry age that triggers the failsafe (default 0.3)")
    f.add_argument("--force-budget", action="store_true", help="fly even when the serial link budget does not fit")
    f.add_argument("--sitl", choices=("realtime", "lockstep"), default="realtime",
                   help="built-in SITL timing when no port/connection is given (default realtime)")
    f.add_argument("--lockstep", action="store_true", help="the vehicle at --connect is a SITL in lockstep")
    f.add_argument("--seed", type=int, default=0, help="built-in SITL seed (default 0)")
    f.add_argument("--sitl-arg", action="append", default=[], metavar="ARG",
                   help="extra option for the built-in SITL, repeatable (e.g. --sitl-arg=--wind=2)")
    f.add_argument("--summary", metavar="FILE.json", help="write the end-of-flight summary here")
    f.add_argument("--quiet", "-q", action="store_true", help="only warnings, failsafes and the final table")


def _print(quiet: bool):
    def out(line: str) -> None:
        if quiet and not line.startswith(("[failsafe]", "[warning]", "[interrupt]", "[landed]")):
            return
        print(line, flush=True)
    return out


def cmd_fly(args: argparse.Namespace, format_table) -> int:
    config = load_config(args.config)
    fc = config.flight
    changes = {}
    if args.telemetry_rate is not None:
        changes["telemetry_rate_hz"] = args.telemetry_rate
    if args.stale_timeout is not None:
        changes["telemetry_stale_s"] = args.stale_timeout
    if args.output is not None:
        changes["output"] = args.output
    if changes:
        config = dataclasses.replace(config, flight=dataclasses.replace(fc, **changes))
        fc = config.flight
    key = read_signing_key(args.signing_key) if args.signing_key else None
    console = _print(args.quiet)
    budget_ok = True
    if args.port is not None:
        budget = compute_budget(control_streams(1.0 / config.experiment.ts_s, fc.telemetry_rate_hz, fc.output),
                                args.baud, signed=key is not None)
        if not budget.fits:
            print(format_budget(budget), file=sys.stderr)
            print("the 100 Hz exchange does not fit this link; configurations that fit:", file=sys.stderr)
            for fix in suggest_fixes(budget, 1.0 / config.experiment.ts_s, fc.output):
                print(f"  {fix}", file=sys.stderr)
            if not args.force_budget:
                print("refusing to fly (--force-budget overrides)", file=sys.stderr)
                return _finish(args, None, "preflight_refused", config, "link budget exceeded")
            budget_ok = True
            console("[warning] link budget exceeded; flying anyway (--force-budget)")
    sitl = None
    lockstep = args.lockstep
    try:
        if args.port is None and args.connect is None:
            lockstep = args.sitl == "lockstep"
            link = MavlinkLink("udpin:127.0.0.1:0", target_system=args.target_system,
                               target_component=args.target_component, signing_key=key)
            port = link.conn.port.getsockname()[1]
            sitl = EmbeddedSitl(port, lockstep=lockstep, seed=args.seed, extra_args=args.sitl_arg).start()
            link.alive_check = sitl.check_alive
            console(f"[link] built-in SITL ({'lockstep' if lockstep else 'real time'}) on udp 127.0.0.1:{port}")
        else:
            url = args.port if args.port is not None else args.connect
            link = MavlinkLink(url, baud=args.baud, target_system=args.target_system,
                               target_component=args.target_component, signing_key=key)
    except LinkError as exc:
        print(f"gcs: error: {exc}", file=sys.stderr)
        return _finish(args, None, "link_error", config, str(exc))
    interrupts = _Interrupts()
    try:
        with interrupts:
            flight = Flight(config, args.controller, link, None if lockstep else MonotonicClock(), console=console,
                            interrupts=interrupts)
            try:
                flight.preflight(budget_ok)
            except PreflightRefused as exc:
                console(f"[failsafe] preflight refused: {exc}")
                flight.restore_params()
                return _finish(args, None, "preflight_refused", config, str(exc), flight.events)
            except LinkError as exc:
                if sitl is not None:
                    sitl.check_alive()
                console(f"[failsafe] link error: {exc}")
                return _finish(args, None, "link_error", config, str(exc), flight.events)
            result = flight.fly()
            flight.restore_params()
    finally:
        link.close()
        if sitl is not None:
            sitl.stop()
    if result.metrics:
        table = {"results": {result.controller: {k: {"mean": v, "std": 0.0} for k, v in result.metrics.items()}}}
        print(format_table(table, f"{config.experiment.name}: {result.controller}, {result.duration_s:.2f} s flown, "
                                  f"exit {result.exit_reason}"))
    lp = result.loop
    print(f"loop: {lp['ticks']} ticks, {lp['deadline_misses']} deadline misses, jitter p99 {lp['jitter_p99_ms']:.3f} ms, "
          f"tick p99 {lp['tick_p99_ms']:.3f} ms; link: {result.link['received']} in, {result.link['sent']} out, "
          f"{result.link['bad_data']} bad, {result.link['other_system']} from other systems")
    return _finish(args, result, result.exit_reason, config)


def _finish(args, result: FlightResult | None, reason: str, config, detail: str = "", events=None) -> int:
    if result is None:
        doc = {"controller": args.controller, "config": config.source, "exit_reason": reason,
               "exit_code": EXIT_CODES[reason], "detail": detail, "duration_s": 0.0, "metrics": {},
               "loop": {"ticks": 0, "deadline_misses": 0, "jitter_p99_ms": 0.0, "tick_p99_ms": 0.0},
               "events": events or []}
    else:
        doc = result.to_json()
    if args.summary:
        try:
            Path(args.summary).write_text(json.dumps(doc, indent=1))
        except OSError as exc:
            print(f"gcs: error: cannot write summary {args.summary}: {exc.strerror or exc}", file=sys.stderr)
    if reason != "completed":
        print(f"gcs fly: {reason} (exit {EXIT_CODES[reason]})" + (f": {detail}" if detail else ""), file=sys.stderr)
    return EXIT_CODES[reason]

