"""A fresh copy of a SimTwo scene with the project's script, LIDAR and settings installed.

What docs/simtwo.md's "Step by step (Windows)" tells a user to do by hand, done to a copy (SimTwo rewrites
its scene's ``config_*.ini`` when it exits, so every run gets its own):

- ``control.pas`` <- ``simtwo/control.pas``, with ``BRIDGE_IP`` / ``BRIDGE_PORT`` set (step 2);
- ``AGV.xml`` gets the ``<ranger2d>`` element of ``simtwo/AGV_lidar.xml`` inside ``<sensors>`` (step 3);
- ``config_Params.ini`` [Config] and ``config_Cameras.ini`` [Cameras] get the lines of
  ``simtwo/settings/*.ini`` (steps 4-5), with SimTwo's UDP port set;
- headless only: the Cameras window is placed where no other window covers it (a covered or off-screen
  OpenGL window reads back black).
"""
from __future__ import annotations

import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path

from ..simtwo.ports import BRIDGE_UDP_PORT, LOCALHOST, SIMTWO_UDP_PORT

ROOT = Path(__file__).resolve().parents[3]
SIMTWO_DIR = ROOT / "simtwo"
DEFAULT_SCENE = "RobotFactoryPro2022"
#: where the Cameras window goes on the virtual screen (right of every window SimTwo's scene opens)
CAMERAS_WINDOW = {"FCameras_Left": "1700", "FCameras_Top": "0"}


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
    text = path.read_text(encoding="latin-1") if path.exists() else f"[{section}]\n"
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
    path.write_text(nl.join(lines) + nl, encoding="latin-1")


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


def configure_script(text: str, s: SceneSettings) -> str:
    """``control.pas`` with ``BRIDGE_IP`` and ``BRIDGE_PORT`` set, as step 2 tells a user to."""
    for name, value in (("BRIDGE_IP", f"'{s.bridge_host}'"), ("BRIDGE_PORT", str(s.bridge_port))):
        text, n = re.subn(rf"^(\s*{name}\s*=\s*)[^;]*;", lambda m, v=value: m.group(1) + v + ";", text,
                          count=1, flags=re.M)
        if n != 1:
            raise SceneError(f"the script has no constant {name} to set (simtwo/control.pas defines it)")
    return text


def install(simtwo_dir: Path, dest: Path, settings: SceneSettings | None = None,
            scene: str = DEFAULT_SCENE, headless: bool = True) -> Path:
    """Copy ``simtwo_dir/scene`` to ``dest`` (which must not exist) and install the project's side into it.
    Returns ``dest``."""
    s = settings or SceneSettings()
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
    params = ini_lines(SIMTWO_DIR / "settings" / "config_Params.ini")
    params["EditUDPPort_Text"] = str(s.udp_port)
    set_ini(dest / "config_Params.ini", "Config", params)
    cameras = ini_lines(SIMTWO_DIR / "settings" / "config_Cameras.ini")
    if headless:
        cameras.update(CAMERAS_WINDOW)
    set_ini(dest / "config_Cameras.ini", "Cameras", cameras)
    for name, values in s.extra_ini.items():  # each of SimTwo's ini files has one section
        m = re.search(r"^\[(\w+)\]", (dest / name).read_text(encoding="latin-1"), re.M)
        if not m:
            raise SceneError(f"{name}: not one of the scene's ini files")
        set_ini(dest / name, m.group(1), values)
    return dest
