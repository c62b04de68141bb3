"""Discovering plug-in modules (commands, benchmarks, experiments): one module per entry, found by name."""
from __future__ import annotations

import argparse
import importlib
import pkgutil
from types import ModuleType


def discover(package: ModuleType) -> dict[str, ModuleType]:
    """``{module.NAME: module}`` for every public module of ``package``, sorted by ``(ORDER, NAME)``."""
    mods = []
    for info in pkgutil.iter_modules(package.__path__):
        if not info.name.startswith("_"):
            mods.append(importlib.import_module(f"{package.__name__}.{info.name}"))
    mods.sort(key=lambda m: (getattr(m, "ORDER", 50), m.NAME))
    return {m.NAME: m for m in mods}


def add_entry_parsers(parser: argparse.ArgumentParser, entries: dict[str, ModuleType], dest: str,
                      title: str, output_option: tuple[str, str, str]) -> None:
    """One sub-parser per entry (``raf bench NAME``, ``raf experiment NAME``) with the shared output option.

    ``output_option`` is ``(flag, metavar, help)``; the chosen module is stored as ``args._<dest>``.
    """
    sub = parser.add_subparsers(dest=dest, metavar="NAME", title=title)
    flag, metavar, help_ = output_option
    for name, mod in entries.items():
        p = sub.add_parser(name, help=mod.HELP, description=getattr(mod, "DESCRIPTION", mod.HELP))
        p.add_argument(flag, metavar=metavar, help=help_)
        mod.add_arguments(p)
        p.set_defaults(**{f"_{dest}": mod})
    parser.set_defaults(_parser=parser)
