"""``raf demo``: the main demonstration, what the README's first command runs."""
from __future__ import annotations

import argparse
from pathlib import Path

NAME = "demo"
HELP = "the main demo: draws the field map and runs the localization experiment into --out (default out/demo)"
ORDER = 1


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="out/demo", metavar="DIR", help="where figures and results go")
    parser.add_argument("--quick", action="store_true", help="a shorter run (used by the test suite)")


def _stages():
    """(title, function(args, out_dir)) in order; later issues add the simulator, bridge and localization."""
    return [("field map", _field_map), ("protocol codec benchmark", _protocol),
            ("stand-in simulator snapshot", _snapshot),
            ("simulator + bridge + localization in the SimTwo-like mode: camera calibration drive, reference and second route (raf experiment localization)",
             _localization)]


def _field_map(args, out: Path) -> None:
    from ..field import load_field
    from ..field.draw import save_field_png

    print(f"  wrote {save_field_png(load_field(args.field), out / 'field.png')}")


def _protocol(args, out: Path) -> None:
    from ..bench import protocol
    from ..results import print_table, write_json

    ns = argparse.Namespace(seconds=0.2 if args.quick else 1.0, repeats=3)
    res = protocol.run(ns)
    print_table("  protocol", res, protocol.TARGETS)
    write_json(out / "protocol.json", res)


def _snapshot(args, out: Path) -> None:
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "robotatfactory", "--field", args.field, "sim", "--snapshot", str(out / "scene.png")]
    subprocess.run(cmd, check=True)


def _localization(args, out: Path) -> None:
    from ..commands.experiment import run as run_experiment
    from ..experiments import registry

    mod = registry()["localization"]
    parser = argparse.ArgumentParser()
    parser.add_argument("--out")
    mod.add_arguments(parser)
    argv = ["--out", str(out / "localization"), "--laps", "1"]
    if args.quick:
        argv += ["--no-rviz", "--no-tf-tree"]
    ns = parser.parse_args(argv)
    ns._experiment, ns.field = mod, args.field
    run_experiment(ns)


def run(args) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stages = _stages()
    for i, (title, fn) in enumerate(stages, 1):
        print(f"[{i}/{len(stages)}] {title}")
        fn(args, out)
    print(f"demo done: results in {out.resolve()}")
    return 0
