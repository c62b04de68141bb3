"""Printing benchmark and experiment results as a table and writing them as flat JSON.

Keys carry their units (``decode_frames_per_s``, ``ekf_position_rmse_m``); values are numbers, strings
or booleans, never nested.
"""
from __future__ import annotations

import json
import math
import platform
from pathlib import Path
from typing import Mapping


def flat(results: Mapping) -> dict:
    out = {}
    for k, v in results.items():
        if isinstance(v, (bool, str)) or v is None:
            out[k] = v
        elif isinstance(v, (int, float)):
            out[k] = float(v) if isinstance(v, float) else int(v)
            if isinstance(v, float) and not math.isfinite(v):
                out[k] = None
        elif hasattr(v, "item"):  # numpy scalar
            out[k] = v.item()
        else:
            raise TypeError(f"result {k!r} is {type(v).__name__}; results are flat numbers/strings")
    return out


def print_table(title: str, results: Mapping, targets: Mapping[str, str] | None = None) -> None:
    targets = targets or {}
    rows = [(k, _fmt(v), targets.get(k, "")) for k, v in results.items()]
    w0 = max([len(r[0]) for r in rows] + [6])
    w1 = max([len(r[1]) for r in rows] + [5])
    print(title)
    print(f"{'metric':<{w0}}  {'value':>{w1}}  target")
    print(f"{'-' * w0}  {'-' * w1}  ------")
    for k, v, t in rows:
        print(f"{k:<{w0}}  {v:>{w1}}  {t}")


MAX_SHOWN = 72  # characters of a string value the table shows (the JSON keeps it whole)


def _fmt(v) -> str:
    if isinstance(v, str) and len(v) > MAX_SHOWN:
        return f"{v[:MAX_SHOWN - 20]}... ({len(v)} chars)"
    if isinstance(v, bool) or v is None or isinstance(v, str):
        return str(v)
    if isinstance(v, int):
        return f"{v:d}"
    if v == 0 or 1e-3 <= abs(v) < 1e6:
        return f"{v:.4g}" if abs(v) < 1 else f"{v:,.2f}" if abs(v) < 1000 else f"{v:,.0f}"
    return f"{v:.3e}"


def machine_info() -> dict:
    import os

    return {"machine": platform.machine(), "python": platform.python_version(), "cpu_count": os.cpu_count()}


def write_json(path: str | Path, results: Mapping) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(flat(results), indent=1, sort_keys=False) + "\n")
    return path
