"""A world that is not the map (issue 20): the stand-in's field, parts, start pose and camera drawn off their
nominal values, seeded per run, while the robot's side (agent, localization, bridge) keeps the nominal map and
robot file.

Every size is a standard deviation of a normal draw truncated at :data:`CLIP` sigmas; all are 0 (off) by
default (:class:`Perturb`, ``raf sim --set perturb.field_mm=3``, the competition experiment's ``--sim`` and
``--perturb``). The draw is a :class:`random.Random` seeded with the string
``robotatfactory/perturb/<what>/round<r>/seed<s>`` (SHA-512 seeding: the same on every machine), one stream per
kind, so turning one perturbation on does not change another's draw.

* ``field_mm``: **systematic per run, rigid per fixture**. Each of the four fixtures (incoming and outgoing
  warehouses, machines A and B: its walls, ribs, part slots and wall markers, assigned by the nearest slot) is
  shifted by (dx, dy) ~ N(0, field_mm) and turned about its slots' centre by N(0, field_mm / 0.3 m) rad (its
  ends move about field_mm more); each of the two printed floor sheets (x < 0, x >= 0: the floor markers) is
  shifted and turned the same way (N(0, field_mm / 0.84 m) rad). The factory (the referee's slots, the
  machines' outputs) is built on the displaced field: it is the world.
* ``parts_mm`` / ``parts_deg``: each part as a referee would put it into its slot: along the wall by N(0,
  parts_mm), away from the wall by |N(0, parts_mm)| plus what its turn N(0, parts_deg) needs for its back
  corners to clear the wall (a part never starts inside a wall).
* ``start_cm`` / ``start_deg``: the robot put down near the nominal start pose, by N(0, start_cm) in x and y
  and N(0, start_deg) in heading, kept with its 0.15 m footprint radius inside the start area.
* ``camera_pct`` / ``camera_px`` / ``camera_deg``: the camera the simulator renders with, against the robot
  file's nominal one: focal lengths fx and fy each scaled by 1 + N(0, camera_pct %), the principal point moved
  by N(0, camera_px) px in x and y, the mount's pitch and roll by N(0, camera_deg) deg each (the mount has no
  yaw setting in the robot file; it is not drawn).

Plain Python and numpy (no MuJoCo).
"""
from __future__ import annotations

import dataclasses
import math
import random
from dataclasses import dataclass

import numpy as np

from ..settings import setting

CLIP = 3.0  # sigmas: every draw is truncated there
FIXTURES = ("incoming", "outgoing", "machine_A", "machine_B")
FIXTURE_ARM = 0.3  # m: a fixture's turn of field_mm / FIXTURE_ARM rad moves a point this far out by field_mm
SHEET_ARM = 0.84  # m: the same for a floor sheet (half the floor's length)
ROBOT_RADIUS = 0.15  # m: the start pose is kept this far inside the start area (the 0.3 m square's half)


@dataclass(frozen=True)
class Perturb:
    """Sizes of the world's departures from the map (standard deviations; 0: off). See the module docstring."""

    field_mm: float = setting(0.0, "mm, s.d. of each fixture's (warehouse, machine: walls, ribs, slots, wall "
                                   "markers) and floor sheet's systematic shift from the map, and of its turn's "
                                   "reach; 0: the map", lo=0.0, hi=30.0)
    parts_mm: float = setting(0.0, "mm, s.d. of each part's placement error in its slot (along the wall; away "
                                   "from it, one-sided); 0: at the slot centre", lo=0.0, hi=15.0)
    parts_deg: float = setting(0.0, "deg, s.d. of each part's heading error in its slot; 0: square", lo=0.0,
                               hi=15.0)
    start_cm: float = setting(0.0, "cm, s.d. of the robot's start position error in x and y (kept inside the "
                                   "start area); 0: the nominal start pose", lo=0.0, hi=10.0)
    start_deg: float = setting(0.0, "deg, s.d. of the robot's start heading error; 0: the nominal heading",
                               lo=0.0, hi=30.0)
    camera_pct: float = setting(0.0, "%, s.d. of the rendering camera's focal lengths fx, fy (each) against the "
                                     "robot file's; 0: nominal", lo=0.0, hi=10.0)
    camera_px: float = setting(0.0, "px, s.d. of the rendering camera's principal point cx, cy (each) against "
                                    "the robot file's; 0: nominal", lo=0.0, hi=30.0)
    camera_deg: float = setting(0.0, "deg, s.d. of the camera mount's pitch and roll (each) against the robot "
                                     "file's; 0: nominal", lo=0.0, hi=5.0)

    @property
    def any(self) -> bool:
        return any(getattr(self, f.name) for f in dataclasses.fields(self))

    def describe(self) -> str:
        """``field 3 mm, parts 3 mm 2 deg, ...`` or ``none``."""
        if not self.any:
            return "none"
        return (f"field {self.field_mm:g} mm, parts {self.parts_mm:g} mm {self.parts_deg:g} deg, start "
                f"{self.start_cm:g} cm {self.start_deg:g} deg, camera {self.camera_pct:g} % {self.camera_px:g} px "
                f"{self.camera_deg:g} deg (standard deviations, truncated at {CLIP:g})")


#: the competition experiment's ``--perturb`` shortcut: the issue's "a few" of each
ISSUE_20 = Perturb(field_mm=2.0, parts_mm=3.0, parts_deg=2.0, start_cm=3.0, start_deg=3.0, camera_pct=2.0,
                   camera_px=3.0, camera_deg=1.0)


def _rng(what: str, round_no: int, seed: int) -> random.Random:
    return random.Random(f"robotatfactory/perturb/{what}/round{round_no}/seed{seed}")


def _g(rng: random.Random, sigma: float) -> float:
    """N(0, sigma) truncated at CLIP sigmas (0 when sigma is 0, and the stream still advances)."""
    while True:
        v = rng.gauss(0.0, 1.0)
        if abs(v) <= CLIP:
            return v * sigma


def _rigid(dx: float, dy: float, dth: float, about) -> np.ndarray:
    """4x4 world transform: turn by dth about ``about`` (x, y), then shift by (dx, dy)."""
    c, s = math.cos(dth), math.sin(dth)
    ax, ay = about
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[0, 3] = ax - c * ax + s * ay + dx
    T[1, 3] = ay - s * ax - c * ay + dy
    return T


def _xy(T: np.ndarray, x: float, y: float) -> tuple[float, float]:
    return float(T[0, 0] * x + T[0, 1] * y + T[0, 3]), float(T[1, 0] * x + T[1, 1] * y + T[1, 3])


def _yaw(T: np.ndarray) -> float:
    return math.atan2(T[1, 0], T[0, 0])


def fixture_moves(field, sigma_m: float, round_no: int, seed: int) -> dict[str, np.ndarray]:
    """The rigid transform of each fixture and floor sheet (``floor_left``, ``floor_right``) for this run."""
    rng = _rng("field", round_no, seed)
    out = {}
    for zone in FIXTURES:
        slots = field.slots_of(zone)
        centre = (sum(s.xy[0] for s in slots) / len(slots), sum(s.xy[1] for s in slots) / len(slots)) \
            if slots else (0.0, 0.0)
        out[zone] = _rigid(_g(rng, sigma_m), _g(rng, sigma_m), _g(rng, sigma_m / FIXTURE_ARM), centre)
    fx = field.floor.x
    for name, cx in (("floor_left", (fx[0] + 0.0) / 2), ("floor_right", (fx[1] + 0.0) / 2)):
        out[name] = _rigid(_g(rng, sigma_m), _g(rng, sigma_m), _g(rng, sigma_m / SHEET_ARM), (cx, 0.0))
    return out


def _nearest_zone(field, x: float, y: float) -> str:
    return min(field.slots, key=lambda s: math.hypot(s.xy[0] - x, s.xy[1] - y)).zone


def displaced_field(field, sigma_m: float, round_no: int, seed: int):
    """``field`` with its fixtures and floor sheets moved (see the module docstring); ``field`` itself when
    ``sigma_m`` is 0."""
    if sigma_m <= 0:
        return field
    moves = fixture_moves(field, sigma_m, round_no, seed)
    boxes = []
    for b in field.boxes:
        T = moves[_nearest_zone(field, b.center[0], b.center[1])]
        x, y = _xy(T, b.center[0], b.center[1])
        boxes.append(dataclasses.replace(b, center=(x, y, b.center[2]), yaw=b.yaw + _yaw(T)))
    slots = []
    for s in field.slots:
        T = moves[s.zone]
        slots.append(dataclasses.replace(s, xy=_xy(T, *s.xy), facing=s.facing + _yaw(T)))
    markers = []
    for m in field.markers:
        x, y = float(m.position[0]), float(m.position[1])
        if m.kind == "wall":
            T = moves[_nearest_zone(field, x, y)]
        else:
            T = moves["floor_left" if x < 0 else "floor_right"]
        markers.append(dataclasses.replace(m, pose=T @ m.pose))
    return dataclasses.replace(field, boxes=tuple(boxes), slots=tuple(slots), markers=tuple(markers), _by_id={})


def part_pose(field, slot, pid: int, p: Perturb, round_no: int, seed: int) -> tuple[float, float, float]:
    """(x, y, facing) of part ``pid`` put into ``slot`` (of the world's field) with the placement error."""
    if not (p.parts_mm or p.parts_deg):
        return slot.xy[0], slot.xy[1], slot.facing
    rng = _rng(f"part{pid}", round_no, seed)
    sig = p.parts_mm / 1000.0
    along, away = _g(rng, sig), abs(_g(rng, sig))
    dth = math.radians(_g(rng, p.parts_deg))
    away += field.part.width / 2 * abs(math.sin(dth)) + (0.0005 if dth else 0.0)  # its back corners clear the wall
    f = slot.facing  # the plate faces away from the wall: +facing is away from it
    x = slot.xy[0] + away * math.cos(f) - along * math.sin(f)
    y = slot.xy[1] + away * math.sin(f) + along * math.cos(f)
    return x, y, f + dth


def start_pose(field, nominal, p: Perturb, round_no: int, seed: int) -> tuple[float, float, float]:
    """The robot's true start pose near ``nominal`` (x, y, theta), inside the start area."""
    x, y, th = (float(v) for v in nominal)
    if not (p.start_cm or p.start_deg):
        return x, y, th
    rng = _rng("start", round_no, seed)
    sig = p.start_cm / 100.0
    x, y, th = x + _g(rng, sig), y + _g(rng, sig), th + math.radians(_g(rng, p.start_deg))
    a = field.start_area
    lo_x, hi_x = a.x[0] + ROBOT_RADIUS, a.x[1] - ROBOT_RADIUS
    lo_y, hi_y = a.y[0] + ROBOT_RADIUS, a.y[1] - ROBOT_RADIUS
    if lo_x <= hi_x:
        x = min(max(x, lo_x), hi_x)
    if lo_y <= hi_y:
        y = min(max(y, lo_y), hi_y)
    return x, y, th


def true_camera(camera, p: Perturb, round_no: int, seed: int):
    """The camera the simulator renders with (a CameraSpec), drawn from the robot file's ``camera``."""
    if not (p.camera_pct or p.camera_px or p.camera_deg):
        return camera
    rng = _rng("camera", round_no, seed)
    kx, ky = 1.0 + _g(rng, p.camera_pct / 100.0), 1.0 + _g(rng, p.camera_pct / 100.0)
    dcx, dcy = _g(rng, p.camera_px), _g(rng, p.camera_px)
    dpitch, droll = _g(rng, p.camera_deg), _g(rng, p.camera_deg)
    return dataclasses.replace(camera, fx=camera.fx * kx, fy=camera.fy * ky, cx=camera.cx + dcx, cy=camera.cy + dcy,
                               pitch_down_deg=camera.pitch_down_deg + dpitch, roll_deg=camera.roll_deg + droll)


@dataclass(frozen=True)
class World:
    """What the stand-in simulates for one run: the field, the robot (its camera drawn), the start pose, and
    how far each differs from the nominal ones (for the results)."""

    field: object
    robot: object
    start: tuple[float, float, float] | None  # None: as configured (no start perturbation)
    perturb: Perturb

    @classmethod
    def draw(cls, field, robot, perturb: Perturb, round_no: int, seed: int, nominal_start=None) -> "World":
        world_field = displaced_field(field, perturb.field_mm / 1000.0, round_no, seed)
        cam = true_camera(robot.camera, perturb, round_no, seed)
        world_robot = robot if cam is robot.camera else dataclasses.replace(robot, camera=cam)
        start = None
        if perturb.start_cm or perturb.start_deg:
            sp = field.start_pose
            start = start_pose(field, nominal_start or (sp.x, sp.y, sp.theta), perturb, round_no, seed)
        return cls(world_field, world_robot, start, perturb)

    def offsets(self, nominal_field, nominal_robot, nominal_start=None) -> dict[str, float]:
        """How far this world is from the map, flat keys with units: the largest slot, marker and box
        displacement (mm), the start pose's error (cm, deg) and the camera's (%, px, deg)."""
        out: dict[str, float] = {}
        nf, wf = nominal_field, self.field
        if wf is not nf:
            out["field_slot_max_mm"] = 1000 * max(math.dist(a.xy, b.xy) for a, b in zip(nf.slots, wf.slots))
            out["field_marker_max_mm"] = 1000 * max(float(np.linalg.norm(a.position - b.position))
                                                    for a, b in zip(nf.markers, wf.markers))
            out["field_box_max_mm"] = 1000 * max(math.dist(a.center[:2], b.center[:2]) for a, b in zip(nf.boxes, wf.boxes))
        if self.start is not None:
            sp = nominal_start or (nf.start_pose.x, nf.start_pose.y, nf.start_pose.theta)
            out["start_error_cm"] = 100 * math.dist(sp[:2], self.start[:2])
            out["start_error_deg"] = math.degrees(self.start[2] - sp[2])
        a, b = nominal_robot.camera, self.robot.camera
        if a is not b:
            out["camera_fx_error_pct"] = 100 * (b.fx / a.fx - 1)
            out["camera_fy_error_pct"] = 100 * (b.fy / a.fy - 1)
            out["camera_cx_error_px"] = b.cx - a.cx
            out["camera_cy_error_px"] = b.cy - a.cy
            out["camera_pitch_error_deg"] = b.pitch_down_deg - a.pitch_down_deg
            out["camera_roll_error_deg"] = b.roll_deg - a.roll_deg
        return {k: round(v, 3) for k, v in out.items()}
