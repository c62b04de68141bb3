"""Layered settings shared by the components' configurations: YAML files, ``--set NAME=VALUE``, merging,
and typed settings objects.

A typed settings object is a tree of frozen dataclasses whose fields are made with :func:`setting` (the
default, what it means, its allowed values: the one place for each) and :func:`section` (a group). The same
nested mapping, from a YAML file, ``--set``, ROS parameters or an experiment's options, becomes the object
through :func:`build`, the one validation: an unknown name or a bad value is a
:class:`robotatfactory.errors.ConfigError` naming the setting by its path (``dock.approach_speed``) and what is
allowed. :func:`tree` and :func:`descriptions` go the other way (printing, ROS 2 parameter declarations).

Plain Python (PyYAML only).
"""
from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path
from typing import Any, Mapping


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
    """``["udp/port=9999", "camera.enabled=false"]`` to a nested dict (``/`` or ``.`` between a section and its
    setting, as in ROS 1's and ROS 2's parameter names); values parsed as YAML scalars."""
    import yaml

    from .errors import ConfigError

    out: dict = {}
    for it in items or []:
        if "=" not in it:
            raise ConfigError(f"--set {it!r}: expected NAME=VALUE, e.g. camera/fx=283.5")
        k, v = it.split("=", 1)
        keys = [s for s in k.strip().lstrip("~").replace(".", "/").split("/") if s]
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


# ------------------------------------------------------------------------------------------ typed settings
def _meta(doc: str, lo, hi, lo_open: bool, choices, kind, pattern, what, size, items) -> dict:
    return {"doc": doc, "lo": lo, "hi": hi, "lo_open": lo_open, "choices": choices, "kind": kind,
            "pattern": pattern, "what": what, "size": size, "items": items}


def setting(default: Any, doc: str = "", *, lo: float | None = None, hi: float | None = None,
            lo_open: bool = False, choices: tuple | None = None, kind: type | None = None,
            pattern: str | None = None, what: str = "", size: tuple[int, int] | None = None,
            items: type | None = None):
    """A field of a settings dataclass: ``default``, ``doc`` (units first, then what it does) and the values
    :func:`build` allows: numbers within ``lo``..``hi`` (``lo_open``: above ``lo``), one of ``choices``, a
    string matching ``pattern`` (``what`` says it in words), a list of ``size`` = (least, most) ``items``
    (numbers). ``kind`` when the default does not say it (a default of None: "unset", e.g. taken from the
    robot file)."""
    meta = _meta(doc, lo, hi, lo_open, choices, kind or type(default), pattern, what, size, items)
    return dataclasses.field(default=default, metadata=meta)


def spec(doc: str = "", *, default: Any = dataclasses.MISSING, lo: float | None = None, hi: float | None = None,
         lo_open: bool = False, choices: tuple | None = None, size: tuple[int, int] | None = None,
         items: type | None = None):
    """A field of a model (a dataclass read from data, such as the robot file's camera) with what
    :func:`setting` says of a setting: its meaning and allowed values. The model keeps no default for it (its
    file gives the value); :func:`overlay` makes settings of such fields, so a component that lets a user
    change the model's values declares none of them again."""
    meta = _meta(doc, lo, hi, lo_open, choices, None, None, "", size, items)
    return dataclasses.field(default=default, metadata={"spec": meta})


def overlay(model: type, names: tuple[str, ...] | None = None, name: str | None = None) -> type:
    """A settings section (frozen dataclass) whose settings are ``model``'s fields (all, or ``names``) made with
    :func:`spec`, each unset (None) by default: values given over a model object made elsewhere (the robot
    file's camera), applied with :func:`over`. Subclass it to add the component's own settings."""
    import typing

    hints = typing.get_type_hints(model)
    specs = {f.name: f for f in dataclasses.fields(model) if "spec" in f.metadata}
    names = tuple(specs) if names is None else names
    out = []
    for n in names:
        if n not in specs:
            raise TypeError(f"{model.__name__}.{n} is not a spec() field")
        m = dict(specs[n].metadata["spec"])
        hint = hints[n]
        m["kind"] = typing.get_origin(hint) or hint
        out.append((n, hint | None, dataclasses.field(default=None, metadata=m)))
    cls = dataclasses.make_dataclass(name or f"{model.__name__}Overlay", out, frozen=True)
    cls.__doc__ = f"Values over a {model.__name__} (unset: the model's own): {', '.join(names)}."
    cls.model = model
    return cls


def over(values, model_obj):
    """``model_obj`` (a :func:`spec` model) with the settings of ``values`` (an :func:`overlay` section, or a
    subclass of one) that are set; the unset ones keep the model's values."""
    names = {f.name for f in dataclasses.fields(model_obj)}
    given = {f.name: getattr(values, f.name) for f in dataclasses.fields(values)
             if f.name in names and "kind" in f.metadata and getattr(values, f.name) is not None}
    return dataclasses.replace(model_obj, **given) if given else model_obj


def given(obj, where: str = "") -> dict:
    """The settings of ``obj`` that are set (not None), as the nested mapping :func:`build` reads."""
    out = {}
    for f in _settings_fields(obj):
        v = getattr(obj, f.name)
        if f.metadata.get("section"):
            sub = given(v)
            if sub:
                out[f.name] = sub
        elif v is not None:
            out[f.name] = list(v) if isinstance(v, tuple) else v
    return out


def section(cls: type, doc: str = ""):
    """A group of settings (a settings dataclass) inside another."""
    return dataclasses.field(default_factory=cls, metadata={"doc": doc, "section": cls})


def _join(where: str, name: str) -> str:
    return f"{where}.{name}" if where else name


def _allowed(m: Mapping) -> str:
    kind, lo, hi, choices = m["kind"], m["lo"], m["hi"], m["choices"]
    if choices:
        return "one of " + ", ".join(map(str, choices))
    if kind is bool:
        return "true or false"
    if m.get("what"):
        return m["what"]
    if kind in (tuple, list) and m.get("size"):
        least, most = m["size"]
        count = f"{least}" if least == most else f"{least} to {most}"
        return f"a list of {count} {'numbers' if m.get('items') in (int, float) else 'values'}"
    what = "a whole number" if kind is int else "a number" if kind is float else f"a {kind.__name__}"
    if lo is not None and hi is not None:
        return f"{what} in {'(' if m['lo_open'] else '['}{lo:g}, {hi:g}]"
    if lo is not None:
        return f"{what} {'>' if m['lo_open'] else '>='} {lo:g}"
    if hi is not None:
        return f"{what} <= {hi:g}"
    return what


def _value(path: str, v: Any, f: dataclasses.Field) -> Any:
    from .errors import ConfigError

    m = f.metadata
    kind = m["kind"]
    if v is None and f.default is None:
        return None
    bad = ConfigError(f"setting {path} must be {_allowed(m)}, got {v!r}"
                      + (f" ({m['doc']})" if m.get("doc") else ""))
    if kind is bool:
        if isinstance(v, bool):
            return v
        if isinstance(v, int) and v in (0, 1):  # a switch given as 0 / 1
            return bool(v)
        raise bad
    if kind in (int, float):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise bad
        if kind is int and float(v) != int(v):
            raise bad
        v = int(v) if kind is int else float(v)
        lo, hi = m["lo"], m["hi"]
        if lo is not None and (v < lo or (m["lo_open"] and v == lo)) or hi is not None and v > hi:
            raise bad
    elif kind is str:
        if not isinstance(v, str):
            raise bad
        if m.get("pattern") is not None and not re.fullmatch(m["pattern"], v):
            raise bad
    elif kind in (tuple, list):
        if isinstance(v, (str, bytes)) or not isinstance(v, (list, tuple)):
            raise bad
        if m.get("size") and not m["size"][0] <= len(v) <= m["size"][1]:
            raise bad
        if m.get("items") in (int, float):
            if not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v):
                raise bad
            v = tuple(m["items"](x) for x in v)
        v = tuple(tuple(x) if isinstance(x, list) else x for x in v)
    if m["choices"] and v not in m["choices"]:
        raise bad
    return v


def build(cls: type, values: Mapping | None = None, where: str = ""):
    """The settings object ``cls`` with ``values`` (a nested mapping; what it lacks keeps its default), each
    value checked (:func:`setting`'s kind, range and choices), then the object's own ``check()`` if it has one
    (cross-setting rules). ``where``: the path of this group in a larger tree (for the errors)."""
    from .errors import ConfigError

    values = {} if values is None else values
    if not isinstance(values, Mapping):
        raise ConfigError(f"{where or 'settings'}: expected a mapping of settings, got {values!r}")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(values) - set(fields))
    if unknown:
        raise ConfigError(f"unknown setting(s) {', '.join(_join(where, str(u)) for u in unknown)}; known"
                          f"{' in ' + where if where else ''}: {', '.join(fields)}")
    kw = {}
    for name, v in values.items():
        f, path = fields[name], _join(where, name)
        sub = f.metadata.get("section")
        if not sub and "kind" not in f.metadata:  # a plain field: set in code, not from settings
            raise ConfigError(f"{path} is not a setting (set in code only)")
        kw[name] = build(sub, v, path) if sub else _value(path, v, f)
    obj = cls(**kw)
    if hasattr(obj, "check"):
        obj.check()
    return obj


def _settings_fields(obj) -> list:
    """The fields of a settings dataclass that are settings or sections (not the plain ones set in code)."""
    return [f for f in dataclasses.fields(obj) if "kind" in f.metadata or f.metadata.get("section")]


def tree(obj) -> dict:
    """A settings object as the nested mapping :func:`build` reads (tuples as lists: YAML's and ROS's)."""
    out = {}
    for f in _settings_fields(obj):
        v = getattr(obj, f.name)
        out[f.name] = tree(v) if f.metadata.get("section") else list(v) if isinstance(v, tuple) else v
    return out


def to_yaml(obj, header: str = "", indent: int = 0) -> str:
    """A settings object as a YAML file that :func:`build` reads back: every setting with its value and,
    after it, what it means (the comments ROS 2's parameter descriptions are read from: :func:`yaml_comments`);
    ``header`` as comment lines on top."""
    import yaml

    lines = [f"# {h}".rstrip() for h in header.splitlines()] if header else []
    pad = " " * indent
    for f in _settings_fields(obj):
        v, doc = getattr(obj, f.name), f.metadata.get("doc", "")
        if f.metadata.get("section"):
            empty = all(getattr(v, g.name) is None for g in dataclasses.fields(v))  # all unset: an empty mapping
            lines.append(f"{pad}{f.name}:{' {}' if empty else ''}" + (f"  # {doc}" if doc else ""))
            lines.append(to_yaml(v, indent=indent + 2).rstrip("\n"))
            continue
        if v is None:  # unset (null is no ROS parameter value): shown as a comment
            lines.append(f"{pad}# {f.name}: (unset) {doc}".rstrip())
            continue
        # one flow-style value: dumped as a one-element list (a bare scalar gets YAML's "..." end marker)
        value = yaml.safe_dump([list(v) if isinstance(v, tuple) else v], default_flow_style=True,
                               width=10 ** 6).strip()[1:-1]
        text = f"{pad}{f.name}: {value}"
        lines.append(f"{text:<36} # {doc}" if doc else text)
    return "\n".join(lines) + "\n"


def descriptions(cls: type, sep: str = ".", where: str = "") -> dict[str, tuple[str, tuple | None]]:
    """``{path: (doc, (lo, hi) or None)}`` of every setting of ``cls`` (ROS 2's parameter descriptors)."""
    out: dict = {}
    for f in _settings_fields(cls):
        path = f"{where}{sep}{f.name}" if where else f.name
        sub = f.metadata.get("section")
        if sub:
            out.update(descriptions(sub, sep, path))
        else:
            m = f.metadata
            lo, hi, kind = m.get("lo"), m.get("hi"), m.get("kind")
            rng = None
            if kind in (int, float) and (lo is not None or hi is not None):
                big = 2 ** 62 if kind is int else 1e300  # one side open: as far as the parameter's type goes
                rng = (lo if lo is not None else -big, hi if hi is not None else big)
            doc = m.get("doc", "")
            out[path] = (doc + (f" ({_allowed(m)})" if m.get("choices") else ""), rng)
    return out


def describer(cls: type, sep: str = "."):
    """``describe(name) -> (doc, (lo, hi) or None)`` of ``cls``'s settings by parameter name (``udp.port``): what
    a node hands :meth:`~robotatfactory.ros.mw.base.Node.params` for ROS 2's parameter descriptors. The table is
    made on first use."""
    table: dict | None = None

    def describe(name: str) -> tuple[str, tuple | None]:
        nonlocal table
        if table is None:
            table = descriptions(cls, sep)
        return table.get(name, ("", None))

    return describe
