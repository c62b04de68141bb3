"""Calibration files (``raf calibrate``'s YAML: ``camera:`` and ``fit:``) and robot files with a changed camera:
writing, reading with one validation, and applying a file to a robot's camera."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

from ...errors import ConfigError
from ...robot import CameraSpec, RobotSpec
from .solver import CalibrationResult


def calibration_dict(result: CalibrationResult) -> dict:
    """The YAML document: ``camera:`` (what bridge and localize load) and ``fit:``."""
    c = result.camera
    return {"camera": camera_dict(c), "fit": result.summary()}


def camera_dict(c: CameraSpec) -> dict:
    def r(v, n=6):
        return float(round(float(v), n))
    return {"fx": r(c.fx, 4), "fy": r(c.fy, 4), "cx": r(c.cx, 4), "cy": r(c.cy, 4),
            "distortion": [r(v, 8) for v in c.distortion], "xyz": [r(v, 5) for v in c.xyz],
            "pitch_down_deg": r(c.pitch_down_deg, 4), "roll_deg": r(c.roll_deg, 4),
            "width": int(c.width), "height": int(c.height)}


def write_calibration(path: str | Path, result_or_camera, fit: dict | None = None) -> Path:
    """Write a calibration YAML from a :class:`CalibrationResult` (or a CameraSpec and a ``fit`` dict)."""
    import yaml

    if isinstance(result_or_camera, CalibrationResult):
        doc = calibration_dict(result_or_camera)
    else:
        doc = {"camera": camera_dict(result_or_camera), "fit": dict(fit or {})}
    p = Path(path)
    if p.parent and not p.parent.exists():
        p.parent.mkdir(parents=True, exist_ok=True)
    header = ("# camera calibration (raf calibrate; docs/calibration.md). Pixels with centres at integers,\n"
              "# distortion: OpenCV (k1, k2, p1, p2, k3); xyz: base_link -> camera_link (m); pitch down and roll\n"
              "# about the optical axis in degrees. Load with: raf bridge --calibration FILE, raf localize\n"
              "# --calibration FILE.\n")
    p.write_text(header + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None))
    return p


@dataclass(frozen=True)
class Calibration:
    """A loaded calibration file: the camera values it sets (a subset of the keys is allowed)."""

    path: str
    camera: dict
    fit: dict

    def apply(self, cam: CameraSpec) -> CameraSpec:
        """``cam`` with this file's values."""
        c = self.camera
        kw = {}
        for k in ("fx", "fy", "cx", "cy", "pitch_down_deg", "roll_deg"):
            if k in c:
                kw[k] = float(c[k])
        if "xyz" in c:
            kw["xyz"] = tuple(float(v) for v in c["xyz"])
        if "distortion" in c:
            kw["distortion"] = tuple(float(v) for v in c["distortion"])
        for k in ("width", "height"):
            if k in c and int(c[k]) != getattr(cam, k):
                raise ConfigError(f"calibration {self.path}: camera/{k} is {c[k]} but the camera's image is "
                                  f"{cam.width}x{cam.height} (a calibration holds for one image size)")
        return replace(cam, **kw)


def load_calibration(path: str | Path) -> Calibration:
    """Read and check a calibration YAML (``camera:`` mapping; ``fit:`` optional), once per process: every
    consumer (the command's check, the settings, the node, the camera object) gets the same
    :class:`Calibration` until the file changes."""
    p = Path(path)
    try:
        st = p.stat()
        key = (str(p.resolve()), st.st_mtime_ns, st.st_size)
    except OSError:
        key = None  # missing: _parse says so
    if key is not None and key in _LOADED:
        return _LOADED[key]
    cal = _parse(path)
    if key is not None:
        _LOADED[key] = cal
    return cal


_LOADED: dict[tuple, Calibration] = {}


def _parse(path: str | Path) -> Calibration:
    from ...settings import read_yaml

    d = read_yaml(path, "calibration file")
    cam = d.get("camera")
    if not isinstance(cam, dict) or not cam:
        raise ConfigError(f"calibration file {path}: needs a 'camera:' mapping (fx, fy, cx, cy, distortion, xyz, "
                          f"pitch_down_deg, roll_deg)")
    known = {"fx", "fy", "cx", "cy", "distortion", "xyz", "pitch_down_deg", "roll_deg", "width", "height"}
    bad = sorted(set(cam) - known)
    if bad:
        raise ConfigError(f"calibration file {path}: unknown camera key(s) {bad}; known: {sorted(known)}")

    def num(k, v, positive=False):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or (positive and v <= 0):
            raise ConfigError(f"calibration file {path}: camera/{k} must be a finite "
                              f"{'positive ' if positive else ''}number, got {v!r}")
        return float(v)
    for k in ("fx", "fy"):
        if k in cam:
            num(k, cam[k], positive=True)
    for k in ("cx", "cy", "pitch_down_deg", "roll_deg"):
        if k in cam:
            num(k, cam[k])
    if "xyz" in cam:
        v = cam["xyz"]
        if not isinstance(v, (list, tuple)) or len(v) != 3:
            raise ConfigError(f"calibration file {path}: camera/xyz must be [x, y, z] in metres, got {v!r}")
        [num("xyz", a) for a in v]
    if "distortion" in cam:
        v = cam["distortion"]
        if not isinstance(v, (list, tuple)) or not 1 <= len(v) <= 5:
            raise ConfigError(f"calibration file {path}: camera/distortion must be [k1, k2, p1, p2, k3], got {v!r}")
        [num("distortion", a) for a in v]
    for k in ("width", "height"):
        if k in cam and (isinstance(cam[k], bool) or not isinstance(cam[k], int) or cam[k] <= 0):
            raise ConfigError(f"calibration file {path}: camera/{k} must be a positive integer, got {cam[k]!r}")
    fit = d.get("fit") or {}
    if not isinstance(fit, dict):
        raise ConfigError(f"calibration file {path}: 'fit:' must be a mapping")
    return Calibration(str(path), dict(cam), dict(fit))


def calibrated_robot(robot: RobotSpec, path: str | Path) -> RobotSpec:
    """``robot`` with the camera of a calibration file."""
    return replace(robot, camera=load_calibration(path).apply(robot.camera))


def robot_dict(robot: RobotSpec) -> dict:
    """A robot as the JSON document :func:`robotatfactory.robot.load_robot` reads."""
    from dataclasses import asdict

    d = asdict(robot)
    d["camera"]["xyz"] = list(robot.camera.xyz)
    d["camera"]["distortion"] = list(robot.camera.distortion)
    d["lidar"]["xyz"] = list(robot.lidar.xyz)
    return d


def write_robot_json(robot: RobotSpec, path: str | Path) -> Path:
    """Write ``robot`` as a JSON file that ``raf sim --robot FILE`` (``load_robot``) accepts."""
    import json

    p = Path(path)
    if p.suffix != ".json":
        raise ConfigError(f"robot file {p}: must end in .json (load_robot recognises files by that suffix)")
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(robot_dict(robot), indent=1))
    return p
