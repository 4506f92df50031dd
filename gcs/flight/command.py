"""``gcs fly`` from the command line: arguments, link, optional built-in SITL, summary."""

from __future__ import annotations

import argparse
import json
import os
import sys
import traceback
from pathlib import Path

from gcs.config import load_config
from gcs.control import CONTROLLERS
from quadrotor.clock import MonotonicClock
from gcs.flight.embedded import EmbeddedSitl
from quadrotor.errors import ConfigError
from gcs.errors import LogError
from gcs.flight.fly import EXIT_CODES, Flight, FlightResult, PreflightRefused
from gcs.flight.loop import Interrupts
from gcs.flight.recorder import BYTES_PER_FLIGHT_TICK, FlightRecorder, utc_offset_ns
from gcs.flight.output import OUTPUTS
from gcs.link.budget import compute_budget, control_streams, format_budget, suggest_fixes
from gcs.link.mavlink import LinkError, MavlinkLink, read_signing_key

__all__ = ["add_fly_parser", "cmd_fly", "DEFAULT_FLY_CONFIG"]

DEFAULT_FLY_CONFIG = "outdoor-circle"
DEFAULT_RIG_CONFIG = "indoor-4dof"
RIG_KINDS = ("4dof",)


def add_fly_parser(sub, positive_int, positive_float) -> None:
    f = sub.add_parser(
        "fly", help="fly a vehicle (or the built-in SITL) with the paper's controllers at 100 Hz over MAVLink",
        description="Preflight, GUIDED_NOGPS, arm, the config's mission at 100 Hz, LAND, disarm. With neither "
                    "--port nor --connect it flies the built-in SITL on loopback. Exit codes: 0 completed, "
                    "2 bad config/option, 3 telemetry lost, 4 geofence, 5 interrupted (landed), 6 link error, "
                    "7 preflight refused, 8 immediate LAND (second Ctrl-C), 9 the vehicle left guided control, "
                    "10 unsafe command caught before the wire, 11 internal error, 12 telemetry too slow.")
    f.add_argument("--controller", default="nlsoc", choices=CONTROLLERS, help="controller (default nlsoc)")
    f.add_argument("--config", default=None,
                   help=f"experiment config, path or bundled name (default {DEFAULT_FLY_CONFIG}; "
                        f"{DEFAULT_RIG_CONFIG} with --rig)")
    f.add_argument("--rig", choices=RIG_KINDS, default=None,
                   help="fly the paper's indoor 4-DOF rig over its XBee serial protocol instead of a MAVLink "
                        "autopilot (with no --port: the rig emulator)")
    where = f.add_mutually_exclusive_group()
    where.add_argument("--port", metavar="DEVICE", help="serial device of the telemetry radio, e.g. /dev/ttyUSB0")
    where.add_argument("--connect", metavar="URL", help="pymavlink URL: udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT")
    f.add_argument("--baud", type=int_range(50, 20_000_000), default=None,
                   help="serial baud rate (default 57600; 115200 with --rig)")
    f.add_argument("--target-system", type=int_range(1, 255), default=1, help="vehicle system id, 1..255 (default 1)")
    f.add_argument("--target-component", type=int_range(1, 255), default=1,
                   help="vehicle component id, 1..255 (default 1)")
    f.add_argument("--signing-key", metavar="FILE", help="MAVLink 2 signing key file (32 bytes, 64 hex digits or a passphrase)")
    f.add_argument("--output", choices=OUTPUTS, help="setpoint message (default: the config's [flight] output)")
    f.add_argument("--telemetry-rate", type=positive_float, metavar="HZ", help="ATTITUDE/LOCAL_POSITION_NED rate")
    f.add_argument("--stale-timeout", type=positive_float, metavar="S", help="telemetry age that triggers the failsafe (default 0.3)")
    f.add_argument("--force-budget", action="store_true", help="fly even when the serial link budget does not fit")
    f.add_argument("--sitl", choices=("realtime", "lockstep"), default="realtime",
                   help="built-in SITL timing when no port/connection is given (default realtime)")
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
    f.add_argument("--quiet", "-q", action="store_true", help="only warnings, failsafes and the final table")


def int_range(lo: int, hi: int):
    """An argparse type: a whole number in ``lo..hi``."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"must be in {lo}..{hi}, got {v}")
        return v
    return parse


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


def _print(quiet: bool):
    def out(line: str) -> None:
        if quiet and not line.startswith(("[failsafe]", "[warning]", "[interrupt]", "[landed]")):
            return
        print(line, flush=True)
    return out


def _config_for(args: argparse.Namespace):
    """The config as flown: the file plus the command line's overrides (recorded in its raw
    document, so the log's config.json is what flew)."""
    config = load_config(args.config or (DEFAULT_RIG_CONFIG if args.rig else DEFAULT_FLY_CONFIG))
    changes = {}
    if args.telemetry_rate is not None:
        changes["telemetry_rate_hz"] = args.telemetry_rate
    if args.stale_timeout is not None:
        changes["telemetry_stale_s"] = args.stale_timeout
    if args.output is not None:
        changes["output"] = args.output
    if changes:
        config = config.with_changes("flight", **changes)
    if args.duration is not None:
        config = config.with_duration(args.duration)
    return config


def open_flight_log(args: argparse.Namespace, config, controller_name: str, *, vehicle: str,
                    extra_metadata: dict | None = None) -> FlightRecorder:
    """The flight's recorder: checks the log path and the free space before anything flies.

    Raises
    ------
    PreflightRefused
        The log cannot be written there (unwritable directory, full disk).
    """
    if getattr(args, "no_log", False):
        return FlightRecorder(None)
    from gcs.control import make_controller
    from gcs.log.cli import default_log_path
    from gcs.log.flightlog import BackgroundFlightLog
    from gcs.log.meta import run_attachments, run_metadata
    from gcs.mission import Mission

    path = Path(args.log) if args.log else default_log_path(controller_name, config.experiment.name)
    ticks = int(Mission(config.mission).duration_s / config.experiment.ts_s) + 6000  # + preflight and landing
    try:
        log = BackgroundFlightLog(path, expected_bytes=ticks * BYTES_PER_FLIGHT_TICK)
    except LogError as exc:
        raise PreflightRefused(f"{exc} (--log PATH writes elsewhere, --no-log writes none)") from None
    rec = FlightRecorder(log)
    md = dict(extra_metadata or {})
    md.update(vehicle=vehicle, time_base="vehicle time since boot (lockstep)" if _lockstep(args)
              else "UTC (the loop's monotonic clock plus a fixed offset)")
    rec.header(run_metadata(config, [controller_name], source="flight", **md),
               run_attachments(config, {controller_name: make_controller(controller_name, config)}))
    return rec


def _lockstep(args: argparse.Namespace) -> bool:
    builtin = args.port is None and args.connect is None
    return (args.sitl == "lockstep") if builtin else bool(args.lockstep)


def cmd_fly(args: argparse.Namespace, format_table) -> int:
    check_output_paths(args)
    if args.rig is not None:
        return _cmd_fly_rig(args, format_table)
    if args.baud is None:
        args.baud = 57600
    config = _config_for(args)
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
    return _logged(args, config, "mavlink", lambda rec: _fly_mavlink(args, config, key, console, budget_ok, rec,
                                                                    format_table))


def _logged(args: argparse.Namespace, config, vehicle: str, fly) -> int:
    """Open the flight log (refused before anything flies if it cannot be written), run ``fly(recorder)``,
    finish the log whatever happens."""
    try:
        recorder = open_flight_log(args, config, args.controller, vehicle=vehicle)
    except PreflightRefused as exc:
        return _finish(args, None, "preflight_refused", config, str(exc))
    try:
        return fly(recorder)
    finally:
        recorder.close()
        if recorder.path is not None and not args.quiet:
            print(f"log: {recorder.path}", file=sys.stderr)


def _fly_mavlink(args, config, key, console, budget_ok, recorder, format_table) -> int:
    sitl = None
    lockstep = _lockstep(args)
    try:
        if args.port is None and args.connect is None:
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
        recorder.event(0, "failsafe", f"link error: {exc}")
        return _finish(args, None, "link_error", config, str(exc))
    return _fly(args, config, Flight, link, sitl, lockstep, recorder, console, format_table, budget_ok=budget_ok)


def _fly(args, config, flight_class, link, child, lockstep: bool, recorder, console, format_table,
         **preflight_kwargs) -> int:
    """Preflight and fly ``flight_class`` over ``link``; the link and the child simulator (if any) end with it.

    Whatever happens after the flight object exists — a refusal, a link failure, an exception
    anywhere — the vehicle is disarmed on the ground or landed, the parameters changed for the
    flight are restored and then the summary is written.
    """
    interrupts = Interrupts()
    clock = None if lockstep else MonotonicClock()
    if clock is not None:
        recorder.offset_ns = utc_offset_ns(clock.now_ns())
    flight = None
    result: FlightResult | None = None
    failure: tuple[str, str] | None = None
    try:
        with interrupts:
            flight = flight_class(config, args.controller, link, clock, console=console, interrupts=interrupts,
                                  recorder=recorder)
            if child is not None:
                flight.vehicle_alive = child.exit_reason
            try:
                flight.preflight(**preflight_kwargs)
            except PreflightRefused as exc:
                flight.event("failsafe", f"preflight refused: {exc}")
                flight.disarm_on_ground()
                failure = ("preflight_refused", str(exc))
            except LinkError as exc:
                why = (child.exit_reason() if child is not None else None) or str(exc)
                flight.event("failsafe", f"link error: {why}")
                flight.disarm_on_ground()
                failure = ("link_error", why)
            else:
                result = flight.fly()
            flight.restore_params()
    except Exception as exc:  # noqa: BLE001 - outside the mission loop's own net: land, restore, report
        why = f"{type(exc).__name__}: {exc}"
        print(f"gcs: internal error: {why}", file=sys.stderr)
        failure, result = ("internal_error", why), None
        if flight is not None:
            _last_resort(flight, why)
    finally:
        link.close()
        if child is not None:
            child.stop()
    if failure is not None:
        return _finish(args, None, failure[0], config, failure[1], flight.events if flight is not None else None)
    return _report(args, result, config, format_table)


def _last_resort(flight, why: str) -> None:
    """An exception escaped the flight: land (or disarm on the ground) and restore, each step on its own."""
    flight.event("failsafe", f"internal error ({why}): landing", traceback=traceback.format_exc())
    for step in (flight.emergency_land, flight.restore_params):
        try:
            step()
        except Exception as exc:  # noqa: BLE001 - each last-resort step is tried whatever the others did
            flight.event("failsafe", f"{step.__name__} failed: {type(exc).__name__}: {exc}")


def _cmd_fly_rig(args: argparse.Namespace, format_table) -> int:
    """``gcs fly --rig 4dof``: the rig on ``--port`` at ``--baud`` (115200), or its emulator."""
    from gcs.errors import ConfigError
    from gcs.link.rig import rig_link_budget

    for flag, given in (("--connect", args.connect), ("--signing-key", args.signing_key), ("--output", args.output),
                        ("--lockstep", args.lockstep or None)):
        if given is not None:
            raise ConfigError(flag, "", "not used with --rig (the rig takes CONTROL frames on a serial port: --port)")
    baud = args.baud if args.baud is not None else 115200
    config = _config_for(args)
    console = _print(args.quiet)
    if args.port is not None:
        b = rig_link_budget(baud, 1.0 / config.experiment.ts_s)
        share = max(b["down_share"], b["up_share"])
        if share > 0.8:
            print(f"rig link at {baud} baud: telemetry {b['down_b_s']:.0f} B/s ({b['down_share']:.0%}), control "
                  f"{b['up_b_s']:.0f} B/s ({b['up_share']:.0%}) of {b['capacity_b_s']:.0f} B/s; 115200 baud fits",
                  file=sys.stderr)
            if not args.force_budget:
                print("refusing to fly (--force-budget overrides)", file=sys.stderr)
                return _finish(args, None, "preflight_refused", config, "link budget exceeded")
            console("[warning] link budget exceeded; flying anyway (--force-budget)")
    return _logged(args, config, f"rig {args.rig}", lambda rec: _fly_rig(args, config, baud, console, rec,
                                                                        format_table))


def _fly_rig(args, config, baud: int, console, recorder, format_table) -> int:
    from gcs.flight.embedded import EmbeddedRig
    from gcs.flight.rig import RigFlight
    from gcs.link.rig import RigLink

    rig = None
    lockstep = args.port is None and args.sitl == "lockstep"
    try:
        if args.port is None:
            # Lockstep runs without the emulated baud limit (as fast as it computes) unless asked.
            rig = EmbeddedRig(lockstep=lockstep, seed=args.seed, baud=0 if lockstep else baud,
                              extra_args=args.sitl_arg).start()
            console(f"[link] rig emulator ({'lockstep' if lockstep else 'real time'}) on {rig.device}")
        link = RigLink(rig.device if rig is not None else args.port, baud)
    except LinkError as exc:
        print(f"gcs: error: {exc}", file=sys.stderr)
        if rig is not None:
            rig.stop()
        return _finish(args, None, "link_error", config, str(exc))
    return _fly(args, config, RigFlight, link, rig, lockstep, recorder, console, format_table)


def _report(args, result: FlightResult, config, format_table) -> int:
    if result.metrics:
        table = {"results": {result.controller: {k: {"mean": v, "std": 0.0} for k, v in result.metrics.items()}}}
        print(format_table(table, f"{config.experiment.name}: {result.controller}, {result.duration_s:.2f} s flown, "
                                  f"exit {result.exit_reason}"))
    lp = result.loop
    ln = result.link
    print(f"loop: {lp['ticks']} ticks, {lp['deadline_misses']} deadline misses, jitter p99 {lp['jitter_p99_ms']:.3f} ms, "
          f"tick p99 {lp['tick_p99_ms']:.3f} ms (logging p50 {lp.get('log_p50_ms', 0.0) * 1000:.0f} us); "
          f"link: {ln.get('received', 0)} in, {ln.get('sent', 0)} out, {ln.get('bad_data', 0)} bad"
          + (f", {ln['other_system']} from other systems" if "other_system" in ln else ""))
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

