"""``gcs`` command line.

Subcommands:

* ``gcs sim``: fly the paper's controllers on the in-process simulation and print
  a table like the paper's Tables 1, 2 and 4 (``--json`` for machines).
* ``gcs configs``: list the bundled experiment configs.
* ``gcs campaign``: the paper's experiments through ``gcs fly``, in parallel (:mod:`gcs.campaign`).
* ``gcs link-budget``: MAVLink 2 bytes per second each way over a serial link
  (exit 1 when it does not fit, with configurations that do).

Errors the user can cause print one line ``gcs: error: ...`` and exit non-zero
(2 for a bad config or option); no traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Sequence

from gcs import __version__
from gcs.config import MATRIX_MODES, bundled_configs, load_config
from gcs.control import CONTROLLERS
from quadrotor.errors import ConfigError, QuadrotorError
from gcs.metrics import METRICS

__all__ = ["main", "build_parser", "format_table"]

DEFAULT_CONFIG = "outdoor-altitude"

METRIC_LABELS = {
    "J": "J (eq. 5 / eq. 17)",
    "J_u": "J_u = sum|u| [N]",
    "J_u_hover": "J_u_hover = sum|u - mg| [N]",
    "J_u_all": "J_u_all (u, tau_phi, tau_theta, tau_psi)",
    "J_e": "J_e = sum||e|| vs reference",
    "J_e_setpoint": "J_e vs final set point",
    "steady_state_error_m": "steady-state error [m]",
    "overshoot_m": "overshoot [m]",
    "rms_error_m": "RMS position error [m]",
}


def _int_at_least(minimum: int):
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if v < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum}, got {v}")
        return v
    return parse


_positive_int = _int_at_least(1)
_nonneg_int = _int_at_least(0)


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not v > 0 or v != v or v == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return v


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # argparse's own usage errors: exit 2, one line
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="gcs", description="Ground-station flight controller for quadrotors: the paper's NLSOC, LOC and PD.")
    p.add_argument("--version", action="version", version=f"gcs {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    s = sub.add_parser("sim", help="closed-loop in-process simulation of the paper's experiments",
                       description="Fly the controllers on the reduced plant (RK4 at 1 ms, zero-order hold over "
                                   "the 10 ms control period) and print the paper's metrics, mean and standard "
                                   "deviation over runs.")
    s.add_argument("--config", default=DEFAULT_CONFIG,
                   help=f"experiment config: a TOML path or a bundled name ({', '.join(bundled_configs())}); "
                        f"default {DEFAULT_CONFIG}")
    s.add_argument("--controller", default="all", choices=CONTROLLERS + ("all",),
                   help="controller to fly, or all of them (default all)")
    s.add_argument("--runs", type=_positive_int, help="runs per controller (default: the config's sim.runs)")
    s.add_argument("--seed", type=_nonneg_int, help="base seed (default: the config's sim.seed)")
    s.add_argument("--duration", type=_positive_float, metavar="SECONDS",
                   help="simulated seconds per run (default: the config's experiment.duration_s)")
    s.add_argument("--matrices", choices=MATRIX_MODES,
                   help="fly the corrected or the literal printed matrices (default: the config's)")
    wind = s.add_mutually_exclusive_group()
    wind.add_argument("--wind", dest="wind", action="store_true", default=None, help="blow the config's wind")
    wind.add_argument("--no-wind", dest="wind", action="store_false", help="calm air")
    s.add_argument("--no-noise", action="store_true", help="ideal sensors: feed the true state back")
    s.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    s.add_argument("--quiet", "-q", action="store_true", help="no progress on stderr")
    from gcs.log.cli import add_log_parser, add_sim_log_arguments
    add_sim_log_arguments(s)

    sub.add_parser("configs", help="list the bundled experiment configs")

    add_log_parser(sub)

    from gcs.flight.command import add_fly_parser
    add_fly_parser(sub, _positive_int, _positive_float)

    from gcs.campaign.cli import add_campaign_parser
    add_campaign_parser(sub)

    b = sub.add_parser("link-budget", help="bytes per second each way of the 100 Hz exchange over a serial link",
                       description="Compute the MAVLink 2 link budget of the control exchange at a baud rate: "
                                   "telemetry down, setpoints up, housekeeping both ways.")
    b.add_argument("--baud", type=_positive_int, default=57600, help="serial baud rate, 8N1 (default 57600)")
    b.add_argument("--rate", type=_positive_float, default=100.0, help="control rate [Hz] (default 100)")
    b.add_argument("--telemetry-rate", type=_positive_float, help="ATTITUDE/LOCAL_POSITION_NED rate [Hz] (default: --rate)")
    b.add_argument("--output", choices=("attitude", "rates", "actuator"), default="attitude",
                   help="setpoint message (SET_ATTITUDE_TARGET or SET_ACTUATOR_CONTROL_TARGET)")
    b.add_argument("--signed", action="store_true", help="MAVLink 2 signing (+13 bytes a frame)")
    b.add_argument("--air-rate", type=_positive_float, metavar="BPS",
                   help="telemetry radio air data rate [bit/s] (half duplex, shared by both directions)")
    b.add_argument("--ecc", action="store_true", help="radio error correction on (halves the air throughput)")
    b.add_argument("--max-utilisation", type=_positive_float, default=0.8, help="largest usable share (default 0.8)")
    return p


def format_table(result: dict, title: str) -> str:
    """A metrics table: one row per metric, one column per controller, 'mean ± std'."""
    results = result["results"]
    names = list(results)
    keys = [k for k in METRICS if any(k in results[n] for n in names)]
    cells = [[METRIC_LABELS.get(k, k)] for k in keys]
    for row, key in zip(cells, keys):
        for n in names:
            m = results[n].get(key)
            row.append("-" if m is None else f"{m['mean']:.4g} ± {m['std']:.2g}")
    header = ["metric"] + names
    widths = [max(len(r[i]) for r in cells + [header]) for i in range(len(header))]
    line = lambda r: "  ".join(c.ljust(widths[0]) if i == 0 else c.rjust(widths[i]) for i, c in enumerate(r))
    out = [title, line(header), "  ".join("-" * w for w in widths)]
    out += [line(r) for r in cells]
    return "\n".join(out)


def _cmd_sim(args: argparse.Namespace) -> int:
    from gcs.sim import SimOptions, check_run, run_experiment

    config = load_config(args.config)
    if args.matrices is not None and args.matrices != config.experiment.matrices:
        config = config.with_matrices(args.matrices)
    controllers = list(CONTROLLERS) if args.controller == "all" else [args.controller]
    options = SimOptions(duration_s=args.duration, wind=args.wind, noise=not args.no_noise)
    check_run(config, args.runs, options)  # before the log is sized: a clear refusal, exit 2

    def progress(name: str, i: int, n: int) -> None:
        print(f"\r  flying {name:<14} run {i + 1}/{n}", end="", file=sys.stderr, flush=True)

    from gcs.log.cli import open_sim_log
    with open_sim_log(args, config, controllers, options) as log:
        result = run_experiment(config, controllers, runs=args.runs, seed=args.seed, options=options,
                                progress=None if (args.quiet or args.json or not sys.stderr.isatty()) else progress,
                                log=log)
    if not (args.quiet or args.json or not sys.stderr.isatty()):
        print("\r" + " " * 40 + "\r", end="", file=sys.stderr, flush=True)
    doc = result.to_json()
    if args.json:
        print(json.dumps(doc))
        return 0
    e = config.experiment
    blow = config.sim.wind_enabled if args.wind is None else args.wind
    w = config.sim.wind
    wind = f"wind {w.mean_speed_m_s:g} m/s + gusts {w.gust_std_m_s:g} m/s" if blow else "wind off"
    sensors = "ideal" if (args.no_noise or config.sim.sensors.is_ideal) else config.sim.sensors.altitude
    title = (f"{e.name}: {result.runs} run(s) x {result.duration_s:g} s, Ts = {e.ts_s * 1000:g} ms, "
             f"horizon {e.horizon_s:g} s then {e.after_horizon}, matrices {e.matrices}, "
             f"{wind}, sensors {sensors}")
    print(format_table(doc, title))
    return 0


def _cmd_link_budget(args: argparse.Namespace) -> int:
    from gcs.link.budget import compute_budget, control_streams, format_budget, suggest_fixes

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


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``gcs`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.command == "sim":
            return _cmd_sim(args)
        if args.command == "fly":
            from gcs.flight.command import cmd_fly
            return cmd_fly(args, format_table)
        if args.command == "link-budget":
            return _cmd_link_budget(args)
        if args.command == "campaign":
            from gcs.campaign.cli import cmd_campaign
            return cmd_campaign(args, list(sys.argv[1:] if argv is None else argv))
        if args.command == "log":
            from gcs.log.cli import cmd_log
            return cmd_log(args)
        if args.command == "configs":
            for name in bundled_configs():
                print(f"{name:20s} {load_config(name).experiment.description}")
            return 0
        parser.print_help()
        return 2
    except QuadrotorError as exc:
        print(f"gcs: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("gcs: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (e.g. `gcs sim | head`): not an error of ours.
        import os
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
