"""Load a field description (JSON inside the package, or a file) into :class:`Field`."""
from __future__ import annotations

import json
import math
from importlib import resources
from pathlib import Path

import numpy as np

from .model import Area, Box, Field, Marker, PartSpec, Pose2D, Slot

DEFAULT_FIELD = "rules2026"


class FieldError(ValueError):
    """A field file is missing, malformed or inconsistent."""


def available_fields() -> list[str]:
    """Names of the field files shipped with the package (``raf --field NAME``)."""
    data = resources.files("robotatfactory") / "data"
    return sorted(p.name[len("field_"):-len(".json")] for p in data.iterdir()
                  if p.name.startswith("field_") and p.name.endswith(".json"))


def marker_pose(x: float, y: float, z: float, rx: float, ry: float, rz: float) -> np.ndarray:
    """4x4 world <- marker transform from the rules' table (degrees; R = Rx * Ry * Rz)."""
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    # intrinsic X-Y-Z in scipy is exactly Rx @ Ry @ Rz
    T[:3, :3] = Rotation.from_euler("XYZ", [rx, ry, rz], degrees=True).as_matrix()
    T[:3, 3] = (x, y, z)
    return T


def _read_raw(name_or_path: str) -> dict:
    path = Path(name_or_path)
    if path.suffix == ".json" and path.exists():
        text = path.read_text()
    else:
        res = resources.files("robotatfactory") / "data" / f"field_{name_or_path}.json"
        if not res.is_file():
            raise FieldError(f"unknown field {name_or_path!r}: choose one of {available_fields()} "
                             "or give a path to a field .json file")
        text = res.read_text()
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise FieldError(f"field {name_or_path!r}: invalid JSON at line {e.lineno}: {e.msg}") from None


def _apply_overlay(base: dict, overlay: dict) -> dict:
    """A field file with ``base`` lists only its differences from that base field."""
    raw = json.loads(json.dumps(base))
    raw["name"] = overlay["name"]
    raw["description"] = overlay.get("description", raw.get("description", ""))
    by_id = {m["id"]: m for m in raw["markers"]}
    if "wall_marker_size" in overlay:
        for m in raw["markers"]:
            if m["kind"] == "wall":
                m["size"] = overlay["wall_marker_size"]
    # give each listed id the pose of the next one in its group (a swap for pairs, a reversal of
    # positions for longer groups given in reversed order)
    for group in overlay.get("swap_ids", []):
        _permute(by_id, group, list(reversed(group)))
    for group in overlay.get("reverse_ids", []):
        _permute(by_id, group, list(reversed(group)))
    # geometry that differs from the base: the floor's extent, a uniform shift of the floor markers (the
    # print's offset), per-marker coordinates (applied after the permutations: keyed by the final id) and
    # per-box centre/size (by name)
    if "floor" in overlay:
        raw["floor"] = overlay["floor"]
    dx, dy = overlay.get("floor_marker_offset", (0.0, 0.0))
    for m in raw["markers"]:
        if m["kind"] == "floor":
            m["x"], m["y"] = m["x"] + dx, m["y"] + dy
    for mid, values in overlay.get("marker_overrides", {}).items():
        m = by_id.get(int(mid))
        if m is None:
            raise FieldError(f"field overlay overrides marker {mid}, which the base field lacks")
        bad = set(values) - {"x", "y", "z", "rx", "ry", "rz", "size"}
        if bad:
            raise FieldError(f"field overlay: marker {mid}: unknown keys {sorted(bad)}")
        m.update(values)
    # markers the base has and this field does not show (e.g. SimTwo's mirrored 62-65: no detector finds them)
    gone = {int(i) for i in overlay.get("remove_ids", [])}
    if gone - set(by_id):
        raise FieldError(f"field overlay removes markers {sorted(gone - set(by_id))}, which the base field lacks")
    raw["markers"] = [m for m in raw["markers"] if m["id"] not in gone]
    slots = {f"{s['zone']}_{s['number']}": s for s in raw["slots"]}
    for name, values in overlay.get("slot_overrides", {}).items():
        if name not in slots:
            raise FieldError(f"field overlay overrides slot {name!r}, which the base field lacks")
        bad = set(values) - {"xy", "facing_deg"}
        if bad:
            raise FieldError(f"field overlay: slot {name!r}: unknown keys {sorted(bad)}")
        slots[name].update(values)
    boxes = {b["name"]: b for b in raw["static_boxes"]}
    for name, values in overlay.get("box_overrides", {}).items():
        if name not in boxes:
            raise FieldError(f"field overlay overrides box {name!r}, which the base field lacks")
        bad = set(values) - {"center", "size", "yaw"}
        if bad:
            raise FieldError(f"field overlay: box {name!r}: unknown keys {sorted(bad)}")
        boxes[name].update(values)
    return raw


def _permute(by_id: dict, ids: list[int], take_from: list[int]) -> None:
    keys = ("x", "y", "z", "rx", "ry", "rz")
    try:
        saved = {i: {k: by_id[i][k] for k in keys} for i in ids}
    except KeyError as e:
        raise FieldError(f"field overlay names marker {e.args[0]}, which the base field lacks") from None
    for dst, src in zip(ids, take_from):
        by_id[dst].update(saved[src])


def load_field(name_or_path: str = DEFAULT_FIELD) -> Field:
    """Load a shipped field by name (see :func:`available_fields`) or a field ``.json`` file."""
    raw = _read_raw(name_or_path)
    if "base" in raw:
        raw = _apply_overlay(_read_raw(raw["base"]), raw)
    try:
        return _build(raw)
    except (KeyError, TypeError, ValueError) as e:
        if isinstance(e, FieldError):
            raise
        raise FieldError(f"field {name_or_path!r} is malformed: {type(e).__name__}: {e}") from None


def _build(raw: dict) -> Field:
    markers = []
    for m in raw["markers"]:
        if m["kind"] not in ("floor", "wall"):
            raise FieldError(f"marker {m['id']}: kind must be floor or wall, not {m['kind']!r}")
        if not m["size"] > 0:
            raise FieldError(f"marker {m['id']}: size must be positive")
        markers.append(Marker(id=int(m["id"]), kind=m["kind"], size=float(m["size"]),
                              pose=marker_pose(m["x"], m["y"], m["z"], m["rx"], m["ry"], m["rz"]),
                              euler_deg=(m["rx"], m["ry"], m["rz"])))
    ids = [m.id for m in markers]
    if len(set(ids)) != len(ids):
        dup = sorted({i for i in ids if ids.count(i) > 1})
        raise FieldError(f"field {raw['name']!r}: duplicate marker ids {dup}")
    boxes = tuple(Box(b["name"], tuple(b["center"]), tuple(b["size"]), float(b.get("yaw", 0.0)))
                  for b in raw["static_boxes"])
    slots = tuple(Slot(s["zone"], int(s["number"]), s["role"], tuple(s["xy"]),
                       math.radians(s["facing_deg"])) for s in raw["slots"])
    p = raw["part"]
    part = PartSpec(p["width"], p["depth"], p["body_height"], p["feet_height"], tuple(p["plate"]),
                    p["tag_size"], p["mass"])
    sp = raw["start_pose"]
    team = tuple(Area(t["name"], (t["center"][0] - t["size"] / 2, t["center"][0] + t["size"] / 2),
                      (t["center"][1] - t["size"] / 2, t["center"][1] + t["size"] / 2))
                 for t in raw["team_areas"])
    b = raw["beacons"]
    return Field(
        name=raw["name"], description=raw.get("description", ""),
        dictionary=raw.get("dictionary", "DICT_5X5_100"),
        floor=Area("floor", tuple(raw["floor"]["x"]), tuple(raw["floor"]["y"])),
        markers=tuple(sorted(markers, key=lambda m: m.id)), boxes=boxes, slots=slots, part=part,
        start_area=Area("start", tuple(raw["start_area"]["x"]), tuple(raw["start_area"]["y"])),
        start_pose=Pose2D(sp["x"], sp["y"], math.radians(sp["yaw_deg"])),
        team_areas=team, beacon_diameter=b["diameter"], beacon_height=b["height"],
        beacons=tuple(tuple(c) for c in b["centers"]),
    )
