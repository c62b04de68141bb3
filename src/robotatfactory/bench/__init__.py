"""Benchmarks, one module each, run by ``raf bench NAME``.

A benchmark module defines ``NAME``, ``HELP``, ``TARGETS`` (``{result_key: "description of target"}``),
``add_arguments(parser)`` and ``run(args) -> dict``; the dict is flat, keys carry their units.
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
