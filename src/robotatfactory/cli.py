"""``raf``: the one front door. Every subcommand is a module in :mod:`robotatfactory.commands`.

A command module defines ``NAME``, ``HELP``, ``add_arguments(parser)`` and ``run(args) -> int``; it
imports heavy libraries (MuJoCo, rospy, OpenCV) inside ``run`` so that ``raf --help`` stays fast.
"""
from __future__ import annotations

import argparse
import sys

from . import __version__


def _command_modules():
    from . import commands
    from .registry import discover

    return list(discover(commands).values())


def build_parser() -> argparse.ArgumentParser:
    from .field import DEFAULT_FIELD

    parser = argparse.ArgumentParser(
        prog="raf",
        description="robotatfactory: ROS 1 framework for the RobotAtFactory 4.0 competition on SimTwo "
                    "(with a MuJoCo stand-in simulator).",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"robotatfactory {__version__}")
    parser.add_argument("--field", default=DEFAULT_FIELD, metavar="NAME",
                        help="competition map: a shipped field name (rules2026, simtwo2022) or a field "
                             f".json file (default: {DEFAULT_FIELD})")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands")
    for mod in _command_modules():
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=getattr(mod, "DESCRIPTION", mod.HELP),
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 0
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        return 130
    except Exception as e:  # a clear message, not a traceback, for the errors users cause
        from .errors import UserError

        if isinstance(e, UserError):
            print(f"raf {args.command}: error: {e}", file=sys.stderr)
            return 2
        raise


if __name__ == "__main__":
    sys.exit(main())
