"""``gcs fly`` on the command line: options -> a :class:`gcs.api.FlightSpec` -> :func:`gcs.api.fly` -> the
end-of-flight table, the summary file and the exit code."""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from gcs.api import DEFAULT_CONFIG, DEFAULT_RIG_CONFIG, FIRMWARE_SITLS, FlightSpec, fly
from gcs.cli.args import Parser, float_range, int_range, positive_float
from gcs.control import CONTROLLERS
from gcs.flight.context import Interrupts
from gcs.flight.result import EXIT_CODES, FlightResult
from gcs.link.endpoints import BadOutUrl, parse_out_url
from gcs.link.keys import read_signing_key
from gcs.log.foxglove_live import live_argument
from gcs.report import format_table
from gcs.vehicles.arducopter_sitl import ENV_VAR as ARDUCOPTER_ENV
from gcs.vehicles.px4_sitl import ENV_VAR as PX4_ENV
from gcs.vehicles.output import OUTPUTS
from quadrotor.errors import ConfigError

__all__ = ["add_fly_parser", "cmd_fly", "spec_from_args", "RIG_KINDS"]

RIG_KINDS = ("4dof",)


def add_fly_parser(sub) -> None:
    """``gcs fly``'s options (the fields of :class:`gcs.api.FlightSpec`)."""
    f = sub.add_parser(
        "fly", help="fly a vehicle (or the built-in SITL) with the paper's controllers at 100 Hz over MAVLink",
        description="Preflight, GUIDED_NOGPS, arm, the config's mission at 100 Hz, LAND, disarm. With neither "
                    "--port nor --connect it flies the built-in SITL on loopback. Exit codes: 0 completed, "
                    "2 bad config/option, 3 telemetry lost, 4 geofence, 5 interrupted (landed), 6 link error, "
                    "7 preflight refused, 8 immediate LAND (second Ctrl-C), 9 the vehicle left guided control, "
                    "10 unsafe command caught before the wire, 11 internal error, 12 telemetry too slow, "
                    "13 a fault past the vehicle's authority (landed).")
    f.add_argument("--controller", default="nlsoc", choices=CONTROLLERS, help="controller (default nlsoc)")
    f.add_argument("--config", default=None,
                   help=f"experiment config, path or bundled name (default {DEFAULT_CONFIG}; "
                        f"{DEFAULT_RIG_CONFIG} with --rig)")
    f.add_argument("--rig", choices=RIG_KINDS, default=None,
                   help="fly the paper's indoor 4-DOF rig over its XBee serial protocol instead of a MAVLink "
                        "autopilot (with no --port: the rig emulator)")
    where = f.add_mutually_exclusive_group()
    where.add_argument("--port", metavar="DEVICE", help="serial device of the telemetry radio, e.g. /dev/ttyUSB0")
    where.add_argument("--connect", metavar="URL",
                       help="pymavlink URL: udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT")
    f.add_argument("--baud", type=int_range(50, 20_000_000), default=None,
                   help="serial baud rate (default 57600; 115200 with --rig)")
    f.add_argument("--target-system", type=int_range(1, 255), default=1, help="vehicle system id, 1..255 (default 1)")
    f.add_argument("--target-component", type=int_range(1, 255), default=1,
                   help="vehicle component id, 1..255 (default 1)")
    f.add_argument("--signing-key", metavar="FILE",
                   help="MAVLink 2 signing key file (32 bytes, 64 hex digits or a passphrase)")
    f.add_argument("--output", choices=OUTPUTS, help="setpoint message (default: the config's [flight] output)")
    f.add_argument("--telemetry-rate", type=positive_float, metavar="HZ", help="ATTITUDE/LOCAL_POSITION_NED rate")
    f.add_argument("--stale-timeout", type=positive_float, metavar="S",
                   help="telemetry age that triggers the failsafe (default 0.3)")
    f.add_argument("--force-budget", action="store_true", help="fly even when the serial link budget does not fit")
    f.add_argument("--sitl", choices=("realtime", "lockstep", *FIRMWARE_SITLS), default="realtime",
                   help="the child vehicle when no port/connection is given: the built-in SITL in real time "
                        "(default) or lockstep, or a real firmware's SITL: 'arducopter' (ArduPilot's ArduCopter SITL; "
                        f"--arducopter PATH or ${ARDUCOPTER_ENV}) or 'px4' (PX4 SITL with SIH; --px4 PATH or "
                        f"${PX4_ENV})")
    f.add_argument("--arducopter", metavar="PATH", default=None,
                   help=f"the ArduCopter SITL binary or its directory (default ${ARDUCOPTER_ENV})")
    f.add_argument("--px4", metavar="PATH", default=None,
                   help=f"the PX4 SITL build: a folder with bin/px4 and etc/, its bin/px4, or a .tar.gz of it "
                        f"(default ${PX4_ENV})")
    f.add_argument("--speedup", type=float_range(0.1, 50.0), default=None, metavar="S",
                   help="a firmware SITL's speed-up (simulated s per wall s): started so with --sitl "
                        "arducopter/px4, or how a SITL at --connect was started; the flight then runs on the "
                        "vehicle's clock")
    f.add_argument("--ready-timeout", type=float_range(1.0, 3600.0), default=60.0, metavar="S",
                   help="vehicle seconds to wait for the vehicle to become ready (EKF, telemetry) and to accept "
                        "arming (default 60)")
    f.add_argument("--lockstep", action="store_true", help="the vehicle at --connect is a SITL in lockstep")
    f.add_argument("--seed", type=int_range(0, 2**32 - 1), default=0, help="built-in SITL seed (default 0)")
    f.add_argument("--sitl-arg", action="append", default=[], metavar="ARG",
                   help="extra option for the built-in SITL, repeatable (e.g. --sitl-arg=--wind=2)")
    f.add_argument("--duration", type=positive_float, metavar="SECONDS",
                   help="cut the config's mission at this time, then land (e.g. 120 for a short outdoor-altitude)")
    f.add_argument("--summary", metavar="FILE.json", help="write the end-of-flight summary here")
    g = f.add_mutually_exclusive_group()
    g.add_argument("--log", metavar="PATH",
                   help="MCAP flight log (default logs/<UTC time>_<controller>_<experiment>.mcap)")
    g.add_argument("--no-log", action="store_true", help="write no flight log")
    f.add_argument("--live", type=live_argument, metavar="HOST:PORT", default=None,
                   help="[HOST:]PORT: also serve the log's channels live on the Foxglove WebSocket protocol (HOST "
                        "default 127.0.0.1; open ws://HOST:PORT in Foxglove)")
    f.add_argument("--out", type=out_argument, action="append", default=[], metavar="URL",
                   help="another ground station, repeatable (as MAVProxy's --out): udpout:HOST:PORT, udpin:HOST:PORT, "
                        "tcpin:HOST:PORT or tcp:HOST:PORT; it gets the vehicle's traffic and its own goes to the "
                        "vehicle, except setpoints (dropped while gcs flies)")
    f.add_argument("--quiet", "-q", action="store_true", help="only warnings, failsafes and the final table")


def spec_from_args(args: argparse.Namespace, command_line: str = "") -> FlightSpec:
    """The :class:`FlightSpec` of parsed ``gcs fly`` options (``--signing-key`` read, ``--summary`` checked)."""
    check_output_paths(args)
    if args.rig is not None:
        for flag, given in (("--connect", args.connect), ("--signing-key", args.signing_key), ("--output", args.output),
                            ("--lockstep", args.lockstep or None)):
            if given is not None:
                raise ConfigError(flag, "",
                                  "not used with --rig (the rig takes CONTROL frames on a serial port: --port)")
    builtin = args.port is None and args.connect is None
    firmware = args.sitl if args.sitl in FIRMWARE_SITLS else None
    if firmware is not None and not builtin:
        raise ConfigError("--sitl", args.sitl, "starts the firmware as the child vehicle: not with --port/--connect")
    if args.arducopter is not None and firmware != "arducopter":
        raise ConfigError("--arducopter", args.arducopter, "only with --sitl arducopter")
    if args.px4 is not None and firmware != "px4":
        raise ConfigError("--px4", args.px4, "only with --sitl px4")
    return FlightSpec(
        controller=args.controller, config=args.config, vehicle="rig" if args.rig else "mavlink", port=args.port,
        connect=args.connect, baud=args.baud, lockstep=(args.sitl == "lockstep") if builtin else bool(args.lockstep),
        firmware=firmware,
        firmware_path=args.arducopter if firmware == "arducopter" else args.px4, speedup=args.speedup,
        ready_timeout_s=args.ready_timeout,
        seed=args.seed, sitl_args=tuple(args.sitl_arg), target_system=args.target_system,
        target_component=args.target_component,
        signing_key=read_signing_key(args.signing_key) if args.signing_key else None, output=args.output,
        telemetry_rate_hz=args.telemetry_rate, stale_timeout_s=args.stale_timeout, duration_s=args.duration,
        force_budget=args.force_budget, log=not args.no_log, log_path=args.log, live=args.live, out=tuple(args.out),
        metadata={"command_line": command_line} if command_line else {})


def out_argument(text: str) -> str:
    """The ``argparse`` type of ``--out``: the URL checked (a usage error otherwise), as given."""
    try:
        parse_out_url(text)
    except BadOutUrl as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: {exc.reason}") from None
    return text


def check_output_paths(args: argparse.Namespace) -> None:
    """``--summary``: its folder must exist and be writable (refused before anything flies, exit 2)."""
    if not args.summary:
        return
    folder = Path(args.summary).resolve().parent
    if not folder.is_dir():
        raise ConfigError("--summary", "", f"folder {str(folder)!r} does not exist")
    if not os.access(folder, os.W_OK):
        raise ConfigError("--summary", "", f"folder {str(folder)!r} is not writable")
    if Path(args.summary).is_dir():
        raise ConfigError("--summary", "", f"{args.summary!r} is a folder, not a file")


def _console(quiet: bool):
    def out(line: str) -> None:
        if quiet and not line.startswith(("[failsafe]", "[warning]", "[interrupt]", "[landed]")):
            return
        print(line, flush=True)
    return out


def cmd_fly(args: argparse.Namespace, argv: list[str] | None = None) -> int:
    """Run ``gcs fly``; the exit code."""
    spec = spec_from_args(args, " ".join(["gcs", *(argv or [])]))
    result = fly(spec, console=_console(args.quiet), interrupts=Interrupts(),
                 report=lambda text: print(text, file=sys.stderr))
    if result.log_path is not None and not args.quiet:
        print(f"log: {result.log_path}", file=sys.stderr)
    return report(args, result)


def report(args: argparse.Namespace, result: FlightResult) -> int:
    """The end-of-flight table and loop line, the summary file, the one-line reason; the exit code."""
    if result.loop.get("ticks"):
        if result.metrics:
            table = {"results": {result.controller: {k: {"mean": v, "std": 0.0} for k, v in result.metrics.items()}}}
            print(format_table(table, f"{result.experiment}: {result.controller}, {result.duration_s:.2f} s flown, "
                                      f"exit {result.exit_reason}"))
        lp, ln = result.loop, result.link
        print(f"loop: {lp['ticks']} ticks, {lp.get('deadline_misses', 0)} deadline misses, jitter p99 "
              f"{lp.get('jitter_p99_ms', 0.0):.3f} ms, tick p99 {lp.get('tick_p99_ms', 0.0):.3f} ms (logging p50 "
              f"{lp.get('log_p50_ms', 0.0) * 1000:.0f} us); link: {ln.get('received', 0)} in, {ln.get('sent', 0)} "
              f"out, {ln.get('bad_data', 0)} bad"
              + (f", {ln['other_system']} from other systems" if "other_system" in ln else ""))
    if args.summary:
        try:
            Path(args.summary).write_text(json.dumps(result.to_json(), indent=1))
        except OSError as exc:
            print(f"gcs: error: cannot write summary {args.summary}: {exc.strerror or exc}", file=sys.stderr)
    if result.exit_reason != "completed":
        detail = result.detail
        print(f"gcs fly: {result.exit_reason} (exit {EXIT_CODES[result.exit_reason]})"
              + (f": {detail}" if detail else ""), file=sys.stderr)
    return EXIT_CODES[result.exit_reason]


#: FlightSpec fields a campaign sets for each run itself (``--fly-arg`` may not change them).
PLANNED_FIELDS = ("controller", "config", "vehicle", "lockstep", "seed", "duration_s", "log", "log_path", "metadata")


def fly_overrides(extra_args: list[str]) -> dict:
    """The :class:`FlightSpec` fields that ``gcs fly`` options ``extra_args`` set (``gcs campaign --fly-arg``).

    Raises
    ------
    ConfigError
        An option that does not parse, or one the campaign sets for each run itself.
    """
    if not extra_args:
        return {}
    parser = Parser(prog="gcs fly")
    add_fly_parser(parser.add_subparsers(dest="command", parser_class=Parser))
    try:
        base = spec_from_args(parser.parse_args(["fly"]))
        given = spec_from_args(parser.parse_args(["fly", *extra_args]))
    except SystemExit:
        raise ConfigError("--fly-arg", "", f"not gcs fly options: {' '.join(extra_args)}") from None
    out = {f: getattr(given, f) for f in given.__dataclass_fields__ if getattr(given, f) != getattr(base, f)}
    clash = sorted(set(out) & set(PLANNED_FIELDS))
    if clash:
        raise ConfigError("--fly-arg", "", f"the campaign sets {', '.join(clash)} for each run itself")
    return out
