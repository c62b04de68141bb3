"""Experiments, one module each, run by ``raf experiment NAME``.

An experiment module defines ``NAME``, ``HELP``, ``TARGETS``, ``add_arguments(parser)`` and
``run(args, out_dir: pathlib.Path | None) -> dict``; it writes its figures into ``out_dir`` when given,
and the command writes ``out_dir/results.json`` from the returned flat dict.
"""
from __future__ import annotations


def registry() -> dict:
    """``{NAME: module}`` of every module in this package."""
    import sys

    from ..registry import discover

    return discover(sys.modules[__name__])
