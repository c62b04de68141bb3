"""``raf bench NAME``: run one benchmark, print a table, optionally write a flat JSON result."""
from __future__ import annotations

import argparse

NAME = "bench"
HELP = "run a benchmark (raf bench --help lists them); prints a table, --json FILE writes the figures"
ORDER = 80


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..bench import registry
    from ..registry import add_entry_parsers

    add_entry_parsers(parser, registry(), "bench", "benchmarks",
                      ("--json", "FILE", "write the results as a flat JSON object"))


def run(args) -> int:
    from ..results import machine_info, print_table, write_json

    mod = getattr(args, "_bench", None)
    if mod is None:
        args._parser.print_help()
        return 2
    results = dict(mod.run(args))
    results.update({k: v for k, v in machine_info().items() if k not in results})
    print_table(f"raf bench {mod.NAME}", results, getattr(mod, "TARGETS", {}))
    if args.json:
        print(f"wrote {write_json(args.json, results)}")
    return 0
