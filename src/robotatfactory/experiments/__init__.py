"""Experiments, one module each, run by ``raf experiment NAME``.

An experiment module defines ``NAME``, ``HELP``, ``TARGETS``, ``add_arguments(parser)`` and
``run(args, out_dir: pathlib.Path | None) -> dict``; it writes its figures into ``out_dir`` when given,
and the command writes ``out_dir/results.json`` from the returned flat dict.
"""
from __future__ import annotations

import importlib
import pkgutil


def registry() -> dict:
    mods = {}
    for info in pkgutil.iter_modules(__path__):
        if not info.name.startswith("_"):
            mod = importlib.import_module(f"{__name__}.{info.name}")
            mods[mod.NAME] = mod
    return dict(sorted(mods.items()))
