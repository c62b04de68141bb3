"""``raf experiment NAME``: run one experiment, print a table, --out DIR writes figures and results.json."""
from __future__ import annotations

import argparse
from pathlib import Path

NAME = "experiment"
HELP = "run an experiment (raf experiment --help lists them); --out DIR writes figures and results.json"
ORDER = 81


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..experiments import registry
    from ..registry import add_entry_parsers

    add_entry_parsers(parser, registry(), "experiment", "experiments",
                      ("--out", "DIR", "write figures and DIR/results.json here"))


def run(args) -> int:
    from ..results import print_table, write_json

    mod = getattr(args, "_experiment", None)
    if mod is None:
        args._parser.print_help()
        return 2
    out = Path(args.out) if args.out else None
    if out:
        out.mkdir(parents=True, exist_ok=True)
    results = dict(mod.run(args, out))
    print_table(f"raf experiment {mod.NAME}", results, getattr(mod, "TARGETS", {}))
    if out:
        print(f"wrote {write_json(out / 'results.json', results)}")
    failed = [k for k, ok in results.items() if k.endswith("_target_met") and ok is False]
    if failed:
        print(f"targets not met: {', '.join(failed)}")
    # an experiment whose targets are its pass/fail criterion says so (EXIT_STATUS_FROM_TARGETS): exit status 1
    return 1 if failed and getattr(mod, "EXIT_STATUS_FROM_TARGETS", False) else 0
