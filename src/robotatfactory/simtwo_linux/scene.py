"""A fresh copy of a SimTwo scene with the project's script, LIDAR and settings installed.

What docs/simtwo.md's "Step by step (Windows)" tells a user to do by hand, done to a copy (SimTwo rewrites
its scene's ``config_*.ini`` when it exits, so every run gets its own):

- ``control.pas`` <- ``simtwo/control.pas``, with ``BRIDGE_IP`` / ``BRIDGE_PORT`` set (step 2);
- ``AGV.xml`` gets the ``<ranger2d>`` element of ``simtwo/AGV_lidar.xml`` inside ``<sensors>`` (step 3);
- with a robot's camera (``raf simtwo run --robot FILE``): ``AGV.xml``'s ``<camera>`` shell gets its focal
  length, pitch and mount (:func:`install_camera`; what GLScene cannot render is refused);
- ``config_Params.ini`` [Config] and ``config_Cameras.ini`` [Cameras] get the lines of
  ``simtwo/settings/*.ini`` (steps 4-5), with SimTwo's UDP port set;
- headless only: the Cameras window is placed where no other window covers it (a covered or off-screen
  OpenGL window reads back black), and the main viewer is made small (:data:`VIEWER_WINDOW`).
"""
from __future__ import annotations

import math
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

from ..simtwo.ports import BRIDGE_UDP_PORT, LOCALHOST, SIMTWO_UDP_PORT
from ..simtwo.teleport import SIMTWO_PART_PREFIX, SIMTWO_PART_Z, part_heading, spare_part_xy

ROOT = Path(__file__).resolve().parents[3]
SIMTWO_DIR = ROOT / "simtwo"
DEFAULT_SCENE = "RobotFactoryPro2022"
#: the field model of SimTwo's RobotAtFactory 4.0 scene (robotatfactory/data/field_simtwo2022.json)
SIMTWO_FIELD = "simtwo2022"


#: where the Cameras window goes on the virtual screen (right of every window SimTwo's scene opens)
CAMERAS_WINDOW = {"FCameras_Left": "1700", "FCameras_Top": "0"}
#: headless, nobody looks at the main viewer: a small one renders faster, and SimTwo's GUI thread renders it
#: beside the camera's (a render took 8 ms at 160 x 120, 3.6 ms at 32 x 24: the camera 5.9-6.2 frames/s
#: instead of 5.0-5.2); the physics and the camera's image do not depend on it
VIEWER_WINDOW = {"FViewer_Width": "32", "FViewer_Height": "24"}
#: headless with the camera open: SimTwo's "Hot CPU" (Params, CBHotCPU: no Sleep(1) before each cadencer
#: step). With the camera the GUI loop never idles (its renders keep it busy), so the sleep only delays each
#: step: the camera 6.7-7.3 frames/s instead of 5.9-6.2, SimTwo's GUI thread at 0.66 cores either way.
#: Without the camera the loop does idle, and Hot CPU would spin a core (0.98 instead of 0.66): off then
HOT_CPU = {"CBHotCPU_Checked": "1"}


def field_for_simtwo(name: str) -> str:
    """The field to use with SimTwo's scene: ``name`` unless it is the project's default (the rules' field,
    which SimTwo's scene is not), then :data:`SIMTWO_FIELD`."""
    from ..field import DEFAULT_FIELD

    return SIMTWO_FIELD if name == DEFAULT_FIELD else name


class SceneError(ValueError):
    """The scene cannot be installed: the message says which file and what is wrong."""


@dataclass
class SceneSettings:
    """How the scene copy talks to the bridge (the values a Windows user edits by hand)."""

    udp_port: int = SIMTWO_UDP_PORT          # SimTwo listens for Commands (config_Params.ini EditUDPPort)
    bridge_host: str = LOCALHOST             # control.pas BRIDGE_IP
    bridge_port: int = BRIDGE_UDP_PORT       # control.pas BRIDGE_PORT
    script: Path = SIMTWO_DIR / "control.pas"
    lidar: bool = True                       # paste simtwo/AGV_lidar.xml into AGV.xml
    extra_ini: dict[str, dict[str, str]] = field(default_factory=dict)  # {"config_Params.ini": {key: value}}
    parts: list[PartPlacement] | None = None  # None: the parts where the scene file has them
    camera: object | None = None             # a robot file's CameraSpec for AGV.xml's <camera>; None: the scene's


@dataclass(frozen=True)
class PartPlacement:
    """Where one of the scene's parts (robots Part1..Part4) starts: its colour (``R``, ``G``, ``B``), the
    centre (m, SimTwo's world frame) and the heading of its plate (rad, as a field's Slot.facing)."""

    color: str
    x: float
    y: float
    facing: float


#: SimTwo's part bodies by colour
PART_FILES = {"R": "PartRed.xml", "G": "PartGreen.xml", "B": "PartBlue.xml"}
#: where a part the round does not use waits: outside the field, beyond the walls


def round_parts(field, incoming) -> list[PartPlacement]:
    """Placements of Part1..Part4 for a round's incoming warehouse (``RoundSetup.incoming``: a part type or
    None per slot, slot 1 first): each part on its incoming slot's centre; spare parts off the field."""
    out = []
    spare = 0
    for number, part in enumerate(incoming, start=1):
        if part is None:
            x, y = spare_part_xy(spare)
            out.append(PartPlacement("B", x, y, 0.0))
            spare += 1
            continue
        slot = field.slot("incoming", number)
        out.append(PartPlacement(part.letter, slot.xy[0], slot.xy[1], slot.facing))
    return out


def place_parts(scene_xml: Path, parts: list[PartPlacement]) -> None:
    """Rewrite the ``<pos>``, ``<rot_deg>`` and ``<body>`` of robots Part1..PartN in ``scene_xml``, turned as
    SimTwo turns a part (:func:`~robotatfactory.simtwo.teleport.part_heading`)."""
    text = scene_xml.read_text(encoding="latin-1")
    for i, p in enumerate(parts, start=1):
        if p.color not in PART_FILES:
            raise SceneError(f"part {i}: colour {p.color!r} is not one of {sorted(PART_FILES)}")
        name = f"{SIMTWO_PART_PREFIX}{i}"
        m = re.search(rf"<robot>\s*<ID name='{name}'/>.*?</robot>", text, re.S)
        if not m:
            raise SceneError(f"{scene_xml}: no robot {name} to place")
        deg = math.degrees(part_heading(p.facing))
        body = (f"<robot>\n    <ID name='{name}'/>\n    <pos x='{p.x:.6f}' y='{p.y:.6f}' z='{SIMTWO_PART_Z}'/>\n"
                f"    <rot_deg x='0' y='0' z='{deg:.4f}'/>\n    <body file='{PART_FILES[p.color]}'/>\n  </robot>")
        text = text[:m.start()] + body + text[m.end():]
    scene_xml.write_text(text, encoding="latin-1")


def ini_lines(path: Path) -> dict[str, str]:
    """The ``key=value`` lines of one of ``simtwo/settings/*.ini`` (comments and section lines skipped)."""
    out = {}
    for line in path.read_text().splitlines():
        line = line.strip()
        if not line or line.startswith((";", "#", "[")):
            continue
        key, sep, value = line.partition("=")
        if not sep:
            raise SceneError(f"{path}: not a key=value line: {line!r}")
        out[key.strip()] = value.strip()
    return out


def set_ini(path: Path, section: str, values: dict[str, str]) -> None:
    """Set ``values`` in ``[section]`` of ``path``, keeping every other line (SimTwo's ini files are flat:
    one section each); a key that is not there yet is added at the section's end."""
    text = path.read_bytes().decode("latin-1") if path.exists() else f"[{section}]\n"  # keeps CRLF
    nl = "\r\n" if "\r\n" in text else "\n"
    lines = text.splitlines()
    try:
        start = next(i for i, line in enumerate(lines) if line.strip() == f"[{section}]")
    except StopIteration:
        lines += [f"[{section}]"]
        start = len(lines) - 1
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("[")), len(lines))
    todo = dict(values)
    for i in range(start + 1, end):
        key = lines[i].partition("=")[0].strip()
        if key in todo:
            lines[i] = f"{key}={todo.pop(key)}"
    lines[end:end] = [f"{k}={v}" for k, v in todo.items()]
    path.write_bytes((nl.join(lines) + nl).encode("latin-1"))


def lidar_element() -> str:
    """The ``<ranger2d>`` element of ``simtwo/AGV_lidar.xml`` (its comment left out)."""
    text = (SIMTWO_DIR / "AGV_lidar.xml").read_text()
    m = re.search(r"^<ranger2d>.*?^</ranger2d>", text, re.S | re.M)
    if not m:
        raise SceneError("simtwo/AGV_lidar.xml has no <ranger2d> element at the start of a line")
    return m.group(0)


def install_lidar(agv_xml: Path) -> None:
    text = agv_xml.read_text(encoding="latin-1")
    if re.search(r"<ranger2d>\s*<ID value='ranger2d'", text):
        return  # already there
    # the last </sensors>: the robot's sensor list (comments above it may mention the tag too)
    i = text.rfind("</sensors>")
    if i < 0:
        raise SceneError(f"{agv_xml}: no </sensors> to put the LIDAR in")
    agv_xml.write_text(text[:i] + lidar_element() + "\n" + text[i:], encoding="latin-1")


#: the logical resolution SimTwo's GLScene turns the focal length (mm) into pixels with: run.py's Xvfb runs at
#: 96 dpi (Windows at 100 %), so fx = fy = 2 * focal length * 96 / 25.4 (docs/calibration.md)
CAMERA_DPI = 96.0
#: SimTwo's camera image (cameras.pas 13-14: CameraImageWidth = 320 * 2, CameraImageHeight = 240 * 2)
CAMERA_SIZE = (640, 480)


def focal_length_mm(fx: float, dpi: float = CAMERA_DPI) -> float:
    """The ``<focal length>`` (mm) GLScene renders ``fx`` pixels with at ``dpi``."""
    return fx * 25.4 / (2 * dpi)


def _camera_shell(text: str, where) -> re.Match:
    m = re.search(r"<camera>.*?</camera>", text, re.S)
    if not m:
        raise SceneError(f"{where}: no <camera> shell")
    return m


def _xyz(elem: str, tag: str, where) -> tuple[float, float, float]:
    m = re.search(rf"<{tag}\s+x=['\"]([^'\"]*)['\"]\s+y=['\"]([^'\"]*)['\"]\s+z=['\"]([^'\"]*)['\"]\s*/>", elem)
    if not m:
        raise SceneError(f"{where}: the <camera> shell has no <{tag} x= y= z=/>")
    try:
        return tuple(float(v) for v in m.groups())
    except ValueError:
        raise SceneError(f"{where}: the camera's <{tag}> is not three numbers: {m.group(0)}") from None


def scene_camera(agv_xml: Path) -> dict:
    """The ``<camera>`` shell of an AGV.xml: ``pos`` (m, on its solid), ``rot_deg`` and ``focal`` (mm)."""
    text = Path(agv_xml).read_text(encoding="latin-1")
    elem = _camera_shell(text, agv_xml).group(0)
    m = re.search(r"<focal\s+length=['\"]([^'\"]*)['\"]\s*/>", elem)
    return {"pos": _xyz(elem, "pos", agv_xml), "rot_deg": _xyz(elem, "rot_deg", agv_xml),
            "focal": float(m.group(1)) if m else 50.0}  # Viewer.pas 3326: 50 when the element is missing


class CalibrationConstraints(NamedTuple):
    """What ``raf calibrate`` is told of a renderer's camera: the parameters it holds at the robot file's values
    (``--hold``) and its square-pixel prior (``--aspect-sigma``, relative 1 sigma of fy/fx)."""

    hold: tuple[str, ...]
    aspect_sigma: float

    def calibrate_args(self) -> tuple[str, ...]:
        """The ``raf calibrate`` options that say it."""
        return (*(("--hold", ",".join(self.hold)) if self.hold else ()), "--aspect-sigma", f"{self.aspect_sigma:g}")

    def keys(self) -> dict:
        """The result keys that report it."""
        return {"calibration_held": ",".join(self.hold) or "none", "calibration_aspect_sigma": self.aspect_sigma}


#: ``raf calibrate`` on SimTwo. Held: the principal point (``cx, cy``): GLScene's frustum is symmetric, so it is
#: the image centre (:func:`camera_refusals`); held, the floor markers that SimTwo's calibration drive sees leave
#: no degenerate direction (docs/calibration.md). Square pixels (aspect sigma 1e-4): GLScene renders one focal
#: length, so fy = fx is a fact of the renderer, not a guess (held like OpenCV's CALIB_FIX_ASPECT_RATIO). The
#: drive pitches the camera about its x axis only, which leaves fy on a line with the pitch (correlation -0.997);
#: the default prior (0.005) let that line carry fy 0.6-1.1 % off where fx was 0.1-0.3 % (3 of 9 runs; tied: 5 of
#: 5 within 0.12 % and 0.07 deg, docs/calibration.md "Square pixels held on SimTwo")
SIMTWO_CALIBRATION = CalibrationConstraints(hold=("cx", "cy"), aspect_sigma=1e-4)


def camera_refusals(camera) -> list[str]:
    """Why SimTwo's GLScene camera cannot be ``camera`` (a robot file's CameraSpec): an ideal pinhole with a
    symmetric frustum (fx = fy, the principal point at the image's centre), 640 x 480, no roll (the camera's
    ``rot_deg`` is not mapped to a roll here). Empty when it can."""
    out = []
    w, h = CAMERA_SIZE
    if (camera.width, camera.height) != (w, h):
        out.append(f"image {camera.width} x {camera.height}: SimTwo's camera is {w} x {h} (cameras.pas)")
    if abs(camera.fx - camera.fy) > 1e-6 * abs(camera.fx):
        out.append(f"fx {camera.fx:g} != fy {camera.fy:g}: GLScene has one focal length (square pixels)")
    if abs(camera.cx - (w - 1) / 2) > 1e-3 or abs(camera.cy - (h - 1) / 2) > 1e-3:
        out.append(f"principal point ({camera.cx:g}, {camera.cy:g}) off the image centre ({(w - 1) / 2:g}, "
                   f"{(h - 1) / 2:g}): GLScene's frustum is symmetric")
    if any(abs(v) > 0 for v in camera.distortion):
        out.append(f"distortion {tuple(camera.distortion)}: GLScene renders an ideal pinhole")
    if abs(camera.roll_deg) > 1e-9:
        out.append(f"roll {camera.roll_deg:g} deg: not installed into the scene (only pitch and mount)")
    if not camera.bottom_up:
        out.append("bottom_up false: SimTwo's frames are bottom-up")
    return out


def camera_values(camera, nominal, scene: dict) -> dict:
    """The ``<camera>`` values that render ``camera``: the scene's minus the nominal robot's (``nominal``, the
    camera the unedited scene renders) plus ``camera``'s. ``pos`` is on the BasePlate solid (its centre 16.5 mm
    above the floor), so the mount moves by the difference; ``rot_deg`` x is 90 + the pitch down (120: 30
    degrees); the focal length from fx (:func:`focal_length_mm`)."""
    px, py, pz = scene["pos"]
    rx, ry, rz = scene["rot_deg"]
    d = [c - n for c, n in zip(camera.xyz, nominal.xyz)]
    return {"pos": (px + d[0], py + d[1], pz + d[2]),
            "rot_deg": (rx + camera.pitch_down_deg - nominal.pitch_down_deg, ry, rz),
            "focal": focal_length_mm(camera.fx), "decimation": int(camera.decimation)}


def install_camera(agv_xml: Path, camera, nominal=None) -> dict:
    """Write ``camera`` (a robot file's CameraSpec) into ``agv_xml``'s ``<camera>`` shell: focal length, pitch
    (``rot_deg`` x), mount (``pos``) and frame decimation, relative to ``nominal`` (default the shipped robot
    file's camera, which the unedited scene renders). SceneError lists what GLScene cannot render
    (:func:`camera_refusals`). Returns the values written."""
    if nominal is None:
        from ..robot import load_robot

        nominal = load_robot("simtwo").camera
    why = camera_refusals(camera)
    if why:
        raise SceneError("SimTwo's camera cannot render this robot file's camera: " + "; ".join(why))
    text = Path(agv_xml).read_text(encoding="latin-1")
    m = _camera_shell(text, agv_xml)
    v = camera_values(camera, nominal, scene_camera(agv_xml))
    elem = m.group(0)
    fmt = lambda t: " ".join(f"{a}='{c:.6f}'" for a, c in zip("xyz", t))  # noqa: E731
    elem = re.sub(r"<pos\s[^>]*/>", f"<pos {fmt(v['pos'])}/>", elem, count=1)
    elem = re.sub(r"<rot_deg\s[^>]*/>", f"<rot_deg {fmt(v['rot_deg'])}/>", elem, count=1)
    focal = f"<focal length='{v['focal']:.6f}'/>"
    elem, n = re.subn(r"<focal\s[^>]*/>", focal, elem, count=1)
    if not n:
        elem = elem.replace("</camera>", f"  {focal}\n    </camera>")
    frame = f"<frame decimation='{v['decimation']}'/>"
    elem, n = re.subn(r"<frame\s[^>]*/>", frame, elem, count=1)
    if not n:
        elem = elem.replace("</camera>", f"  {frame}\n    </camera>")
    Path(agv_xml).write_text(text[:m.start()] + elem + text[m.end():], encoding="latin-1")
    return v


def configure_script(text: str, s: SceneSettings) -> str:
    """The script with ``BRIDGE_IP`` and ``BRIDGE_PORT`` set, as step 2 tells a user to. Both or neither: a
    script with neither does not talk to the bridge (e.g. simtwo/linux/abi_check.pas) and is left as it is."""
    values = {"BRIDGE_IP": f"'{s.bridge_host}'", "BRIDGE_PORT": str(s.bridge_port)}
    found = {name for name in values if re.search(rf"^\s*{name}\s*=", text, re.M)}
    if found and found != set(values):
        missing = sorted(set(values) - found)[0]
        raise SceneError(f"the script has no constant {missing} to set (simtwo/control.pas defines it)")
    for name in found:
        text = re.sub(rf"^(\s*{name}\s*=\s*)[^;]*;", lambda m, v=values[name]: m.group(1) + v + ";", text,
                      count=1, flags=re.M)
    return text


def install(simtwo_dir: Path, dest: Path, settings: SceneSettings | None = None,
            scene: str = DEFAULT_SCENE, headless: bool = True) -> Path:
    """Copy ``simtwo_dir/scene`` to ``dest`` (which must not exist) and install the project's side into it.
    Returns ``dest``."""
    s = settings or SceneSettings()
    if s.camera is not None and camera_refusals(s.camera):  # before anything is copied
        raise SceneError("SimTwo's camera cannot render this robot file's camera: "
                         + "; ".join(camera_refusals(s.camera)))
    src = Path(simtwo_dir) / scene
    if not (src / "scene.xml").exists():
        known = sorted(p.name for p in Path(simtwo_dir).iterdir() if (p / "scene.xml").exists())
        raise SceneError(f"no scene {scene!r} in {simtwo_dir} (scenes: {', '.join(known)})")
    dest = Path(dest)
    shutil.copytree(src, dest)
    script = configure_script(Path(s.script).read_text(encoding="latin-1"), s)
    (dest / "control.pas").write_text(script, encoding="latin-1")
    if s.lidar:
        install_lidar(dest / "AGV.xml")
    if s.camera is not None:
        install_camera(dest / "AGV.xml", s.camera)
    if s.parts is not None:
        place_parts(dest / "scene.xml", s.parts)
    params = ini_lines(SIMTWO_DIR / "settings" / "config_Params.ini")
    params["EditUDPPort_Text"] = str(s.udp_port)
    set_ini(dest / "config_Params.ini", "Config", params)
    cameras = ini_lines(SIMTWO_DIR / "settings" / "config_Cameras.ini")
    if headless:
        cameras.update(CAMERAS_WINDOW)
        set_ini(dest / "config_Viewer.ini", "Viewer", VIEWER_WINDOW)
    set_ini(dest / "config_Cameras.ini", "Cameras", cameras)
    for name, values in s.extra_ini.items():  # each of SimTwo's ini files has one section
        m = re.search(r"^\[(\w+)\]", (dest / name).read_text(encoding="latin-1"), re.M)
        if not m:
            raise SceneError(f"{name}: not one of the scene's ini files")
        set_ini(dest / name, m.group(1), values)
    return dest
