"""Benchmarks, one module each, run by ``raf bench NAME``.

A benchmark module defines ``NAME``, ``HELP``, ``TARGETS`` (``{result_key: "description of target"}``),
``add_arguments(parser)`` and ``run(args) -> dict``; the dict is flat, keys carry their units.
"""
from __future__ import annotations


def registry() -> dict:
    """``{NAME: module}`` of every module in this package."""
    import sys

    from ..registry import discover

    return discover(sys.modules[__name__])
