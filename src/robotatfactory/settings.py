"""Layered settings shared by the nodes' configurations: YAML files, ``--set NAME=VALUE`` and merging.

Plain Python (PyYAML only); errors are :class:`robotatfactory.errors.ConfigError` naming the file or option.
"""
from __future__ import annotations

from pathlib import Path


def deep_update(base: dict, over: dict) -> dict:
    """``over`` onto ``base`` recursively (both nested dicts); returns ``base``."""
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(base.get(k), dict):
            deep_update(base[k], v)
        else:
            base[k] = v
    return base


def read_yaml(path: str | Path, what: str = "settings file") -> dict:
    """A YAML file holding a mapping (an empty file is an empty mapping)."""
    import yaml

    from .errors import ConfigError

    try:
        with open(path) as fh:
            loaded = yaml.safe_load(fh) or {}
    except OSError as e:
        raise ConfigError(f"{what} {path}: {e}") from None
    except yaml.YAMLError as e:
        raise ConfigError(f"{what} {path}: not valid YAML: {e}") from None
    if not isinstance(loaded, dict):
        raise ConfigError(f"{what} {path}: expected a mapping, got {type(loaded).__name__}")
    return loaded


def parse_set(items: list[str]) -> dict:
    """``["udp/port=9999", "camera/enabled=false"]`` to a nested dict; values parsed as YAML scalars."""
    import yaml

    from .errors import ConfigError

    out: dict = {}
    for it in items or []:
        if "=" not in it:
            raise ConfigError(f"--set {it!r}: expected NAME=VALUE, e.g. camera/fx=283.5")
        k, v = it.split("=", 1)
        keys = [s for s in k.strip().lstrip("~").split("/") if s]
        if not keys:
            raise ConfigError(f"--set {it!r}: empty parameter name")
        d = out
        for s in keys[:-1]:
            d = d.setdefault(s, {})
        d[keys[-1]] = yaml.safe_load(v) if v.strip() else ""
    return out


def yaml_comments(path: str | Path, sep: str = ".") -> dict:
    """The end-of-line comments of a block-style YAML settings file by parameter path (``udp.port`` ->
    "SimTwo scripts send SensorFrames here"): the descriptions ROS 2 parameters are declared with."""
    out: dict = {}
    stack: list[tuple[int, str]] = []
    try:
        lines = Path(path).read_text().splitlines()
    except OSError:
        return out
    for line in lines:
        body = line.split(" #", 1)
        text = body[0].rstrip()
        if not text.strip() or text.lstrip().startswith("#") or ":" not in text:
            continue
        indent = len(text) - len(text.lstrip())
        key = text.strip().split(":", 1)[0].strip()
        while stack and stack[-1][0] >= indent:
            stack.pop()
        full = sep.join([k for _, k in stack] + [key])
        if text.rstrip().endswith(":"):  # a section
            stack.append((indent, key))
        elif len(body) > 1:
            out[full] = body[1].strip()
    return out
