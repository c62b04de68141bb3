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
        description="robotatfactory: ROS 1 and ROS 2 framework for the RobotAtFactory 4.0 competition on SimTwo "
                    "(with a MuJoCo stand-in simulator).",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"robotatfactory {__version__}")
    parser.add_argument("--field", default=DEFAULT_FIELD, metavar="NAME",
                        help="competition map: a shipped field name (rules2026, simtwo2022) or a field "
                             f".json file (default: {DEFAULT_FIELD})")
    parser.add_argument("--middleware", choices=("ros1", "ros2"), metavar="{ros1,ros2}",
                        help="the ROS generation the ROS commands run on: ros1 (Debian's ROS 1, .venv) or ros2 "
                             "(ROS 2 Jazzy from PyPI, .venv-ros2); default: $RAF_MIDDLEWARE, else the one this "
                             "Python has")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands")
    for mod in _command_modules():
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=getattr(mod, "DESCRIPTION", mod.HELP),
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def _switch_middleware(want: str, argv: list[str]) -> None:
    """Run this command line again with the Python environment of middleware ``want`` (the two cannot share
    one interpreter: both define std_msgs etc.), unless this Python already has it."""
    import os
    from pathlib import Path

    from .ros.mw import importable
    from .ros.processes import VENVS

    os.environ["RAF_MIDDLEWARE"] = want
    if importable(want):
        return
    root = Path(__file__).resolve().parents[2]
    venv = Path(os.environ.get("RAF_ROS2_VENV", root / VENVS["ros2"])) if want == "ros2" else root / VENVS["ros1"]
    py = venv / "bin" / "python"
    if not py.exists():
        print(f"raf: --middleware {want}: {py} does not exist; run scripts/bootstrap.sh (it builds both "
              "environments)", file=sys.stderr)
        raise SystemExit(2)
    os.execv(str(py), [str(py), "-m", "robotatfactory", *argv])


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    raw = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    if args.middleware:
        _switch_middleware(args.middleware, raw)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 0
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        return 130
    except Exception as e:  # a clear message, not a traceback, for the errors users cause
        if isinstance(e, user_errors()):
            print(f"raf {args.command}: error: {e}", file=sys.stderr)
            return 2
        raise


def user_errors() -> tuple[type[Exception], ...]:
    """The errors a user can cause (bad settings, unknown names, a missing file, SimTwo's build or run)."""
    from .errors import ConfigError
    from .field.loader import FieldError
    from .simtwo.errors import ProtocolError
    from .simtwo_linux.build import BuildError
    from .simtwo_linux.run import SimTwoError
    from .simtwo_linux.scene import SceneError

    return (FieldError, ProtocolError, ConfigError, FileNotFoundError, BuildError, SceneError, SimTwoError)


if __name__ == "__main__":
    sys.exit(main())
