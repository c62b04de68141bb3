"""The options of an experiment (``raf experiment NAME``) as its own parser defaults them, for tests."""
from __future__ import annotations

import argparse


def options(module, field: str | None = "rules2026", **kw) -> argparse.Namespace:
    """``module``'s options (its ``add_arguments``) with their defaults, the global ``--field`` (``field``) and
    ``kw`` set over them."""
    p = argparse.ArgumentParser()
    module.add_arguments(p)
    a = p.parse_args([])
    a.field = field
    for k, v in kw.items():
        setattr(a, k, v)
    return a
