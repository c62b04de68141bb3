"""The MuJoCo scene (an ``MjSpec``) generated from the field map and the robot spec.

Frames: the field frame is MuJoCo's world frame (x towards the outgoing warehouse, y towards the incoming
warehouse, z up, metres). The robot body's frame is ``base_link`` (on the floor midway between the wheels,
x forward, y left, z up).

Geom groups (what renders, what the rays see):

====  ==========================================  ======  ========  ========  =======
group what                                        camera  LIDAR     magnet    contact
====  ==========================================  ======  ========  ========  =======
0     walls, ribs, beacons (static, collide)      yes     yes       no        yes
1     the robot's wheels (tyres)                  yes     own (*)   no        no
2     decoration (floor, markers, tags, feet) and yes     no        no        no
      the parts of the robot's base body
3     parts' bodies (visual)                      yes     yes       no        yes
4     parts' ferromagnetic plates (visual)        yes     yes       yes       yes
5     collision-only shapes (floor plane, wheel   no      no        no        no
      spheres, wheel guard, part boxes)
====  ==========================================  ======  ========  ========  =======

The magnet column is the weld's beam (``magnet="weld"``); SimTwo's solenoid ray (``magnet="force"``,
``MAGNET_FORCE_GROUPS``) sees groups 0, 3 and 4 and pulls only when its nearest hit is a plate.

(*) SimTwo's LIDAR rays are ODE rays attached to the robot's base body: they never hit geoms on that body
(its shells) but do hit the wheels, separate bodies (Viewer.pas 853-862 ``CreateOneRaySensor``, 2998-3011,
``nearCallback`` 346-410). The simulator casts the world with ``LIDAR_GROUPS`` and the robot's own wheels
with ``LIDAR_SELF_GROUPS`` (``SimConfig.lidar_self_hits``, on by default; see ``sensors.Lidar``).

Collision filtering (``contype``/``conaffinity`` bits): the wheel spheres and the caster meet only the floor
(a 65 mm sphere is wider than the 6 mm tyre); walls and parts meet the robot's base, its magnet housing and
a "wheel guard" box around both tyres; parts meet the floor, the walls, each other and the robot;
decoration meets nothing.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field as dc_field

import numpy as np

from ..field import Field
from ..robot import RobotSpec
from . import markers as mk
from .config import SimConfig

# geom groups
G_STATIC, G_WHEEL, G_DECOR, G_PART, G_PLATE, G_HIDDEN = range(6)
G_ROBOT = G_DECOR  # the robot's base-body parts render and are seen by no ray (as SimTwo's shells)
RENDER_GROUPS = (1, 1, 1, 1, 1, 0)
LIDAR_GROUPS = (1, 0, 0, 1, 1, 0)
LIDAR_SELF_GROUPS = (0, 1, 0, 0, 0, 0)
MAGNET_GROUPS = (0, 0, 0, 0, 1, 0)  # the weld's beam (magnet="weld"): plates only
MAGNET_FORCE_GROUPS = (1, 0, 0, 1, 1, 0)  # SimTwo's solenoid ray: its nearest hit of walls, robots, parts, plates
CONTACT_GROUPS = (1, 0, 0, 1, 1, 0)

# collision bits: walls, moving bodies (robot body, parts), the floor, the robot's rolling elements
B_WALL, B_MOVING, B_FLOOR, B_WHEEL = 1, 2, 4, 8

# Robot details the spec leaves open (documented in docs/simulator.md):
BASE_COM_X = -0.02  # m: the base's centre of mass sits 2 cm behind the axle so the caster carries load
MAGNET_Z = 0.035  # m: height of the electromagnet beam = the centre of a part's plate
BUMPER_HALF = (0.005, 0.01, 0.01)  # m: the magnet, x in [0.07, 0.08], 2 cm wide, as tall as a part's plate
SOLENOID_FACE_HALF = (0.005, 0.015, 0.01)  # m: magnet="force": the contact face, as wide as SimTwo's 30 mm solenoid
WHEEL_FRICTION = (1.0, 0.005, 0.0001)
# SimTwo's parts (RobotFactoryPro2022/scene.xml 83-105 loads PartBlue.xml for all four, P33a/SimTwo at 90afa72):
# the body and the plate have no <surface>, so ODE's default mu 0.95 (Viewer.pas 4239) against walls, ribs, the
# robot and other parts; only four feet (spheres of radius 5 mm at the body's lower corners) touch the floor,
# surface mu 'leg_mu' 0.01 (PartBlue.xml 10, 27-53; PartRed/PartGreen.xml say 0.02 but the scene does not load
# them); the feet come first in ODE's simple space (they move, the field does not), so nearCallback takes their
# mu (Viewer.pas 418-436). Mass: the body's 0.2 kg plus the plate shell's 0.01 kg (PartBlue.xml 18, 57; shell
# masses are added to the body, Viewer.pas 3411-3457).
PART_FRICTION = (0.95, 0.005, 0.0001)
PART_FOOT_FRICTION = (0.01, 0.005, 0.0001)
# MuJoCo's pyramidal friction cones (this scene's) with mu 0.01 at the feet made the solver throw held parts off
# the magnet (pyramid edges almost parallel to the normal: contact force spikes of 100+ N in one step, parts
# lost in straight driving and slow turns, measured with raf experiment envelope). A foot friction below this is
# therefore a frictionless floor contact plus the same friction as the part's free joint's frictionloss,
# mu m g = 0.021 (N on the translations: a sliding part decelerates at mu g, measured 0.098 m/s^2, 5.1 cm from
# 0.1 m/s; N m on the rotations, where the feet's would be ~0.001 N m: more yaw resistance than SimTwo's, still
# a third of what the magnet's face can hold)
PART_FOOT_FRICTIONLESS_BELOW = 0.015
PART_FOOT_RADIUS = 0.005  # m: SimTwo's feet, spheres at the body's lower corners (PartBlue.xml 27-53)


def part_floor_frictionloss(part) -> tuple[float, float, float, float, float, float]:
    """The free joint's per-direction friction that stands in for the four feet's floor friction (see
    PART_FOOT_FRICTIONLESS_BELOW): mu m g (N) on x and y; none on z, roll and pitch (the feet resist none of
    them in SimTwo); on yaw the torque of four feet at r from the centre, mu m g r (N m, about 1.0e-3). The
    joint's one value for all six (mu m g on every direction) resisted yaw 21 times harder than SimTwo's feet
    and tipping too: a part on the magnet, turned with the robot, was dragged round the magnet's face (4 mm/s
    of slide at 1.5 rad/s) and lost when the turn reversed."""
    f = PART_FOOT_FRICTION[0] * (part.mass + PART_PLATE_MASS) * 9.81
    r = math.hypot(part.depth / 2 - PART_FOOT_RADIUS, part.width / 2 - PART_FOOT_RADIUS)
    return (f, f, 0.0, 0.0, 0.0, f * r)
PART_PLATE_MASS = 0.01  # kg, added to the rules' part mass (field.part.mass, 0.2 kg = SimTwo's body)
WALL_FRICTION = (0.3, 0.005, 0.0001)
# floor, wheel and caster contacts: stiff (the robot sinks ~5 um, so camera and wheel radius are exact)
# yet stable at the 1 ms step (time constant 4 ms, critically damped)
STIFF_SOLREF = (0.004, 1.0)
STIFF_SOLIMP = (0.99, 0.999, 0.001, 0.5, 2.0)
PLATE_THICKNESS = 0.002  # m the plate stands proud of the part's front face
PART_TAG_FIRST_ID = 70  # ArUco ids of the tags on the parts' tops: 70, 71, ... (the rules leave them open)

FLOOR_RGB = (0.93, 0.93, 0.91)  # the printed A0 sheets
GROUND_RGB = (0.42, 0.42, 0.44)  # the floor around the field
WALL_RGB = (0.78, 0.80, 0.84)
ROBOT_RGB = (0.15, 0.15, 0.17)


@dataclass
class RobotNames:
    """The names of one robot's body, joints, actuators and camera (robot 1: no prefix; robot k: ``rk_``)."""

    prefix: str = ""
    robot_body: str = "robot"
    robot_joint: str = "robot_free"
    wheel_joints: tuple[str, str] = ("wheel_left_hinge", "wheel_right_hinge")
    wheel_bodies: tuple[str, str] = ("wheel_left", "wheel_right")
    actuators: tuple[str, str] = ("motor_left", "motor_right")
    robot_camera: str = "robot_camera"

    @classmethod
    def numbered(cls, k: int) -> "RobotNames":
        """Robot ``k`` (1-based): robot 1 keeps the one-robot scene's names, robot k >= 2 gets ``rk_``."""
        p = "" if k == 1 else f"r{k}_"
        return cls(p, f"{p}robot", f"{p}robot_free", (f"{p}wheel_left_hinge", f"{p}wheel_right_hinge"),
                   (f"{p}wheel_left", f"{p}wheel_right"), (f"{p}motor_left", f"{p}motor_right"),
                   f"{p}robot_camera")


@dataclass
class SceneInfo:
    """Names the simulator looks up after compiling (bodies, joints, geoms, cameras, parts).

    The ``robot_*``, ``wheel_joints`` and ``actuators`` fields name robot 1; ``robots`` names every robot."""

    robot_body: str = "robot"
    robot_joint: str = "robot_free"
    wheel_joints: tuple[str, str] = ("wheel_left_hinge", "wheel_right_hinge")
    actuators: tuple[str, str] = ("motor_left", "motor_right")
    robot_camera: str = "robot_camera"
    robots: list[RobotNames] = dc_field(default_factory=lambda: [RobotNames()])
    overview_camera: str = "overview"
    top_camera: str = "top"
    parts: dict[int, str] = dc_field(default_factory=dict)  # part id -> body name
    part_visual_geoms: dict[int, str] = dc_field(default_factory=dict)  # part id -> body box geom name
    part_tags: dict[int, int] = dc_field(default_factory=dict)  # part id -> ArUco id on its top
    marker_ids: list[int] = dc_field(default_factory=list)


# display colours by type letter; the competition package's PartType.rgba wins when it is installed
_FALLBACK_RGBA = {"R": (0.85, 0.1, 0.1, 1.0), "G": (0.1, 0.7, 0.15, 1.0), "B": (0.1, 0.25, 0.85, 1.0)}


def part_rgba(letter: str) -> tuple[float, float, float, float]:
    """A part's display colour by its type letter (R, G, B)."""
    try:
        from ..competition.parts import PartType

        return tuple(PartType.from_letter(letter).rgba)  # type: ignore[return-value]
    except ImportError:  # pragma: no cover - the competition package is part of the project
        return _FALLBACK_RGBA[letter]


def yaw_quat(theta: float) -> list[float]:
    """MuJoCo quaternion (w, x, y, z) of a rotation by ``theta`` about z."""
    return [math.cos(theta / 2), 0.0, 0.0, math.sin(theta / 2)]


def quat_yaw(q) -> float:
    """Heading (rad) of a MuJoCo quaternion (w, x, y, z): the yaw of the rotated x axis."""
    w, x, y, z = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def mat_quat(R: np.ndarray) -> list[float]:
    import mujoco

    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R, dtype=np.float64).ravel())
    return q.tolist()


def _quad_mesh(spec, name: str, side: float):
    """A square of ``side`` metres in its xy plane facing +z, texture top edge towards +y."""
    import mujoco

    h = side / 2
    m = spec.add_mesh(name=name)
    m.uservert = [-h, -h, 0, h, -h, 0, h, h, 0, -h, h, 0]
    m.usertexcoord = [0, 1, 1, 1, 1, 0, 0, 0]
    m.userface = [0, 1, 2, 0, 2, 3]
    m.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL
    return m


def _add_marker_material(spec, name: str, marker_id: int, dictionary) -> None:
    import mujoco

    img = mk.marker_texture(marker_id, dictionary)
    h, w, _ = img.shape
    t = spec.add_texture(name=f"tex_{name}", type=mujoco.mjtTexture.mjTEXTURE_2D, width=w, height=h, nchannel=3)
    t.data = img.tobytes()
    mat = spec.add_material(name=f"mat_{name}")
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"tex_{name}"
    mat.specular = 0.0
    mat.shininess = 0.0
    mat.reflectance = 0.0


def _visual(geom, group: int = G_DECOR) -> None:
    geom.contype = 0
    geom.conaffinity = 0
    geom.group = group
    geom.mass = 0.0
    geom.density = 0.0


def _box_inertia(mass: float, size: tuple[float, float, float]) -> list[float]:
    x, y, z = size
    return [mass * (y * y + z * z) / 12, mass * (x * x + z * z) / 12, mass * (x * x + y * y) / 12]


def build_spec(field: Field, robot: RobotSpec, config: SimConfig,
               parts: list[tuple[int, str, float, float, float]] | None = None,
               offscreen: tuple[int, int] = (640, 480)):
    """The whole scene as an ``mujoco.MjSpec`` plus the :class:`SceneInfo` naming its parts.

    ``parts`` lists ``(part_id, letter, x, y, facing)``: every part gets its own free body; colours are
    changed at run time through ``model.geom_rgba``. ``offscreen`` is the largest image any renderer of
    this model will make (width, height).
    """
    import mujoco

    spec = mujoco.MjSpec()
    spec.modelname = "robotatfactory"
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.compiler.degree = False
    opt = spec.option
    opt.timestep = robot.physics_step
    opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    opt.cone = mujoco.mjtCone.mjCONE_PYRAMIDAL
    opt.solver = mujoco.mjtSolver.mjSOL_NEWTON
    opt.iterations = 20
    opt.ls_iterations = 10
    # resting parts fall asleep (skipped by the solver) and wake on contact, weld or teleport
    opt.enableflags |= int(mujoco.mjtEnableBit.mjENBL_SLEEP)
    vis = spec.visual
    vis.global_.offwidth = int(offscreen[0])
    vis.global_.offheight = int(offscreen[1])
    vis.quality.shadowsize = 0
    # no multisampling: marker edges are texture edges, anti-aliased by texture filtering anyway; MSAA
    # costs 3x the render time on llvmpipe and changed no detected corner by more than 0.03 px (measured)
    vis.quality.offsamples = 0
    vis.headlight.ambient = [0.42, 0.42, 0.42]
    vis.headlight.diffuse = [0.22, 0.22, 0.22]
    vis.headlight.specular = [0.0, 0.0, 0.0]
    vis.map.znear = 0.002  # x extent (2 m): 4 mm, the camera is 12 cm above the floor
    vis.map.zfar = 5.0
    spec.stat.extent = 2.0
    spec.stat.center = [0.0, 0.0, 0.0]

    info = SceneInfo()
    dictionary = mk.aruco_dictionary(field.dictionary)
    world = spec.worldbody
    # decoration lives in its own static body: a body whose geoms never collide is skipped by the
    # broad phase as a whole (measured: a third of the collision time)
    decor = world.add_body(name="decor")

    # --- lights: one soft directional light from above, no shadows (cheap, no marker broken by a shadow)
    light = world.add_light(name="sun")
    light.type = mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
    light.dir = [0.25, 0.35, -1.0]
    light.pos = [0.0, 0.0, 2.0]
    light.diffuse = [0.5, 0.5, 0.5]
    light.ambient = [0.0, 0.0, 0.0]
    light.specular = [0.0, 0.0, 0.0]
    light.castshadow = False

    # --- floor: a hidden collision plane at z = 0; the visible sheets sit just below the markers
    g = world.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.05])
    g.contype, g.conaffinity, g.group = B_FLOOR, 0, G_HIDDEN
    g.friction = [0.3, 0.005, 0.0001]
    g.solref, g.solimp = list(STIFF_SOLREF), list(STIFF_SOLIMP)
    fx, fy = field.floor.x, field.floor.y
    g = decor.add_geom(name="floor_print", type=mujoco.mjtGeom.mjGEOM_PLANE,
                       size=[(fx[1] - fx[0]) / 2, (fy[1] - fy[0]) / 2, 2.0],
                       pos=[(fx[0] + fx[1]) / 2, (fy[0] + fy[1]) / 2, -0.0005], rgba=[*FLOOR_RGB, 1])
    _visual(g)
    g = decor.add_geom(name="ground", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[3.0, 3.0, 3.0],
                       pos=[0, 0, -0.001], rgba=[*GROUND_RGB, 1])
    _visual(g)

    # --- markers: textured quads at their true poses (wall markers 0.1 mm proud of the wall face)
    qs = mk.quad_scale(dictionary)
    sizes = sorted({round(m.size * qs, 6) for m in field.markers})
    for s in sizes:
        _quad_mesh(spec, f"quad_{int(round(s * 1e6))}", s)
    for m in field.markers:
        _add_marker_material(spec, f"marker_{m.id}", m.id, dictionary)
        side = round(m.size * qs, 6)
        pos = m.position + (0.0001 * m.normal if m.kind == "wall" else 0.0)
        g = decor.add_geom(name=f"marker_{m.id}", type=mujoco.mjtGeom.mjGEOM_MESH,
                           meshname=f"quad_{int(round(side * 1e6))}", material=f"mat_marker_{m.id}",
                           pos=pos.tolist(), quat=mat_quat(m.rotation))
        _visual(g)
        info.marker_ids.append(m.id)

    # --- walls and ribs
    for b in field.boxes:
        g = world.add_geom(name=b.name, type=mujoco.mjtGeom.mjGEOM_BOX, size=list(b.half_extents),
                           pos=list(b.center), quat=yaw_quat(b.yaw), rgba=[*WALL_RGB, 1])
        g.contype, g.conaffinity, g.group = B_WALL, 0, G_STATIC
        g.friction = list(WALL_FRICTION)

    # --- LIDAR beacons (team areas)
    if config.beacons:
        for i, (bx, by) in enumerate(field.beacons):
            g = world.add_geom(name=f"beacon_{i}", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                               size=[field.beacon_diameter / 2, field.beacon_height / 2, 0],
                               pos=[bx, by, field.beacon_height / 2], rgba=[0.95, 0.95, 0.95, 1])
            g.contype, g.conaffinity, g.group = B_WALL, 0, G_STATIC

    # --- cameras for overviews
    _add_overview_cameras(world, field)

    # --- the robot(s)
    n = getattr(config, "robots", 1)
    if n == 1:
        _add_robot(spec, world, robot, config, field)  # the one-robot scene, exactly as it always was
    else:
        info.robots = [RobotNames.numbered(k) for k in range(1, n + 1)]
        for names, pose in zip(info.robots, start_poses(field, n, config.start_poses)):
            _add_robot(spec, world, robot, config, field, names=names, pose=pose, multi=True)

    # --- parts
    tag_side = round(field.part.tag_size * qs, 6)
    _quad_mesh(spec, "quad_tag", tag_side)
    for k, (pid, letter, x, y, facing) in enumerate(parts or []):
        tag_id = PART_TAG_FIRST_ID + k
        if tag_id >= dictionary.bytesList.shape[0]:
            raise ValueError(f"too many parts for {field.dictionary}: tag id {tag_id}")
        _add_marker_material(spec, f"tag_{pid}", tag_id, dictionary)
        _add_part(spec, world, field, pid, letter, x, y, facing)
        info.parts[pid] = f"part_{pid}"
        info.part_visual_geoms[pid] = f"part_{pid}_body"
        info.part_tags[pid] = tag_id
    return spec, info


def _add_overview_cameras(world, field: Field) -> None:
    """``overview``: from the bottom edge, above, at an angle; ``top``: straight down."""
    cx = (field.floor.x[0] + field.floor.x[1]) / 2
    cy = (field.floor.y[0] + field.floor.y[1]) / 2
    eye = np.array([cx, cy - 1.22, 1.32])
    target = np.array([cx, cy + 0.02, 0.0])
    fwd = target - eye
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    cam = world.add_camera(name="overview", pos=eye.tolist(),
                           quat=mat_quat(np.column_stack([right, up, -fwd])))
    cam.fovy = 50.0
    top = world.add_camera(name="top", pos=[cx, cy, 2.05])
    top.fovy = 38.0


def _wheel_inertia(mass: float, r: float, width: float) -> list[float]:
    axial = 0.5 * mass * r * r
    trans = mass * (3 * r * r + width * width) / 12
    return [trans, axial, trans]  # the wheel body's y axis is the axle


def start_poses(field: Field, n: int, given=None) -> list[tuple[float, float, float]]:
    """Start poses (x, y, theta; m, rad, field frame) of ``n`` robots: ``given`` when not None; one robot: the
    field's start pose; several: the centres of the start area's 2 x 2 cells (the rules' 0.35 m square: each
    cell, 0.175 m, holds the 0.14 x 0.15 m robot), the row nearer the field (larger y) first, left to right,
    all with the field start pose's heading. The rules allow several robots per team and ask every robot
    to start inside the start area."""
    if given is not None:
        return [tuple(float(v) for v in p) for p in given]
    sp = field.start_pose
    if n == 1:
        return [(sp.x, sp.y, sp.theta)]
    a = field.start_area
    xs = [a.x[0] + (a.x[1] - a.x[0]) * f for f in (0.25, 0.75)]
    ys = [a.y[0] + (a.y[1] - a.y[0]) * f for f in (0.75, 0.25)]
    cells = [(x, y, sp.theta) for y in ys for x in xs]
    if n > len(cells):
        raise ValueError(f"the start area holds {len(cells)} robots, not {n}: give the start poses")
    return cells[:n]


def _add_robot(spec, world, robot: RobotSpec, config: SimConfig, field: Field, names: RobotNames | None = None,
               pose=None, multi: bool = False) -> None:
    """One robot. ``multi`` (a scene of several robots): the base, magnet and LIDAR housing go in group
    ``G_STATIC`` and the base carries invisible copies of the tyres, so that the other robots' rays see
    them (each robot's own rays exclude its base body: ``mj_ray``'s ``bodyexclude``)."""
    import mujoco

    names = names or RobotNames()
    p = names.prefix
    if pose is not None:
        x, y, th = pose
    else:
        x, y, th = config.start_pose if config.start_pose is not None else \
            (field.start_pose.x, field.start_pose.y, field.start_pose.theta)
    g_body = G_STATIC if multi else G_ROBOT
    body = world.add_body(name=names.robot_body, pos=[x, y, 0.0], quat=yaw_quat(th))
    body.add_freejoint(name=names.robot_joint)
    bsize = tuple(robot.base["size"])
    bz = float(robot.base["z"])
    body.mass = float(robot.base["mass"])
    body.ipos = [BASE_COM_X, 0.0, bz]
    body.iquat = [1.0, 0.0, 0.0, 0.0]
    body.inertia = _box_inertia(body.mass, bsize)
    body.explicitinertial = True

    g = body.add_geom(name=f"{p}robot_base", type=mujoco.mjtGeom.mjGEOM_BOX, size=[s / 2 for s in bsize],
                      pos=[0, 0, bz], rgba=[*ROBOT_RGB, 1])
    g.contype, g.conaffinity, g.group = B_MOVING, B_WALL | B_MOVING, g_body
    g.friction = list(WALL_FRICTION)
    mx = float(robot.electromagnet["x"])
    g = body.add_geom(name=f"{p}robot_magnet", type=mujoco.mjtGeom.mjGEOM_BOX, size=list(BUMPER_HALF),
                      pos=[mx - BUMPER_HALF[0], 0, MAGNET_Z], rgba=[0.55, 0.55, 0.6, 1])
    g.contype, g.conaffinity, g.group = B_MOVING, B_WALL | B_MOVING, g_body
    g.friction = list(WALL_FRICTION)
    if config.magnet == "force":
        # SimTwo's solenoid shell (AGV.xml 89-96: a cylinder of radius 0.015 m, surface mu 0.1) is what a held
        # plate rests against: a hidden 30 mm wide face takes the housing's contacts (the housing above stays
        # what the camera and the rays see), with the shell's friction (priority: its own, not the max) and a
        # stiff contact like ODE's (soft_cfm 1e-5), so that a pulled plate neither creeps nor sinks
        g.contype = g.conaffinity = 0
        g = body.add_geom(name=f"{p}robot_solenoid_face", type=mujoco.mjtGeom.mjGEOM_BOX,
                          size=list(SOLENOID_FACE_HALF), pos=[mx - SOLENOID_FACE_HALF[0], 0, MAGNET_Z],
                          rgba=[0, 0, 0, 0])
        g.contype, g.conaffinity, g.group = B_MOVING, B_WALL | B_MOVING, G_HIDDEN
        g.friction = [float(robot.electromagnet.get("mu", 0.1)), WALL_FRICTION[1], WALL_FRICTION[2]]
        g.priority = 1
        g.solref, g.solimp = list(STIFF_SOLREF), list(STIFF_SOLIMP)
    # the wheels' outline for walls and parts: a box around both tyres, clear of the floor
    wwidth = float(robot.wheel.get("width", 0.02))
    r = robot.wheel_radius
    g = body.add_geom(name=f"{p}robot_wheel_guard", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[r, robot.track / 2 + wwidth / 2, r - 0.0025], pos=[0, 0, r + 0.0025],
                      rgba=[0, 0, 0, 0])
    g.contype, g.conaffinity, g.group = B_MOVING, B_WALL | B_MOVING, G_HIDDEN
    g.friction = list(WALL_FRICTION)
    cr = float(robot.caster["radius"])
    g = body.add_geom(name=f"{p}robot_caster", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[cr, 0, 0],
                      pos=[float(robot.caster["x"]), 0, cr], rgba=[0.6, 0.6, 0.6, 1])
    g.contype, g.conaffinity, g.group = B_WHEEL, B_FLOOR, G_ROBOT
    g.condim = 1  # a ball caster: no friction (priority: its condim wins over the floor's)
    g.priority = 1
    g.solref, g.solimp = list(STIFF_SOLREF), list(STIFF_SOLIMP)
    lx, ly, lz = robot.lidar.xyz
    g = body.add_geom(name=f"{p}robot_lidar", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.022, 0.004, 0],
                      pos=[lx, ly, bz + bsize[2] / 2 + 0.004], rgba=[0.1, 0.1, 0.1, 1])
    _visual(g, g_body)

    # the camera: MuJoCo looks along its -z with +y up; OpenCV's optical frame is x right, y down, z forward
    T = robot.camera.base_to_optical()
    R_mj = T[:3, :3] @ np.diag([1.0, -1.0, -1.0])
    cam = body.add_camera(name=names.robot_camera, pos=list(T[:3, 3]), quat=mat_quat(R_mj))
    c = robot.camera
    cam.resolution = [c.width, c.height]
    cam.sensor_size = [c.width * 1e-5, c.height * 1e-5]
    cam.focal_pixel = [c.fx, c.fy]
    # MuJoCo's principal point offset is from the image centre, which OpenCV calls ((W-1)/2, (H-1)/2), with
    # the opposite sign: principal_pixel +4 puts the principal point 4 px LEFT (and up) of the centre (measured
    # on rendered markers by raf experiment calibration; docs/calibration.md)
    cam.principal_pixel = [(c.width - 1) / 2 - c.cx, (c.height - 1) / 2 - c.cy]

    r = robot.wheel_radius
    wmass = float(robot.wheel["mass"])
    wwidth = float(robot.wheel.get("width", 0.02))
    inset = float(robot.wheel.get("contact_inset", 0.0))
    m = robot.motor
    for side, sign in (("left", 1.0), ("right", -1.0)):
        wb = body.add_body(name=f"{p}wheel_{side}", pos=[0, sign * robot.track / 2, r])
        wb.mass = wmass
        wb.ipos = [0.0, 0.0, 0.0]  # on the axle (MjSpec would otherwise leave it at the body's offset)
        wb.iquat = [1.0, 0.0, 0.0, 0.0]
        wb.inertia = _wheel_inertia(wmass, r, wwidth)
        wb.explicitinertial = True
        j = wb.add_joint(name=f"{p}wheel_{side}_hinge", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 1, 0])
        j.damping = [float(m["Bv"]) * float(m.get("gear", 1.0)) ** 2, 0.0, 0.0]
        j.frictionloss = float(m["Fc"]) * float(m.get("gear", 1.0))
        # the floor contact sits ``contact_inset`` inside the tyre's centre plane, where SimTwo's wheels grip:
        # in a turn on the spot its robot turns as if the track were 2 * inset shorter (docs/simulator.md,
        # "The wheels' contact")
        g = wb.add_geom(name=f"{p}wheel_{side}_contact", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[r, 0, 0],
                        pos=[0, -sign * inset, 0])
        # the sphere only rolls on the floor (it is wider than the 6 mm tyre); walls and parts meet the
        # wheel guard box instead
        g.contype, g.conaffinity, g.group = B_WHEEL, B_FLOOR, G_HIDDEN
        g.condim = 3
        g.friction = list(WHEEL_FRICTION)
        g.solref, g.solimp = list(STIFF_SOLREF), list(STIFF_SOLIMP)
        g.rgba = [0, 0, 0, 0]
        # the tyre as SimTwo's wheel solid (AGV.xml: a cylinder of WheelDiameter/2 and WheelThickness):
        # what the camera sees and the LIDAR's rays hit
        g = wb.add_geom(name=f"{p}wheel_{side}_tyre", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[r, wwidth / 2, 0],
                        quat=[math.cos(math.pi / 4), math.sin(math.pi / 4), 0, 0], rgba=[0.05, 0.05, 0.05, 1])
        _visual(g, G_WHEEL)
        g = wb.add_geom(name=f"{p}wheel_{side}_hub", type=mujoco.mjtGeom.mjGEOM_BOX,
                        size=[r * 0.8, wwidth / 2 + 0.0005, 0.004], rgba=[0.8, 0.8, 0.8, 1])
        _visual(g, G_ROBOT)
        if multi:  # the tyre as the other robots' rays see it: fixed to the base (a tyre is round), invisible
            g = body.add_geom(name=f"{p}wheel_{side}_tyre_seen", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                              size=[r, wwidth / 2, 0], pos=[0, sign * robot.track / 2, r],
                              quat=[math.cos(math.pi / 4), math.sin(math.pi / 4), 0, 0], rgba=[0, 0, 0, 0])
            _visual(g, G_STATIC)
        a = spec.add_actuator(name=f"{p}motor_{side}", target=f"{p}wheel_{side}_hinge")
        a.trntype = mujoco.mjtTrn.mjTRN_JOINT
        a.gainprm[0] = 1.0  # ctrl = torque Kt*I (N.m), computed by the motor model each physics step
        a.ctrllimited = 0


def _add_part(spec, world, field: Field, pid: int, letter: str, x: float, y: float, facing: float) -> None:
    import mujoco


    p = field.part
    body = world.add_body(name=f"part_{pid}", pos=[x, y, 0.0], quat=yaw_quat(facing))
    j = body.add_freejoint(name=f"part_{pid}_free")
    h = p.height
    if PART_FOOT_FRICTION[0] < PART_FOOT_FRICTIONLESS_BELOW:  # the feet's friction as the joint's instead
        j.frictionloss = PART_FOOT_FRICTION[0] * (p.mass + PART_PLATE_MASS) * 9.81
    mass = p.mass + PART_PLATE_MASS
    body.mass = mass
    body.ipos = [0, 0, h / 2]
    body.iquat = [1.0, 0.0, 0.0, 0.0]
    body.inertia = _box_inertia(mass, (p.depth, p.width, h))
    body.explicitinertial = True
    # collision: one box from the feet to the top, plate included (walls, ribs, robots, parts: SimTwo's mu 0.95)
    fh = p.feet_height
    g = body.add_geom(name=f"part_{pid}_collision", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[(p.depth + PLATE_THICKNESS) / 2, p.width / 2, (h - fh) / 2],
                      pos=[PLATE_THICKNESS / 2, 0, fh + (h - fh) / 2])
    g.contype, g.conaffinity, g.group = B_MOVING, B_WALL | B_MOVING, G_HIDDEN
    g.friction = list(PART_FRICTION)
    g.rgba = [0, 0, 0, 0]
    # the floor touches only SimTwo's four feet (PartBlue.xml: spheres of radius 5 mm at the body's lower
    # corners, mu 0.01): a sole as wide and deep as the body and as tall as the feet, whose box-plane contacts
    # are at its four corners, with the feet's friction (priority: theirs, not the larger of the pair).
    # (Four sphere geoms instead, mu 0.01: the solver threw a part off the magnet with a 100+ N spike at 0.6 rad/s.)
    g = body.add_geom(name=f"part_{pid}_feet", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[p.depth / 2, p.width / 2, fh / 2], pos=[0, 0, fh / 2])
    g.contype, g.conaffinity, g.group = 0, B_FLOOR, G_HIDDEN
    g.friction = list(PART_FOOT_FRICTION)
    g.priority = 2
    if PART_FOOT_FRICTION[0] < PART_FOOT_FRICTIONLESS_BELOW:
        g.condim = 1  # frictionless here, the friction is the joint's: see PART_FOOT_FRICTIONLESS_BELOW
    g.rgba = [0, 0, 0, 0]
    # what it looks like: body on four feet, plate in front, tag on top -- in a jointless child body that
    # never collides, so the broad phase skips all of them at once (measured: 2-3 us per physics step)
    look = body.add_body(name=f"part_{pid}_look")
    g = look.add_geom(name=f"part_{pid}_body", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[p.depth / 2, p.width / 2, p.body_height / 2],
                      pos=[0, 0, p.feet_height + p.body_height / 2], rgba=list(part_rgba(letter)))
    _visual(g, G_PART)
    fs = 0.006
    for i, (sx, sy) in enumerate(((1, 1), (1, -1), (-1, 1), (-1, -1))):
        g = look.add_geom(name=f"part_{pid}_foot{i}", type=mujoco.mjtGeom.mjGEOM_BOX,
                          size=[fs, fs, p.feet_height / 2],
                          pos=[sx * (p.depth / 2 - fs), sy * (p.width / 2 - fs), p.feet_height / 2],
                          rgba=[0.2, 0.2, 0.2, 1])
        _visual(g)
    pw, ph = p.plate
    g = look.add_geom(name=f"part_{pid}_plate", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[PLATE_THICKNESS / 2, pw / 2, ph / 2],
                      pos=[p.depth / 2 + PLATE_THICKNESS / 2, 0, MAGNET_Z], rgba=[0.6, 0.6, 0.62, 1])
    _visual(g, G_PLATE)
    # the tag's top edge points the way the plate faces: local +x, i.e. the quad's +y turned by -90 deg
    g = look.add_geom(name=f"part_{pid}_tag", type=mujoco.mjtGeom.mjGEOM_MESH, meshname="quad_tag",
                      material=f"mat_tag_{pid}", pos=[0, 0, h + 0.0002], quat=yaw_quat(-math.pi / 2))
    _visual(g)
