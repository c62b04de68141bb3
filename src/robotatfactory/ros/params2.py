"""The nodes' parameter files in ROS 2's format (``config/ros2/*.yaml``), generated from the ROS 1 files.

One source of truth: ``config/bridge.yaml`` and ``config/localization.yaml`` (ROS 1's ``rosparam`` shape, read
by ``raf bridge``/``raf localize`` on both middlewares) hold the values; this module writes the same values
as a ROS 2 parameter file for ``ros2 launch`` / ``ros2 run ... --ros-args --params-file``::

    /**/raf_bridge:            # the node raf_bridge in any namespace (robot1/raf_bridge too)
      ros__parameters:
        diagnostics:
          period: 1.0          # ROS 2 flattens nested keys with dots: the parameter diagnostics.period

Every leaf of the node's defaults is written (what ``node.params(defaults)`` declares), each value with the
type of its default (ROS 2 parameters keep the type they are declared with: a real written ``60`` would be
an integer and rejected, so it is written ``60.0``), strings quoted (so ``none`` or ``true``-like words stay
strings), and the ROS 1 file's end-of-line comment beside it. Plain Python (PyYAML only): no ROS import
until a node's defaults are asked for (the localization's live in its node module).

    python -m robotatfactory.ros.params2 bridge          # print one file
    python -m robotatfactory.ros.params2 --write         # regenerate config/ros2/*.yaml
    python -m robotatfactory.ros.params2 --check         # exit 1 when a committed file is out of date
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from .mw.base import flatten, typed_like

ROOT = Path(__file__).resolve().parents[3]
OUT_DIR = ROOT / "config" / "ros2"


def _bridge_defaults() -> dict:
    from .config import default_params

    return default_params()


def _agent_defaults() -> dict:
    from .agent_node import default_params

    return default_params()


def _localization_defaults() -> dict:
    from .localization_node import default_params

    return default_params()


@dataclass(frozen=True)
class NodeFile:
    """One node's parameter file: the ROS 1 source, the node name, where the defaults come from."""

    kind: str  # bridge | localization
    node: str  # the node's default name (the launch files' and raf's)
    source: Path  # the ROS 1 file (rosparam shape)
    defaults: Callable[[], dict]

    @property
    def target(self) -> Path:
        return OUT_DIR / f"{self.kind}.yaml"


NODES = {
    "bridge": NodeFile("bridge", "raf_bridge", ROOT / "config" / "bridge.yaml", _bridge_defaults),
    "localization": NodeFile("localization", "raf_localization", ROOT / "config" / "localization.yaml",
                             _localization_defaults),
    "agent": NodeFile("agent", "raf_agent", ROOT / "config" / "agent.yaml", _agent_defaults),
}


def merged(defaults: dict, values: dict, path: str = "") -> dict:
    """Every leaf of ``defaults``, with the value ``values`` gives where it gives one (typed like the
    default: :func:`.mw.base.typed_like`). A key of ``values`` that the defaults lack is kept too (the node decides whether it knows it:
    the bridge rejects it, the localization's ``detector/extra`` takes any), but an empty mapping (the
    localization's ``detector/extra: {}``): it names no parameter."""
    out: dict = {}
    for k, d in defaults.items():
        if isinstance(d, dict) and d:
            v = values.get(k, {})
            if not isinstance(v, dict):
                from ..errors import ConfigError

                raise ConfigError(f"{path}{k} is a section in the node's defaults, got {v!r}")
            out[k] = merged(d, v, f"{path}{k}/")
        else:
            out[k] = typed_like(values[k], d) if k in values else d
    for k, v in values.items():
        if k not in defaults and v != {}:
            out[k] = v
    return out


def tree(kind: str) -> dict:
    """The parameter tree (nested) of a node's ROS 2 file: its defaults with the ROS 1 file's values."""
    from ..settings import read_yaml

    nf = NODES[kind]
    return merged(nf.defaults(), read_yaml(nf.source, f"{nf.kind} parameters"))


def scalar(v) -> str:
    """One value as ROS 2's YAML parser reads it with the right type: strings double-quoted, reals always
    with a decimal point (``1.0e-09``: PyYAML and rcl both read that as a real), lists in flow style."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return ".nan"
        if math.isinf(v):
            return ".inf" if v > 0 else "-.inf"
        s = repr(v)
        if "e" in s and "." not in s.split("e")[0]:
            mant, exp = s.split("e")
            s = f"{mant}.0e{exp if exp[0] in '+-' else '+' + exp}"
        return s
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(scalar(x) for x in v) + "]"
    if v is None:
        return "null"
    raise TypeError(f"cannot write {v!r} as a ROS 2 parameter")


def render(kind: str) -> str:
    """The text of ``config/ros2/<kind>.yaml``."""
    from ..settings import yaml_comments

    nf = NODES[kind]
    comments = yaml_comments(nf.source)
    src = nf.source.relative_to(ROOT)
    params = tree(kind)
    sec = next(k for k, v in params.items() if isinstance(v, dict) and v)
    leaf = next(iter(params[sec]))
    example = f"{sec}: {leaf}: -> {sec}.{leaf}"
    lines = [
        f"# GENERATED from {src} by `python -m robotatfactory.ros.params2 --write`: edit that file, then",
        "# regenerate (tests/test_ros2_params.py fails while this one is out of date).",
        f"# ROS 2 parameter file of the {kind} node ({nf.node}, in any namespace): every parameter it declares,",
        "# with the value of the ROS 1 file or the node's default. Nested keys are ROS 2 parameters with dots",
        f"# ({example}). Use: launch/ros2/*.launch.py, or",
        f"#   ros2 run robotatfactory {nf.node.replace('raf_', '')}_node --ros-args --params-file {nf.target.relative_to(ROOT)}",
        f"/**/{nf.node}:",
        "  ros__parameters:",
    ]

    def walk(d: dict, indent: int, prefix: str) -> None:
        for k, v in d.items():
            pad = " " * indent
            name = f"{prefix}{k}"
            if isinstance(v, dict) and v and any(x is not None for x in flatten(v, ".").values()):
                lines.append(f"{pad}{k}:")
                walk(v, indent + 2, name + ".")
            elif v is None or isinstance(v, dict):  # unset (no ROS 2 parameter value): the node declares it unset
                lines.append(f"{pad}# {k}: (unset)")
            else:
                text = f"{pad}{k}: {scalar(v)}"
                note = comments.get(name, "")
                lines.append(f"{text:<44} # {note}" if note else text)

    walk(params, 4, "")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m robotatfactory.ros.params2",
                                description="the nodes' ROS 2 parameter files (config/ros2/*.yaml), generated "
                                            "from config/bridge.yaml and config/localization.yaml")
    p.add_argument("kind", nargs="?", choices=sorted(NODES), help="print this node's file")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--write", action="store_true", help="write config/ros2/*.yaml")
    g.add_argument("--check", action="store_true", help="exit 1 when a committed file differs from its source")
    a = p.parse_args(argv)
    kinds = [a.kind] if a.kind else sorted(NODES)
    if not (a.write or a.check):
        if not a.kind:
            p.error("name a node (bridge, localization), or --write / --check")
        sys.stdout.write(render(a.kind))
        return 0
    stale = []
    for k in kinds:
        text, target = render(k), NODES[k].target
        if a.write:
            target.parent.mkdir(parents=True, exist_ok=True)
            if not target.exists() or target.read_text() != text:
                target.write_text(text)
                print(f"wrote {target.relative_to(ROOT)}")
        elif not target.exists() or target.read_text() != text:
            stale.append(str(target.relative_to(ROOT)))
    if stale:
        print(f"out of date: {', '.join(stale)} (python -m robotatfactory.ros.params2 --write)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
