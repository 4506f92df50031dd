"""The ``gcs`` command line: one parser, one subcommand module each, errors as one line.

``gcs sim | configs | fly | log | campaign | link-budget``.  Errors the user can cause print
one line ``gcs: error: ...`` and exit with their code (2 for a bad config or option); no
traceback.  Each subcommand builds its inputs and calls the Python API (:mod:`gcs.api`).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from gcs import __version__
from gcs.cli.args import Parser
from gcs.cli.budget import add_budget_parser, cmd_link_budget
from gcs.cli.campaign import add_campaign_parser, cmd_campaign
from gcs.cli.fly import add_fly_parser, cmd_fly
from gcs.cli.sim import add_sim_log_arguments, add_sim_parser, cmd_configs, cmd_sim, open_sim_log
from gcs.log.review.cli import add_log_parser, cmd_log
from quadrotor.errors import QuadrotorError

__all__ = ["main", "build_parser"]


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="gcs",
               description="Ground-station flight controller for quadrotors: the paper's NLSOC, LOC and PD.")
    p.add_argument("--version", action="version", version=f"gcs {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    add_sim_log_arguments(add_sim_parser(sub))
    sub.add_parser("configs", help="list the bundled experiment configs")
    add_log_parser(sub)
    add_fly_parser(sub)
    add_campaign_parser(sub)
    add_budget_parser(sub)
    return p


def _run(args: argparse.Namespace, argv: list[str]) -> int:
    if args.command == "sim":
        return cmd_sim(args, open_sim_log)
    if args.command == "fly":
        return cmd_fly(args, argv)
    if args.command == "link-budget":
        return cmd_link_budget(args)
    if args.command == "campaign":
        return cmd_campaign(args, argv)
    if args.command == "log":
        return cmd_log(args)
    if args.command == "configs":
        return cmd_configs()
    return -1


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``gcs`` console script."""
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    try:
        code = _run(args, argv)
        if code == -1:
            parser.print_help()
            return 2
        return code
    except QuadrotorError as exc:
        print(f"gcs: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("gcs: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (e.g. `gcs sim | head`): not an error of ours.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
