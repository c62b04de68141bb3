"""What SimTwo built for its RobotAtFactory scene, read back from SimTwo, against the project's field model.

``raf simtwo field`` and ``tests/test_simtwo_field.py``. One SimTwo start runs ``simtwo/linux/field_dump.pas``
(this module writes its probe block from the field model) and parses its ``FIELD`` lines:

- every obstacle SimTwo built: the centre and rotation matrix of its ODE geometry, by index (the script API
  has no count, ID or size getter: the script reads until the index is out of range and looks the scene's
  IDs up with ``GetObstacleIndex``); sizes come from the scene's XML (:func:`scene_obstacles`) and are checked
  by the two measurements below;
- the robots before anything moves: the AGV (the start pose) and the parts Part1..Part4;
- slot probes: Part1 set down at each slot of the model (``SetRobotPos``, the part's plate towards the slot's
  ``facing``) and where it stands 0.48 s later: a wall or rib where the model has none pushes it away;
- robot probes: the AGV set down in front of the warehouses and the machines; its LIDAR sweep (the faces its
  rays meet at 0.05 m, compared with the model's boxes cast the same way) and a camera frame (the markers
  OpenCV finds, compared with the model's corners projected through the robot's camera).

:func:`compare` lists every difference between the two with its size; :data:`TOL_M` and friends say how
much is tolerated (and why).
"""
from __future__ import annotations

import ast
import math
import operator
import re
import socket
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field as dc_field
from pathlib import Path
from typing import Callable

import numpy as np

from ..simtwo.ports import LOCALHOST
from .scene import DEFAULT_SCENE, SIMTWO_DIR

SCRIPT = SIMTWO_DIR / "linux" / "field_dump.pas"
READY_LINE = "script: FIELD start"
DONE_LINE = "script: FIELD done"
#: the map's z = 0 is the top of SimTwo's 1 mm field cuboid (docs/field.md): SimTwo's world z minus this
FIELD_TOP_Z = 0.001

#: positions (centres, faces, extents, the start pose): SimTwo's values are the doubles of its ODE geometries,
#: exact; the model writes its numbers to 0.5 mm (a marker face at 0.5695 m is 0.569). 1 mm is ~0.45 px for a
#: wall marker 0.5 m from the camera and below the LIDAR's noise at 0 m (1.5 mm): a real difference in the
#: model shows, its rounding does not
TOL_M = 0.001
#: headings and marker normals / in-plane rotations
TOL_DEG = 1.0
#: a part set down at a slot: how far it may move while it settles (SimTwo's parts sink ~1 mm into their soft
#: feet and creep 1.5 mm when the scene starts; a rib or wall in the slot moves it centimetres)
SLOT_MOVE_M = 0.003
SLOT_TURN_DEG = 2.0
#: LIDAR: the median |measured - model| range per probe (SimTwo's rays are exact; the robot's pose is read
#: at the end of the sweep) and the share of rays within LIDAR_RAY_M (rays grazing an edge may flip)
LIDAR_MEDIAN_M = 0.001
LIDAR_RAY_M = 0.003
LIDAR_SHARE = 0.95
#: camera: mean corner error of a found marker against the model's projection, pixels. The camera is there
#: for what the geometry cannot say (which face reads, the in-plane turn, whether a marker is found at all:
#: tens of pixels); positions are checked above to 1 mm. Measured: 2.1-2.7 px on floor markers whose
#: positions the field texture gives to 0.04 mm, i.e. the robot's camera model (robot_simtwo.json) against
#: SimTwo's GLScene camera, not the field; 5 px is twice that
CAMERA_PX = 5.0
#: the frame taken for a camera line: the second received after it (the first may have been rendered before)
FRAMES_AFTER_LINE = 2


# ---------------------------------------------------------------------------------------------- the dump
@dataclass
class Obstacle:
    index: int
    pos: np.ndarray            # centre, SimTwo's world (m)
    rot: np.ndarray            # 3x3 world <- obstacle
    color: tuple[int, int, int]
    id: str = ""               # from GetObstacleIndex of the scene's IDs ("" if none named it)


@dataclass
class RobotPose:
    id: str
    index: int
    x: float = math.nan
    y: float = math.nan
    z: float = math.nan
    theta: float = math.nan


@dataclass
class SlotProbe:
    name: str
    x: float
    y: float
    theta: float
    x0: float
    y0: float
    theta0: float


@dataclass
class LidarProbe:
    name: str
    x: float
    y: float
    theta: float
    ranges: np.ndarray


@dataclass
class CameraProbe:
    name: str
    x: float
    y: float
    theta: float
    frame: np.ndarray | None = None   # BGR, top row first


@dataclass
class Dump:
    robots: dict[str, RobotPose] = dc_field(default_factory=dict)      # at the first script call
    robots0: dict[str, RobotPose] = dc_field(default_factory=dict)     # in Initialize
    obstacles: list[Obstacle] = dc_field(default_factory=list)
    count: int = -1
    slots: dict[str, SlotProbe] = dc_field(default_factory=dict)
    lidar: dict[str, LidarProbe] = dc_field(default_factory=dict)
    camera: dict[str, CameraProbe] = dc_field(default_factory=dict)
    done: bool = False

    def obstacle(self, sid: str) -> Obstacle | None:
        return next((o for o in self.obstacles if o.id == sid), None)


def parse(lines: list[str]) -> Dump:
    """The ``FIELD`` lines of field_dump.pas (with or without run.py's ``script: `` prefix)."""
    d = Dump()
    names: dict[str, int] = {}
    for line in lines:
        if line.startswith("script: "):
            line = line[len("script: "):]
        p = line.split()
        if len(p) < 2 or p[0] != "FIELD":
            continue
        kind, a = p[1], p[2:]
        if kind in ("robot", "robot0"):
            r = RobotPose(a[0], int(a[1]))
            if r.index >= 0:
                r.x, r.y, r.z, r.theta = map(float, a[2:6])
            (d.robots if kind == "robot" else d.robots0)[r.id] = r
        elif kind == "obstacle":
            v = [float(x) for x in a[1:13]]
            d.obstacles.append(Obstacle(int(a[0]), np.array(v[:3]), np.array(v[3:12]).reshape(3, 3),
                                        tuple(int(x) for x in a[13:16])))
        elif kind == "obstacles":
            d.count = int(a[0])
        elif kind == "name":
            names[a[0]] = int(a[1])
        elif kind == "slot":
            d.slots[a[0]] = SlotProbe(a[0], *map(float, a[1:7]))
        elif kind == "lidar":
            n = int(a[4])
            r = np.array([float(x) for x in a[5].split(";")]) if n > 0 else np.zeros(0)
            d.lidar[a[0]] = LidarProbe(a[0], float(a[1]), float(a[2]), float(a[3]), r)
        elif kind == "camera":
            d.camera[a[0]] = CameraProbe(a[0], float(a[1]), float(a[2]), float(a[3]))
        elif kind == "done":
            d.done = True
    by_index = {o.index: o for o in d.obstacles}
    for sid, i in names.items():
        if i in by_index:
            by_index[i].id = sid
    return d


# ---------------------------------------------------------------------------------------------- probes
@dataclass(frozen=True)
class Probe:
    kind: int        # 0: Part1 set down at a slot; 1: the AGV set down (LIDAR sweep and camera frame)
    name: str
    x: float
    y: float
    theta: float     # SimTwo's heading (SetRobotPos)


def probes(fld) -> list[Probe]:
    """Part1 at every slot of the model; the AGV 0.30-0.35 m in front of each warehouse (at each slot's x)
    and of each machine face, looking at it."""
    from ..simtwo.teleport import part_heading

    out = [Probe(0, s.name, s.xy[0], s.xy[1], part_heading(s.facing)) for s in fld.slots]
    for s in fld.slots:
        if s.zone in ("incoming", "outgoing"):
            # in front of the slot, looking into it (towards the back wall): against the plate's facing
            x = s.xy[0] + 0.235 * math.cos(s.facing)
            y = s.xy[1] + 0.235 * math.sin(s.facing)
            out.append(Probe(1, f"front_{s.name}", x, y, math.remainder(s.facing + math.pi, 2 * math.pi)))
    for zone in ("machine_A", "machine_B"):
        slots = fld.slots_of(zone)
        cy = sum(s.xy[1] for s in slots) / len(slots)
        for s in slots[:2]:  # one input (faces -x) and one output (faces +x) slot: the two faces
            side = "west" if math.cos(s.facing) < 0 else "east"
            x = s.xy[0] + 0.30 * math.cos(s.facing)
            out.append(Probe(1, f"{zone}_{side}", x, cy, math.remainder(s.facing + math.pi, 2 * math.pi)))
    return out


def script_text(fld, template: Path = SCRIPT, probe_list: list[Probe] | None = None) -> str:
    """field_dump.pas with its probe block written from ``fld`` (or ``probe_list``)."""
    text = template.read_text(encoding="latin-1")
    ps = probes(fld) if probe_list is None else probe_list
    body = ["function ProbeCount: integer;", "begin", f"  result := {len(ps)};", "end;", "",
            "function SetProbe(n: integer): integer;", "begin", "  result := 0;"]
    for i, p in enumerate(ps):
        body.append(f"  if n = {i} then begin PName := '{p.name}'; PX := {p.x:.6f}; PY := {p.y:.6f}; "
                    f"PTh := {p.theta:.6f}; result := {p.kind}; end;")
    body.append("end;")
    new, n = re.subn(r"// BEGIN PROBES\n.*?// END PROBES", lambda _m: "// BEGIN PROBES (fielddump.py)\n" +
                     "\n".join(body) + "\n// END PROBES", text, flags=re.S)
    if n != 1:
        raise ValueError(f"{template}: no BEGIN PROBES ... END PROBES block")
    return new


# ---------------------------------------------------------------------------------------------- the scene's XML
_OPS = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
        ast.USub: operator.neg, ast.UAdd: operator.pos}


def evaluate(expr: str, consts: dict[str, float]) -> float:
    """A SimTwo XML value (``'4 * cell_x + wall_thickness'``) with the defines so far."""
    def ev(n):
        if isinstance(n, ast.Expression):
            return ev(n.body)
        if isinstance(n, ast.Constant) and isinstance(n.value, (int, float)):
            return float(n.value)
        if isinstance(n, ast.Name):
            if n.id not in consts:
                raise ValueError(f"{expr!r}: {n.id} is not defined")
            return consts[n.id]
        if isinstance(n, ast.BinOp) and type(n.op) in _OPS:
            return _OPS[type(n.op)](ev(n.left), ev(n.right))
        if isinstance(n, ast.UnaryOp) and type(n.op) in _OPS:
            return _OPS[type(n.op)](ev(n.operand))
        raise ValueError(f"{expr!r}: not a SimTwo expression")
    return ev(ast.parse(expr.strip(), mode="eval"))


def _defines(node, consts: dict[str, float]) -> None:
    for d in node.iter("defines"):
        for c in d.iter("const"):
            consts[c.get("name")] = evaluate(c.get("value"), consts)


@dataclass(frozen=True)
class SceneObstacle:
    id: str              # as SimTwo names it: the scene's <obstacle> ID followed by the cuboid's
    file: str
    shape: str           # cuboid, cylinder, sphere
    size: tuple[float, float, float]
    texture: str         # '' or the texture file (5x5_1000-NN.png: ArUco marker NN)

    @property
    def marker_id(self) -> int | None:
        m = re.match(r"5x5_1000-(\d+)\.png$", self.texture)
        return int(m.group(1)) if m else None


def scene_obstacles(scene_dir: Path) -> list[SceneObstacle]:
    """The obstacles ``scene.xml`` loads, with the sizes its files give (SimTwo's script cannot read them)."""
    consts: dict[str, float] = {}
    root = ET.parse(scene_dir / "scene.xml").getroot()
    out = []
    for el in root:
        if el.tag == "defines":
            _defines(_wrap(el), consts)
        if el.tag not in ("obstacle", "obstacles"):
            continue
        prefix = (el.find("ID").get("name", "") if el.find("ID") is not None else "")
        body = el.find("body")
        fname = body.get("file") if body is not None else el.get("file")
        local = dict(consts)
        sub = ET.parse(scene_dir / fname).getroot()
        for node in sub:
            if node.tag == "defines":
                _defines(_wrap(node), local)
            if node.tag not in ("cuboid", "cylinder", "sphere"):
                continue
            sid = node.find("ID").get("value", "") if node.find("ID") is not None else ""
            s = node.find("size")
            size = tuple(evaluate(s.get(k, "0"), local) for k in "xyz") if s is not None else (0.0, 0.0, 0.0)
            t = node.find("texture")
            out.append(SceneObstacle(prefix + sid, fname, node.tag, size, t.get("name", "") if t is not None else ""))
    return out


def _wrap(defines_node):
    w = ET.Element("wrap")
    w.append(defines_node)
    return w


# ---------------------------------------------------------------------------------------------- running it
def run_dump(fld, build=None, timeout: float = 240.0, keep: Path | None = None,
             progress: Callable[[str], None] = lambda _m: None, probe_list: list[Probe] | None = None,
             robot_camera=None) -> Dump:
    """One SimTwo start with field_dump.pas (probes from ``fld``); its lines and camera frames parsed.
    ``robot_camera``: a robot file's camera installed into the scene's AGV.xml (scene.install_camera)."""
    import zmq

    from . import build as b
    from .run import Ports, SimTwoRun

    build = build or b.require()
    tmp = Path(tempfile.mkdtemp(prefix="raf-fielddump-"))
    script = tmp / "field_dump.pas"
    script.write_text(script_text(fld, probe_list=probe_list), encoding="latin-1")
    run = SimTwoRun(build, Ports.free(), camera=True, script=script, ready_line=READY_LINE, workdir=keep,
                    keep=keep is not None, progress=progress, robot_camera=robot_camera)
    frames: dict[str, np.ndarray] = {}
    sub = udp = None
    try:
        run.start(timeout=90)
        sub = zmq.Context.instance().socket(zmq.SUB)
        sub.setsockopt(zmq.SUBSCRIBE, b"")
        sub.setsockopt(zmq.LINGER, 0)
        sub.connect(f"tcp://127.0.0.1:{run.ports.camera}")
        udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        end = time.monotonic() + timeout
        seen: set[str] = set()
        pending: dict[str, int] = {}   # camera line's probe -> frames received since the line
        while True:
            run.check()
            msgs = run.messages()
            for m in msgs:
                if m.startswith("script: FIELD camera ") and m not in seen:
                    seen.add(m)
                    pending[m.split()[3]] = 0
                    while sub.poll(0):   # frames queued before the line was read were rendered before it
                        sub.recv()
            while sub.poll(20):
                data = sub.recv()
                for name in list(pending):
                    # the first frame received after the line may have been rendered before it (a software
                    # camera takes ~1 s a frame); the second was rendered after the first was sent. The robot
                    # stands still until told to go on.
                    pending[name] += 1
                    if pending[name] >= FRAMES_AFTER_LINE:
                        frames[name] = data
                        del pending[name]
                        udp.sendto(f"FIELD next {name};".encode(), (LOCALHOST, run.ports.udp))
            if DONE_LINE in msgs and not pending:
                break
            if time.monotonic() > end:
                raise TimeoutError("field_dump.pas did not finish; SimTwo's messages:\n" + "\n".join(msgs[-20:]))
        lines = run.messages()
    finally:
        if sub is not None:
            sub.close()
        if udp is not None:
            udp.close()
        run.stop()
        import shutil

        shutil.rmtree(tmp, ignore_errors=True)
    d = parse(lines)
    from ..simtwo.camera import decode_frame

    for name, data in frames.items():
        if name in d.camera:
            d.camera[name].frame = decode_frame(data)
            if keep is not None:
                import cv2

                cv2.imwrite(str(Path(keep) / f"camera_{name}.png"), d.camera[name].frame)
    return d


# ---------------------------------------------------------------------------------------------- comparing
@dataclass(frozen=True)
class Difference:
    what: str        # wall, marker, slot, start, floor, lidar, camera, obstacle
    name: str
    quantity: str    # e.g. "ymin", "centre y", "normal", "in-plane"
    simtwo: float
    model: float
    unit: str = "m"
    note: str = ""

    @property
    def size(self) -> float:
        return self.simtwo - self.model

    def __str__(self) -> str:
        k = 1000.0 if self.unit == "m" else 1.0
        u = "mm" if self.unit == "m" else self.unit
        s = (f"{self.what} {self.name} {self.quantity}: SimTwo {self.simtwo * k:.1f} {u}, model "
             f"{self.model * k:.1f} {u} (difference {self.size * k:+.1f} {u})")
        return s + (f": {self.note}" if self.note else "")


@dataclass
class Report:
    differences: list[Difference] = dc_field(default_factory=list)
    notes: list[str] = dc_field(default_factory=list)
    checked: dict[str, int] = dc_field(default_factory=dict)

    def add(self, d: Difference) -> None:
        self.differences.append(d)

    def count(self, what: str, n: int = 1) -> None:
        self.checked[what] = self.checked.get(what, 0) + n


def _aabb(o: Obstacle, size) -> tuple[np.ndarray, np.ndarray]:
    half = np.abs(o.rot) @ (np.asarray(size) / 2)
    return o.pos - half, o.pos + half


#: scene obstacle ID prefix -> the model's box prefix
WAREHOUSES = {"incoming_whareouse_": "incoming_wh", "output_whareouse_": "outgoing_wh"}
MACHINES = {"Machines_A_": "machine_A", "Machines_B_": "machine_B"}


def _group(scene: list[SceneObstacle], dump: Dump) -> dict[str, list[tuple[Obstacle, SceneObstacle]]]:
    """The model's box name -> SimTwo's obstacles that make it (the warehouse back wall and the machine central
    wall are two stacked cuboids in SimTwo, one box in the model; ribs are numbered along x / y)."""
    by_id = {s.id: s for s in scene}
    groups: dict[str, list] = {}
    for prefix, model in WAREHOUSES.items():
        ribs = [f"{prefix}{n}" for n in ("right_wall", "left_wall", "inside_wall_1", "inside_wall_2", "inside_wall_3")]
        got = [(dump.obstacle(r), by_id[r]) for r in ribs if dump.obstacle(r) and r in by_id]
        got.sort(key=lambda t: t[0].pos[0])
        for k, t in enumerate(got):
            groups[f"{model}_rib{k}"] = [t]
        groups[f"{model}_back_wall"] = [(dump.obstacle(prefix + n), by_id[prefix + n])
                                        for n in ("back_wall", "back_wall_marker")
                                        if dump.obstacle(prefix + n) and prefix + n in by_id]
    for prefix, model in MACHINES.items():
        ribs = [f"{prefix}{n}" for n in ("left_wall", "center_wall", "right_wall")]
        got = [(dump.obstacle(r), by_id[r]) for r in ribs if dump.obstacle(r) and r in by_id]
        got.sort(key=lambda t: t[0].pos[1])
        for k, t in enumerate(got):
            groups[f"{model}_rib{k}"] = [t]
        groups[f"{model}_center_wall"] = [(dump.obstacle(prefix + n), by_id[prefix + n])
                                          for n in ("back_wall", "back_wall_marker_support")
                                          if dump.obstacle(prefix + n) and prefix + n in by_id]
    return groups


def compare(dump: Dump, fld, scene_dir: Path, robot=None, camera: bool = True) -> Report:
    """Every difference between what SimTwo built (``dump``, sizes from ``scene_dir``'s XML) and ``fld``.
    ``camera=False``: a dump without its camera frames (a recorded one): no camera check."""
    rep = Report()
    scene = scene_obstacles(scene_dir)
    by_id = {s.id: s for s in scene}
    if not dump.done:
        rep.add(Difference("dump", "field_dump.pas", "finished", 0, 1, "", "the script did not finish"))
    if dump.count != len(dump.obstacles) or dump.count <= 0:
        rep.add(Difference("dump", "obstacles", "count", len(dump.obstacles), dump.count, ""))
    for o in dump.obstacles:
        if not o.id or o.id not in by_id:
            rep.add(Difference("obstacle", f"#{o.index}", "unknown", 1, 0, "",
                               f"SimTwo built an obstacle no scene ID names, at ({o.pos[0]:.4f}, {o.pos[1]:.4f}, "
                               f"{o.pos[2]:.4f})"))
    for s in scene:
        if dump.obstacle(s.id) is None:
            rep.add(Difference("obstacle", s.id, "missing", 0, 1, "", "in the scene's files, not in SimTwo"))
    _compare_boxes(dump, fld, scene, rep)
    _compare_floor(dump, fld, by_id, rep)
    _compare_markers(dump, fld, scene, rep)
    _compare_start(dump, fld, rep)
    _compare_slots(dump, fld, rep)
    _compare_lidar(dump, fld, rep, robot)
    if camera:
        _compare_camera(dump, fld, rep, robot)
    return rep


def _compare_boxes(dump, fld, scene, rep) -> None:
    groups = _group(scene, dump)
    model = {b.name: b for b in fld.boxes}
    for name in sorted(set(groups) | set(model)):
        if name not in model:
            rep.add(Difference("wall", name, "missing", 1, 0, "", "SimTwo has it, the model does not"))
            continue
        if not groups.get(name):
            rep.add(Difference("wall", name, "missing", 0, 1, "", "the model has it, SimTwo does not"))
            continue
        lo = np.min([_aabb(o, s.size)[0] for o, s in groups[name]], axis=0)
        hi = np.max([_aabb(o, s.size)[1] for o, s in groups[name]], axis=0)
        b = model[name]
        if abs(math.remainder(b.yaw, math.pi / 2)) > 1e-9:
            rep.add(Difference("wall", name, "yaw", 0, math.degrees(b.yaw), "deg"))
        c, h = np.asarray(b.center), np.asarray(b.size) / 2
        if abs(math.remainder(b.yaw, math.pi)) > 1e-9:  # turned 90 degrees: x and y sizes swap
            h = h[[1, 0, 2]]
        mlo, mhi = c - h, c + h
        mlo[2] += FIELD_TOP_Z
        mhi[2] += FIELD_TOP_Z
        # nothing below the field's surface counts (a rib from z = 0 and one from the surface are the same wall)
        lo[2], mlo[2] = max(lo[2], FIELD_TOP_Z), max(mlo[2], FIELD_TOP_Z)
        rep.count("wall")
        for k, axis in enumerate("xyz"):
            for q, sv, mv in (("min", lo[k], mlo[k]), ("max", hi[k], mhi[k])):
                if abs(sv - mv) > TOL_M:
                    rep.add(Difference("wall", name, f"{axis}{q}", sv, mv))
        for o, _s in groups[name]:
            yaw = math.atan2(o.rot[1, 0], o.rot[0, 0])
            if abs(math.remainder(yaw, math.pi / 2)) > math.radians(TOL_DEG):
                rep.add(Difference("wall", o.id, "yaw", math.degrees(yaw), 0, "deg", "not axis-aligned"))


def _compare_floor(dump, fld, by_id, rep) -> None:
    o = dump.obstacle("fieldfield_pro")
    if o is None or "fieldfield_pro" not in by_id:
        rep.add(Difference("floor", "field_pro", "missing", 0, 1, ""))
        return
    lo, hi = _aabb(o, by_id["fieldfield_pro"].size)
    rep.count("floor")
    for q, sv, mv in (("xmin", lo[0], fld.floor.x[0]), ("xmax", hi[0], fld.floor.x[1]),
                      ("ymin", lo[1], fld.floor.y[0]), ("ymax", hi[1], fld.floor.y[1]),
                      ("top z", hi[2], FIELD_TOP_Z)):
        if abs(sv - mv) > TOL_M:
            rep.add(Difference("floor", "field_pro", q, sv, mv))


def marker_frame(o: Obstacle, thickness: float) -> tuple[np.ndarray, np.ndarray]:
    """The printed face's centre and the marker frame (columns x right, y to the top edge, z out of the face)
    of a SimTwo marker plate, in SimTwo's world.

    ``TSolid.SetTexture`` (ODERobots.pas 922-961) maps the texture object-linearly: s = +y, t = -x of the
    plate, centred (offset 0.5); GLScene uploads images bottom row first, so t grows towards the image's top,
    and the 5x5_1000-NN.png images are upright (OpenCV finds each with its top-left corner at the image's
    top-left). So the marker's right is the plate's +y, its top the plate's -x, and it reads correctly from
    the plate's +z side (from the -z side the image is mirrored)."""
    R = np.column_stack([o.rot[:, 1], -o.rot[:, 0], o.rot[:, 2]])
    return o.pos + o.rot[:, 2] * thickness / 2, R


def _against_wall(point: np.ndarray, dump: Dump, scene: list[SceneObstacle]) -> bool:
    """Whether ``point`` (SimTwo's world) lies inside one of SimTwo's walls (not a marker plate, not the field)."""
    for s in scene:
        o = dump.obstacle(s.id)
        if o is None or s.marker_id is not None or s.id == "fieldfield_pro":
            continue
        lo, hi = _aabb(o, s.size)
        if np.all(point >= lo) and np.all(point <= hi):
            return True
    return False


def _compare_markers(dump, fld, scene, rep) -> None:
    seen = set()
    for s in scene:
        mid = s.marker_id
        if mid is None or dump.obstacle(s.id) is None:
            continue
        seen.add(mid)
        centre, R = marker_frame(dump.obstacle(s.id), s.size[2])
        if _against_wall(centre + R[:, 2] * 0.003, dump, scene):
            # the face that reads correctly lies against the wall: from the field the marker is mirrored and no
            # ArUco detector finds it; the model must not have it (a robot would expect to see it)
            rep.count("mirrored marker")
            if fld.has_marker(mid):
                rep.add(Difference("marker", str(mid), "readable", 0, 1, "",
                                   f"{s.id}: the face that reads correctly looks {_dir(R[:, 2])}, into its wall: "
                                   "from the field SimTwo shows it mirrored (no detector finds it); the model has it"))
            continue
        if not fld.has_marker(mid):
            rep.add(Difference("marker", str(mid), "missing", 1, 0, "", f"SimTwo's {s.id}; the model has no {mid}"))
            continue
        m = fld.marker(mid)
        centre = centre - [0, 0, FIELD_TOP_Z]
        rep.count("marker")
        for k, axis in enumerate("xyz"):
            if abs(centre[k] - m.position[k]) > TOL_M:
                rep.add(Difference("marker", str(mid), f"centre {axis}", centre[k], m.position[k], note=s.id))
        side = max(s.size[0], s.size[1])
        if abs(side - m.size) > TOL_M:
            rep.add(Difference("marker", str(mid), "plate side", side, m.size, note=s.id))
        normal = math.degrees(math.acos(float(np.clip(R[:, 2] @ m.normal, -1, 1))))
        if normal > TOL_DEG:
            rep.add(Difference("marker", str(mid), "normal", normal, 0, "deg",
                               f"{s.id}: the face that reads correctly looks {_dir(R[:, 2])}, the model's "
                               f"{_dir(m.normal)}"))
            continue
        Rm = m.rotation
        inplane = math.degrees(math.atan2(float(np.cross(Rm[:, 0], R[:, 0]) @ Rm[:, 2]), float(Rm[:, 0] @ R[:, 0])))
        if abs(inplane) > TOL_DEG:
            rep.add(Difference("marker", str(mid), "in-plane", inplane, 0, "deg",
                               f"{s.id}: its top edge points {_dir(R[:, 1])}, the model's {_dir(Rm[:, 1])}"))
    for m in fld.wall_markers():
        if m.id not in seen:
            rep.add(Difference("marker", str(m.id), "missing", 0, 1, "", "the model has it, SimTwo does not"))


def _dir(v) -> str:
    names = ["+x", "-x", "+y", "-y", "+z", "-z"]
    k = int(np.argmax(np.abs(v)))
    return names[2 * k + (0 if v[k] > 0 else 1)]


def _compare_start(dump, fld, rep) -> None:
    r = dump.robots0.get("AGV") or dump.robots.get("AGV")
    if r is None or r.index < 0:
        rep.add(Difference("start", "AGV", "missing", 0, 1, ""))
        return
    sp = fld.start_pose
    rep.count("start")
    for q, sv, mv in (("x", r.x, sp.x), ("y", r.y, sp.y)):
        if abs(sv - mv) > TOL_M:
            rep.add(Difference("start", "AGV", q, sv, mv))
    dth = math.degrees(math.remainder(r.theta - sp.theta, 2 * math.pi))
    if abs(dth) > TOL_DEG:
        rep.add(Difference("start", "AGV", "heading", math.degrees(sp.theta) + dth, math.degrees(sp.theta), "deg"))


def _compare_slots(dump, fld, rep) -> None:
    from ..simtwo.teleport import part_heading

    for s in fld.slots:
        p = dump.slots.get(s.name)
        if p is None:
            rep.add(Difference("slot", s.name, "probe", 0, 1, "", "no probe result"))
            continue
        rep.count("slot")
        moved = math.hypot(p.x - s.xy[0], p.y - s.xy[1])
        turned = math.degrees(math.remainder(p.theta - part_heading(s.facing), 2 * math.pi))
        if moved > SLOT_MOVE_M:
            for q, sv, mv in (("x", p.x, s.xy[0]), ("y", p.y, s.xy[1])):
                if abs(sv - mv) > TOL_M:
                    rep.add(Difference("slot", s.name, f"part {q}", sv, mv, note="a part set down there moved"))
        if abs(turned) > SLOT_TURN_DEG:
            rep.add(Difference("slot", s.name, "part heading", turned, 0, "deg", "a part set down there turned"))
    # the slots between ribs: their x midway between SimTwo's ribs' inner faces
    for zone, prefix in (("incoming", "incoming_wh"), ("outgoing", "outgoing_wh")):
        ribs = sorted((b for b in fld.boxes if b.name.startswith(prefix + "_rib")), key=lambda b: b.center[0])
        for s in fld.slots_of(zone):
            left = max((b for b in ribs if b.center[0] < s.xy[0]), key=lambda b: b.center[0], default=None)
            right = min((b for b in ribs if b.center[0] > s.xy[0]), key=lambda b: b.center[0], default=None)
            if left is None or right is None:
                continue
            a = dump.obstacle(_rib_id(dump, left.center[0], prefix))
            b = dump.obstacle(_rib_id(dump, right.center[0], prefix))
            if a is None or b is None:
                continue
            mid = (a.pos[0] + b.pos[0]) / 2  # ribs of equal thickness: the gap's centre
            rep.count("slot gap")
            if abs(mid - s.xy[0]) > TOL_M:
                rep.add(Difference("slot", s.name, "x (between SimTwo's ribs)", mid, s.xy[0]))
    # where the scene's own file puts its parts (informational: they are not slot definitions)
    for pid, r in sorted(dump.robots0.items()):
        if not pid.startswith("Part") or r.index < 0:
            continue
        s = min(fld.slots, key=lambda s: math.hypot(s.xy[0] - r.x, s.xy[1] - r.y))
        rep.notes.append(f"SimTwo has {pid} (scene.xml) at ({r.x:.4f}, {r.y:.4f}), heading "
                         f"{math.degrees(r.theta):.1f} deg: "
                         f"{1000 * (r.x - s.xy[0]):+.1f} mm in x, {1000 * (r.y - s.xy[1]):+.1f} mm in y of slot "
                         f"{s.name}")


def _rib_id(dump: Dump, x: float, prefix: str) -> str:
    scene_prefix = {v: k for k, v in WAREHOUSES.items()}[prefix]
    best = min((o for o in dump.obstacles if o.id.startswith(scene_prefix) and "wall" in o.id
                and "back" not in o.id), key=lambda o: abs(o.pos[0] - x), default=None)
    return best.id if best is not None else ""


def _compare_lidar(dump, fld, rep, robot) -> None:
    from ..bench.drive import cast, field_boxes
    from ..robot import load_robot

    robot = robot or load_robot("simtwo")
    lid = robot.lidar
    boxes = field_boxes(fld, lid.xyz[2])
    for name, p in sorted(dump.lidar.items()):
        if p.ranges.size != lid.rays:
            rep.add(Difference("lidar", name, "rays", p.ranges.size, lid.rays, ""))
            continue
        angles = lid.angles()
        ox = p.x + lid.xyz[0] * math.cos(p.theta) - lid.xyz[1] * math.sin(p.theta)
        oy = p.y + lid.xyz[0] * math.sin(p.theta) + lid.xyz[1] * math.cos(p.theta)
        expect = cast(boxes, ox, oy, np.cos(p.theta + angles), np.sin(p.theta + angles))
        use = (p.ranges > 0.15) & np.isfinite(expect) & (expect < 1.0)  # beyond the robot's own wheels
        if use.sum() < 20:
            rep.add(Difference("lidar", name, "rays on walls", int(use.sum()), 20, ""))
            continue
        err = (p.ranges - expect)[use]
        rep.count("lidar")
        med = float(np.median(np.abs(err)))
        share = float(np.mean(np.abs(err) <= LIDAR_RAY_M))
        if med > LIDAR_MEDIAN_M:
            rep.add(Difference("lidar", name, "median |range error|", med, 0))
        if share < LIDAR_SHARE:
            bad = np.flatnonzero(use)[np.abs(err) > LIDAR_RAY_M]
            worst = bad[np.argmax(np.abs(p.ranges - expect)[bad])]
            hx = ox + p.ranges[worst] * math.cos(p.theta + angles[worst])
            hy = oy + p.ranges[worst] * math.sin(p.theta + angles[worst])
            rep.add(Difference("lidar", name, f"share of rays within {LIDAR_RAY_M * 1000:.0f} mm", share,
                               LIDAR_SHARE, "", f"{bad.size} rays off; the worst by "
                               f"{1000 * (p.ranges[worst] - expect[worst]):+.1f} mm, hitting ({hx:.3f}, {hy:.3f})"))


def _compare_camera(dump, fld, rep, robot) -> None:
    from ..localization.detect import MarkerDetector
    from ..localization.synth import camera_world_pose, project
    from ..robot import load_robot

    robot = robot or load_robot("simtwo")
    cam = robot.camera
    det = MarkerDetector()
    for name, p in sorted(dump.camera.items()):
        if p.frame is None:
            rep.add(Difference("camera", name, "frame", 0, 1, "", "no camera frame"))
            continue
        T = camera_world_pose(cam, (p.x, p.y, p.theta))
        found = {d.id: d for d in det.detect(p.frame)}
        for mid, d in found.items():
            if not fld.has_marker(mid):
                rep.add(Difference("camera", name, f"marker {mid}", 1, 0, "", "found, not in the model"))
                continue
            m = fld.marker(mid)
            uv, z = project(m.corners, T, cam.K)
            if np.any(z <= 0):
                rep.add(Difference("camera", name, f"marker {mid}", 1, 0, "", "found, behind the camera in the model"))
                continue
            rep.count("camera marker")
            # the corner order that fits: 0 = as the model, k = the marker turned k x 90 degrees in its plane
            errs = [float(np.mean(np.linalg.norm(np.roll(d.corners, -k, axis=0) - uv, axis=1))) for k in range(4)]
            k = int(np.argmin(errs))
            if k != 0:
                rep.add(Difference("camera", name, f"marker {mid} in-plane", 90.0 * k if k < 3 else -90.0, 0, "deg",
                                   f"the corners fit the model's turned {90 * k} deg (mean {errs[k]:.1f} px; as the "
                                   f"model: {errs[0]:.1f} px)"))
            elif errs[0] > CAMERA_PX:
                rep.add(Difference("camera", name, f"marker {mid} corners", errs[0], 0, "px"))
        from ..localization.synth import visible_markers

        for v in visible_markers(fld, cam, T, margin_px=20, min_side_px=15, max_distance=0.7):
            if fld.marker(v.id).kind == "wall" and v.id not in found:
                # not a difference by itself: SimTwo lights the machines' east faces and the warehouses' walls
                # from one side, and a marker in their shadow is dark grey on dark grey (which face reads and
                # how it is turned are checked from the geometry above)
                rep.notes.append(f"camera {name}: marker {v.id} in view (model) but not found in SimTwo's frame")


def format_report(rep: Report) -> str:
    lines = [f"checked: {', '.join(f'{v} {k}' for k, v in sorted(rep.checked.items()))}"]
    if rep.differences:
        lines.append(f"{len(rep.differences)} differences (tolerance {TOL_M * 1000:.0f} mm, {TOL_DEG:.0f} deg):")
        lines += [f"  {d}" for d in rep.differences]
    else:
        lines.append("no differences beyond the tolerances")
    lines += [f"note: {n}" for n in rep.notes]
    return "\n".join(lines)


def scene_dir(build=None, scene: str = DEFAULT_SCENE) -> Path:
    """The scene's folder in SimTwo's sources: the build's, else any unpacked build's (the scene's XML comes
    from the pinned sources, whatever the patches), else the BuildError that says how to build."""
    from . import build as b

    if build is not None:
        return build.simtwo_dir / scene
    try:
        return b.require().simtwo_dir / scene
    except b.BuildError:
        found = sorted(b.BUILD_ROOT.glob(f"*/src/SimTwo/{scene}/scene.xml"), key=lambda q: q.stat().st_mtime)
        if found:
            return found[-1].parent
        raise
