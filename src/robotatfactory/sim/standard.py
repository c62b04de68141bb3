"""ROS 2's simulation_interfaces standard over this project's simulators, without ROS.

The standard (github.com/ros-simulation/simulation_interfaces, Jazzy release 1.5.1) names what a simulator
offers: features, a simulation state, steps, entities with ground-truth states, spawning, named poses. This
module decides what each call means on the RobotAtFactory field and answers with the standard's result
codes; :mod:`robotatfactory.ros.simulation_interfaces` turns its answers into the standard's messages on
ROS 2. The numbers below are the standard's (``SimulatorFeatures``, ``Result``, ``SimulationState``, the
services' own codes); a test checks them against the generated message classes.

The world as the standard sees it here (docs/ros2.md, "simulation_interfaces"):

* **entities**: ``robot`` (category ROBOT, tag ``robot``) and the parts on the field, ``part_<id>`` (category
  DYNAMIC_OBJECT, tags ``part`` and the colour, ``red``/``green``/``blue``). A part off the field (removed, or
  one of SimTwo's spare parts) is not an entity: spawning a part puts such a part back; deleting one
  takes it off the field. The scene has a fixed set of parts, so a spawn needs a part that is off the field.
* **poses**: in the field frame (the bridge's ``map`` frame; ``""`` and ``world`` mean the same), planar: the
  position's z is the simulator's, roll and pitch must be zero. A part's yaw is the heading of its plate,
  as a slot's ``facing`` (docs/field.md): a part spawned at a slot's named pose stands as the rules put it.
* **named poses**: each slot (tags ``slot`` and its zone: ``incoming``, ``machine_A`` ...) and the start pose
  (tags ``start``, ``spawn``).
* **spawnable resources**: ``raf://part`` (the part keeps its colour), ``raf://part/red|green|blue``
  (the stand-in recolours it; SimTwo cannot).

Two backends (:class:`Backend`) carry the calls to a simulator: the stand-in's control channel (everything)
and SimTwo through the bridge (teleports; no pause, no step, no reset). Units: metres, radians, seconds.
"""
from __future__ import annotations

import dataclasses
import math
import re
from typing import Protocol

# ---- the standard's numbers (simulation_interfaces 1.5.1) ----------------------------------------------------
# SimulatorFeatures
SPAWNING, DELETING, NAMED_POSES, POSE_BOUNDS, ENTITY_TAGS = 0, 1, 2, 3, 4
ENTITY_BOUNDS, ENTITY_BOUNDS_BOX, ENTITY_BOUNDS_CONVEX, ENTITY_CATEGORIES = 5, 6, 7, 8
SPAWNING_RESOURCE_STRING, ENTITY_STATE_GETTING, ENTITY_STATE_SETTING = 9, 10, 11
ENTITY_INFO_GETTING, ENTITY_INFO_SETTING, SPAWNABLES = 12, 13, 14
SIMULATION_RESET, SIMULATION_RESET_TIME, SIMULATION_RESET_STATE, SIMULATION_RESET_SPAWNED = 20, 21, 22, 23
SIMULATION_STATE_GETTING, SIMULATION_STATE_SETTING, SIMULATION_STATE_PAUSE = 24, 25, 26
STEP_SIMULATION_SINGLE, STEP_SIMULATION_MULTIPLE, STEP_SIMULATION_ACTION = 31, 32, 33
SPAWNING_ENTITIES = 50
# Result
FEATURE_UNSUPPORTED, OK, NOT_FOUND, INCORRECT_STATE, OPERATION_FAILED = 0, 1, 2, 3, 4
# SimulationState
STOPPED, PLAYING, PAUSED, QUITTING, NO_WORLD, LOADING_WORLD = 0, 1, 2, 3, 4, 5
STATE_NAMES = {STOPPED: "stopped", PLAYING: "playing", PAUSED: "paused", QUITTING: "quitting",
               NO_WORLD: "no world", LOADING_WORLD: "loading world"}
# SetSimulationState's own codes
ALREADY_IN_TARGET_STATE, STATE_TRANSITION_ERROR, INCORRECT_TRANSITION = 101, 102, 103
# SpawnEntity's own codes
NAME_NOT_UNIQUE, NAME_INVALID, UNSUPPORTED_FORMAT, NO_RESOURCE, INVALID_SPAWN_POSE = 101, 102, 103, 104, 109
# SetEntityState's own code
INVALID_POSE = 101
# SpawnEntities' own code
ENTITIES_SPAWN_FAILED = 150
# ResetSimulation scopes
SCOPE_DEFAULT, SCOPE_TIME, SCOPE_STATE, SCOPE_SPAWNED, SCOPE_ALL = 0, 1, 2, 4, 255
# EntityCategory
CATEGORY_OBJECT, CATEGORY_ROBOT, CATEGORY_DYNAMIC_OBJECT, CATEGORY_STATIC_OBJECT = 0, 1, 4, 5
# TagsFilter, Bounds
FILTER_MODE_ANY, FILTER_MODE_ALL = 0, 1
BOUNDS_EMPTY, BOUNDS_BOX, BOUNDS_CONVEX_HULL, BOUNDS_SPHERE = 0, 1, 2, 3

#: the features each backend offers (GetSimulatorFeatures); the services answer FEATURE_UNSUPPORTED for the rest
COMMON_FEATURES = (SPAWNING, DELETING, NAMED_POSES, POSE_BOUNDS, ENTITY_TAGS, ENTITY_BOUNDS, ENTITY_BOUNDS_BOX,
                   ENTITY_CATEGORIES, ENTITY_STATE_GETTING, ENTITY_STATE_SETTING, ENTITY_INFO_GETTING, SPAWNABLES,
                   SIMULATION_STATE_GETTING, SPAWNING_ENTITIES)
STANDIN_FEATURES = COMMON_FEATURES + (SIMULATION_RESET, SIMULATION_STATE_SETTING, SIMULATION_STATE_PAUSE,
                                      STEP_SIMULATION_SINGLE, STEP_SIMULATION_MULTIPLE, STEP_SIMULATION_ACTION)
SIMTWO_FEATURES = COMMON_FEATURES
SPAWN_FORMATS = ("raf",)
PART_URI = "raf://part"
COLOURS = {"R": "red", "G": "green", "B": "blue"}
ROBOT = "robot"
PART_PREFIX = "part_"
WORLD_FRAMES = ("", "world", "map")  # + the bridge's own map frame
ANGLE_TOLERANCE = math.radians(1.0)  # roll and pitch within this count as planar
QUATERNION_TOLERANCE = 1e-3  # |q| - 1 within this is a unit quaternion


@dataclasses.dataclass
class Answer:
    """What a call returns: the standard's result code, a message (empty when OK) and the call's data."""

    result: int
    message: str = ""
    data: object = None

    @property
    def ok(self) -> bool:
        return self.result == OK


def fail(code: int, message: str) -> Answer:
    return Answer(code, message)


@dataclasses.dataclass(frozen=True)
class EntityState:
    """A ground-truth state in the field frame: pose (x, y, z, yaw) and twist (vx, vy world; wz) at ``time``."""

    x: float
    y: float
    z: float = 0.0
    yaw: float = 0.0
    vx: float = 0.0
    vy: float = 0.0
    wz: float = 0.0
    time: float = 0.0


@dataclasses.dataclass(frozen=True)
class Entity:
    name: str
    category: int
    tags: tuple[str, ...]
    description: str
    radius: float  # m: the circle around its position that holds it (bounds filters)
    state: EntityState


@dataclasses.dataclass(frozen=True)
class PartTruth:
    """One part as a backend sees it: ``on_field`` False when it is parked off the field (removed)."""

    id: int
    letter: str  # R, G, B, or "" when the backend does not know its colour
    x: float
    y: float
    facing: float
    on_field: bool


@dataclasses.dataclass(frozen=True)
class Snapshot:
    """A backend's ground truth: time, the robot's pose and twist (body v, w), the parts."""

    time: float
    pose: tuple[float, float, float]
    velocity: tuple[float, float]
    parts: tuple[PartTruth, ...]
    paused: bool | None  # None: the backend cannot tell


class Backend(Protocol):
    """A simulator as the standard's calls need it. Methods that change the world return an error message
    ("" on success); a backend that lacks an operation is never asked for it (its ``features``)."""

    name: str
    features: tuple[int, ...]

    def snapshot(self) -> Snapshot | str: ...

    def set_robot_pose(self, x: float, y: float, yaw: float) -> str: ...

    def place_part(self, pid: int, x: float, y: float, facing: float, letter: str | None) -> str: ...

    def remove_part(self, pid: int) -> str: ...

    def pause(self) -> str: ...

    def resume(self) -> str: ...

    def step(self, cycles: int) -> str: ...

    def reset(self) -> str: ...


# ---- pose helpers ----------------------------------------------------------------------------------------------
def yaw_of_quaternion(qx: float, qy: float, qz: float, qw: float) -> tuple[float | None, str]:
    """(yaw, "") of a planar unit quaternion; (None, why) when it is not unit length or tilts."""
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    if not all(math.isfinite(v) for v in (qx, qy, qz, qw)) or abs(n - 1.0) > QUATERNION_TOLERANCE:
        return None, f"the orientation is not a unit quaternion (norm {n:.6g})"
    qx, qy, qz, qw = qx / n, qy / n, qz / n, qw / n
    roll = math.atan2(2 * (qw * qx + qy * qz), 1 - 2 * (qx * qx + qy * qy))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (qw * qy - qz * qx))))
    if abs(roll) > ANGLE_TOLERANCE or abs(pitch) > ANGLE_TOLERANCE:
        return None, (f"roll {math.degrees(roll):.1f} deg, pitch {math.degrees(pitch):.1f} deg: the field is "
                      "planar (both must be 0)")
    return math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz)), ""


def quaternion_of_yaw(yaw: float) -> tuple[float, float, float, float]:
    return 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)


# ---- the calls ------------------------------------------------------------------------------------------------
Box = tuple  # (x_min, x_max, y_min, y_max, z_min, z_max), m, in an entity's or a named pose's own frame


def box_radius(box: Box) -> float:
    """The radius of the vertical cylinder about the frame's origin that holds ``box``'s footprint."""
    x0, x1, y0, y1 = box[:4]
    return math.hypot(max(abs(x0), abs(x1)), max(abs(y0), abs(y1)))


def part_box(part) -> Box:
    """A part (:class:`~robotatfactory.field.PartSpec`) in its frame: x along its plate's heading."""
    return (-part.depth / 2, part.depth / 2, -part.width / 2, part.width / 2, 0.0,
            part.feet_height + part.body_height)


class SimulationStandard:
    """The standard's calls on one field, over whichever backend ``backend()`` returns now (the connected
    simulator may change while the bridge runs). ``map_frame`` is the bridge's field frame; ``robot_box``
    (``base_link``) and ``part_box`` (:func:`part_box`) bound the entities (GetEntityBounds, bounds filters,
    named-pose bounds, spawnables)."""

    def __init__(self, field, backend, map_frame: str = "map",
                 robot_box: Box = (-0.075, 0.075, -0.075, 0.075, 0.0, 0.12), part_box_: Box | None = None):
        self.field = field
        self.backend = backend
        self.map_frame = map_frame
        self.robot_box = tuple(robot_box)
        self.part_box = tuple(part_box_) if part_box_ is not None else part_box(field.part)
        self.robot_radius, self.part_radius = box_radius(self.robot_box), box_radius(self.part_box)
        self.stopped = False  # SetSimulationState(STOPPED) until the next play, pause or step

    # -- features and state ------------------------------------------------------------------------------------
    def features(self) -> tuple[tuple[int, ...], tuple[str, ...], str]:
        b = self.backend()
        info = (f"robotatfactory: {b.name}; entities 'robot' and 'part_<id>' (parts on the field), poses in the "
                f"field frame '{self.map_frame}'; spawn: uri '{PART_URI}' or '{PART_URI}/red|green|blue' puts a "
                "removed part back; named poses: the slots and 'start'; docs/ros2.md")
        return tuple(sorted(b.features)), SPAWN_FORMATS, info

    def require(self, feature: int) -> Answer | None:
        """None when the connected simulator has ``feature``, else the FEATURE_UNSUPPORTED answer."""
        b = self.backend()
        if feature in b.features:
            return None
        return fail(FEATURE_UNSUPPORTED, f"{b.name} does not support this (see GetSimulatorFeatures: "
                                         f"{_feature_text(b.name)})")

    def simulation_state(self) -> Answer:
        if (a := self.require(SIMULATION_STATE_GETTING)) is not None:
            return a
        s = self.backend().snapshot()
        if isinstance(s, str):
            return fail(OPERATION_FAILED, s)
        if s.paused is None or not s.paused:
            return Answer(OK, data=PLAYING)
        return Answer(OK, data=STOPPED if self.stopped and s.time <= 0.0 else PAUSED)

    def set_simulation_state(self, target: int) -> Answer:
        if (a := self.require(SIMULATION_STATE_SETTING)) is not None:
            return a
        if target not in (STOPPED, PLAYING, PAUSED, QUITTING):
            return fail(INCORRECT_TRANSITION, f"state {target} is not one the simulation can be set to "
                                              "(STOPPED 0, PLAYING 1, PAUSED 2)")
        if target == QUITTING:
            return fail(FEATURE_UNSUPPORTED, "quitting: the bridge does not own the simulator's process (stop "
                                             "raf sim or raf up instead)")
        now = self.simulation_state()
        if not now.ok:
            return now
        if now.data == target:
            return fail(ALREADY_IN_TARGET_STATE, f"the simulation is already {STATE_NAMES[target]}")
        b = self.backend()
        if target == STOPPED:
            err = b.pause() or b.reset()
            if not err:
                self.stopped = True
        elif target == PAUSED:
            err = b.pause()
            self.stopped = False if not err else self.stopped
        else:
            err = b.resume()
            self.stopped = False if not err else self.stopped
        if err:
            return fail(STATE_TRANSITION_ERROR, err)
        return Answer(OK)

    def reset(self, scope: int) -> Answer:
        if (a := self.require(SIMULATION_RESET)) is not None:
            return a
        if scope not in (SCOPE_DEFAULT, SCOPE_ALL, SCOPE_TIME | SCOPE_STATE | SCOPE_SPAWNED):
            return fail(FEATURE_UNSUPPORTED, f"scope {scope}: the stand-in resets time, state and parts together "
                                             "(SCOPE_DEFAULT or SCOPE_ALL); it has no partial reset")
        err = self.backend().reset()
        return fail(OPERATION_FAILED, err) if err else Answer(OK)

    def step(self, steps: int) -> Answer:
        if (a := self.require(STEP_SIMULATION_MULTIPLE if steps > 1 else STEP_SIMULATION_SINGLE)) is not None:
            return a
        if steps < 1:
            return fail(OPERATION_FAILED, f"steps = {steps}: step at least one control cycle (40 ms)")
        s = self.backend().snapshot()
        if isinstance(s, str):
            return fail(OPERATION_FAILED, s)
        if not s.paused:
            return fail(OPERATION_FAILED, "the simulation is playing: pause it first (SetSimulationState PAUSED)")
        err = self.backend().step(steps)
        if not err:
            self.stopped = False
        return fail(OPERATION_FAILED, err) if err else Answer(OK)

    # -- entities ----------------------------------------------------------------------------------------------
    def entities(self) -> Answer:
        """Answer with data = [Entity] of the robot and the parts on the field."""
        s = self.backend().snapshot()
        if isinstance(s, str):
            return fail(OPERATION_FAILED, s)
        v, w = s.velocity
        x, y, th = s.pose
        out = [Entity(ROBOT, CATEGORY_ROBOT, ("robot",), "the RobotAtFactory robot (differential drive)",
                      self.robot_radius, EntityState(x, y, 0.0, th, v * math.cos(th), v * math.sin(th), w, s.time))]
        for p in s.parts:
            if not p.on_field:
                continue
            colour = COLOURS.get(p.letter, "")
            tags = ("part", colour) if colour else ("part",)
            out.append(Entity(f"{PART_PREFIX}{p.id}", CATEGORY_DYNAMIC_OBJECT, tags,
                              f"part {p.id}" + (f" ({colour})" if colour else ""), self.part_radius,
                              EntityState(p.x, p.y, 0.0, p.facing, time=s.time)))
        return Answer(OK, data=out)

    def filtered(self, pattern: str = "", categories=(), tags=(), tags_mode: int = FILTER_MODE_ANY,
                 bounds_type: int = BOUNDS_EMPTY, points=()) -> Answer:
        """GetEntities / GetEntitiesStates: the entities that pass every filter given."""
        if tags and (a := self.require(ENTITY_TAGS)) is not None:
            return a
        if categories and (a := self.require(ENTITY_CATEGORIES)) is not None:
            return a
        try:
            rx = re.compile(pattern) if pattern else None
        except re.error as e:
            return fail(OPERATION_FAILED, f"filter {pattern!r} is not a regular expression: {e}")
        if bounds_type not in (BOUNDS_EMPTY, BOUNDS_SPHERE, BOUNDS_BOX):
            return fail(FEATURE_UNSUPPORTED, f"bounds type {bounds_type}: supported are TYPE_SPHERE and TYPE_BOX")
        if bounds_type == BOUNDS_SPHERE and len(points) != 2 or bounds_type == BOUNDS_BOX and len(points) != 2:
            return fail(OPERATION_FAILED, f"bounds type {bounds_type} needs 2 points, got {len(points)}")
        if tags_mode not in (FILTER_MODE_ANY, FILTER_MODE_ALL):
            return fail(OPERATION_FAILED, f"tags filter_mode {tags_mode}: FILTER_MODE_ANY 0 or FILTER_MODE_ALL 1")
        a = self.entities()
        if not a.ok:
            return a
        out = []
        for e in a.data:
            if rx is not None and not rx.search(e.name):
                continue
            if categories and e.category not in categories:
                continue
            if tags and not (all if tags_mode == FILTER_MODE_ALL else any)(t in e.tags for t in tags):
                continue
            if bounds_type != BOUNDS_EMPTY and not _overlaps(e, bounds_type, points):
                continue
            out.append(e)
        return Answer(OK, data=out)

    def entity(self, name: str) -> Answer:
        a = self.entities()
        if not a.ok:
            return a
        for e in a.data:
            if e.name == name:
                return Answer(OK, data=e)
        return fail(NOT_FOUND, f"no entity {name!r}: the entities are {', '.join(e.name for e in a.data)}")

    def entity_state(self, name: str) -> Answer:
        if (a := self.require(ENTITY_STATE_GETTING)) is not None:
            return a
        return self.entity(name)

    def entity_info(self, name: str) -> Answer:
        if (a := self.require(ENTITY_INFO_GETTING)) is not None:
            return a
        return self.entity(name)

    def _frame_ok(self, frame: str) -> str:
        if frame in WORLD_FRAMES or frame == self.map_frame:
            return ""
        return f"frame {frame!r}: poses are given in the field frame ('{self.map_frame}', 'world' or '')"

    def set_entity_state(self, name: str, frame: str, x: float, y: float, q, twist) -> Answer:
        if (a := self.require(ENTITY_STATE_SETTING)) is not None:
            return a
        if err := self._frame_ok(frame):
            return fail(INVALID_POSE, err)
        yaw, err = yaw_of_quaternion(*q)
        if yaw is None:
            return fail(INVALID_POSE, err)
        if any(abs(v) > 1e-9 for v in twist):
            return fail(OPERATION_FAILED, "setting a velocity is not supported: the robot moves by cmd_vel, the "
                                          "parts by the robot (the twist must be zero)")
        if not (math.isfinite(x) and math.isfinite(y)) or not self.field.floor.contains(x, y):
            return fail(INVALID_POSE, f"({x:g}, {y:g}) is not on the field's floor")
        if name == ROBOT:
            err = self.backend().set_robot_pose(x, y, yaw)
            return fail(OPERATION_FAILED, err) if err else Answer(OK)
        a = self.entity(name)
        if not a.ok:
            return a
        err = self.backend().place_part(_part_id(name), x, y, yaw, None)
        return fail(OPERATION_FAILED, err) if err else Answer(OK)

    def delete(self, name: str) -> Answer:
        if (a := self.require(DELETING)) is not None:
            return a
        if name == ROBOT:
            return fail(OPERATION_FAILED, "the robot cannot be deleted (only parts can)")
        a = self.entity(name)
        if not a.ok:
            return a
        err = self.backend().remove_part(_part_id(name))
        return fail(OPERATION_FAILED, err) if err else Answer(OK)

    def spawn(self, name: str, allow_renaming: bool, uri: str, resource_string: str, namespace: str,
              frame: str, x: float, y: float, q) -> Answer:
        """Put a part that is off the field back on it; data = the entity's name."""
        if (a := self.require(SPAWNING)) is not None:
            return a
        if not uri:
            if resource_string:
                return fail(FEATURE_UNSUPPORTED, "resource_string is not supported (SPAWNING_RESOURCE_STRING): "
                                                 f"use uri '{PART_URI}'")
            return fail(NO_RESOURCE, f"uri and resource_string are both empty: use uri '{PART_URI}'")
        letter = _letter_of(uri)
        if letter is None:
            return fail(UNSUPPORTED_FORMAT, f"uri {uri!r}: the spawnable resources are '{PART_URI}' and "
                                            f"'{PART_URI}/red', '/green', '/blue' (parts only)")
        if namespace:
            return fail(OPERATION_FAILED, "a part has no interfaces to put in a namespace (entity_namespace "
                                          "must be empty)")
        if err := self._frame_ok(frame):
            return fail(INVALID_SPAWN_POSE, err)
        yaw, err = yaw_of_quaternion(*q)
        if yaw is None:
            return fail(INVALID_SPAWN_POSE, err)
        if not (math.isfinite(x) and math.isfinite(y)) or not self.field.floor.contains(x, y):
            return fail(INVALID_SPAWN_POSE, f"({x:g}, {y:g}) is not on the field's floor")
        s = self.backend().snapshot()
        if isinstance(s, str):
            return fail(OPERATION_FAILED, s)
        on = {f"{PART_PREFIX}{p.id}" for p in s.parts if p.on_field}
        off = [p for p in s.parts if not p.on_field]
        if name:
            if name in on or name == ROBOT:
                if not allow_renaming:
                    return fail(NAME_NOT_UNIQUE, f"{name!r} is on the field already")
                name = ""
            elif not name.startswith(PART_PREFIX) or _part_id(name) not in {p.id for p in off}:
                if not allow_renaming:
                    return fail(NAME_INVALID, f"name {name!r}: a spawned part takes the name of a part off the "
                                              f"field: {', '.join(f'{PART_PREFIX}{p.id}' for p in off) or 'none'}")
                name = ""
        elif not allow_renaming:
            return fail(NAME_INVALID, "the name is empty and allow_renaming is false")
        if not name:
            if not off:
                return fail(OPERATION_FAILED, f"every part of the scene ({len(s.parts)}) is on the field: delete "
                                              "one first (the scene has a fixed set of parts)")
            name = f"{PART_PREFIX}{off[0].id}"
        err = self.backend().place_part(_part_id(name), x, y, yaw, letter or None)
        return fail(OPERATION_FAILED, err) if err else Answer(OK, data=name)

    def entity_bounds(self, name: str) -> Answer:
        """data = the entity's box in its own frame (TYPE_BOX)."""
        if (a := self.require(ENTITY_BOUNDS)) is not None:
            return a
        a = self.entity(name)
        if not a.ok:
            return a
        return Answer(OK, data=self.robot_box if name == ROBOT else self.part_box)

    def spawnables(self, sources=()) -> Answer:
        """data = [(uri, description, box)]; a source given is not searched (there is nothing to search)."""
        if (a := self.require(SPAWNABLES)) is not None:
            return a
        b = self.backend()
        out = [(PART_URI, "a part of the scene that is off the field, put back with its own colour",
                self.part_box)]
        if b.name == "stand-in":
            out += [(f"{PART_URI}/{c}", f"a part of the scene that is off the field, put back {c}", self.part_box)
                    for c in COLOURS.values()]
        msg = f"sources not searched (the scene's parts are all there is): {', '.join(sources)}" if sources else ""
        return Answer(OK, msg, out)

    def spawn_many(self, requests) -> Answer:
        """SpawnEntities: ``requests`` are keyword dicts of :meth:`spawn`; data = [Answer] in order."""
        if (a := self.require(SPAWNING_ENTITIES)) is not None:
            return a
        results = [self.spawn(**r) for r in requests]
        failed = sum(not r.ok for r in results)
        if failed:
            return Answer(ENTITIES_SPAWN_FAILED, f"{failed} of {len(results)} spawn requests failed", results)
        return Answer(OK, data=results)

    def named_pose_bounds(self, name: str) -> Answer:
        """data = the named pose's box in the pose's frame: a slot's part, the start area (robot height)."""
        if (a := self.require(POSE_BOUNDS)) is not None:
            return a
        a = self.named_poses()
        if not a.ok:
            return a
        poses = {p[0]: p for p in a.data}
        if name not in poses:
            return fail(NOT_FOUND, f"no named pose {name!r}: the named poses are {', '.join(poses)}")
        if name != "start":
            return Answer(OK, data=self.part_box)
        _, _, _, px, py, yaw = poses[name]
        area = self.field.start_area
        c, s_ = math.cos(yaw), math.sin(yaw)
        local = [((x - px) * c + (y - py) * s_, -(x - px) * s_ + (y - py) * c) for x in area.x for y in area.y]
        xs, ys = [p[0] for p in local], [p[1] for p in local]
        return Answer(OK, data=(min(xs), max(xs), min(ys), max(ys), 0.0, self.robot_box[5]))

    # -- named poses -------------------------------------------------------------------------------------------
    def named_poses(self, tags=(), tags_mode: int = FILTER_MODE_ANY) -> Answer:
        """data = [(name, description, tags, x, y, yaw)]: the slots and the start pose."""
        if (a := self.require(NAMED_POSES)) is not None:
            return a
        sp = self.field.start_pose
        out = [("start", "the robot's start pose (the centre of the start area)", ("start", "spawn"),
                sp.x, sp.y, sp.theta)]
        for s in self.field.slots:
            out.append((s.name, f"{s.role} slot {s.number} of {s.zone}: a part's pose there (yaw = its plate's "
                                "heading)",
                        ("slot", str(s.zone)), s.xy[0], s.xy[1], s.facing))
        if tags:
            pick = all if tags_mode == FILTER_MODE_ALL else any
            out = [p for p in out if pick(t in p[2] for t in tags)]
        return Answer(OK, data=out)


def _part_id(name: str) -> int:
    try:
        return int(name[len(PART_PREFIX):])
    except ValueError:
        return -1


def _letter_of(uri: str) -> str | None:
    """'' for raf://part (keep the colour), R/G/B for raf://part/<colour>, None for anything else."""
    if uri.rstrip("/") == PART_URI:
        return ""
    by_name = {v: k for k, v in COLOURS.items()}
    head, _, colour = uri.rpartition("/")
    if head == PART_URI and colour in by_name:
        return by_name[colour]
    return None


def _overlaps(e: Entity, kind: int, points) -> bool:
    (ax, ay, az), (bx, by, bz) = points
    s = e.state
    if kind == BOUNDS_SPHERE:
        return math.dist((s.x, s.y, s.z), (ax, ay, az)) <= bx + e.radius
    lo, hi = (min(ax, bx), min(ay, by), min(az, bz)), (max(ax, bx), max(ay, by), max(az, bz))
    dx = max(lo[0] - s.x, 0.0, s.x - hi[0])
    dy = max(lo[1] - s.y, 0.0, s.y - hi[1])
    return math.hypot(dx, dy) <= e.radius and lo[2] - e.radius <= s.z <= hi[2] + e.radius


def _feature_text(name: str) -> str:
    return {"stand-in": "everything but partial resets, velocities, resource strings and worlds",
            "simtwo": "entities, spawn/delete of parts, named poses and the state; no reset, pause or step "
                      "(SimTwo's script API has no call for them)"}.get(name, name)


class StandInBackend:
    """The stand-in (``raf sim``) through its control channel (:mod:`robotatfactory.sim.control`): every feature
    but partial resets. ``client`` is a :class:`~robotatfactory.sim.control.ControlClient`; ``reset`` replaces
    the plain reset request when the caller has more to do around it (the bridge expects the new stream): it
    returns "" or why it failed."""

    name = "stand-in"
    features = STANDIN_FEATURES

    def __init__(self, client, reset=None):
        self.client = client
        self._reset = reset

    def call(self, op: str, **fields) -> tuple[str, dict]:
        """One control-channel request: ("", reply) or (why it failed, the reply or {})."""
        try:
            r = self.client.request(op, **fields)
        except ConnectionError as e:
            return str(e), {}
        if not r.get("ok"):
            return f"{r.get('error')}: {r.get('message')}", r
        return "", r

    def snapshot(self) -> Snapshot | str:
        err, r = self.call("get_state")
        if err:
            return err
        parts = tuple(PartTruth(p["id"], p["type"], *p["pose"], on_field=not p["removed"]) for p in r["parts"])
        return Snapshot(float(r["time"]), tuple(r["pose"]), tuple(r["velocity"]), parts, bool(r["paused"]))

    def set_robot_pose(self, x, y, yaw) -> str:
        return self.call("set_robot_pose", x=x, y=y, theta=yaw)[0]

    def place_part(self, pid, x, y, facing, letter) -> str:
        fields = {"part": pid, "x": x, "y": y, "facing": facing}
        if letter:
            fields["type"] = letter
        return self.call("place_part", **fields)[0]

    def remove_part(self, pid) -> str:
        return self.call("remove_part", part=pid)[0]

    def pause(self) -> str:
        return self.call("pause")[0]

    def resume(self) -> str:
        return self.call("resume")[0]

    def step(self, cycles) -> str:
        return self.call("step", cycles=int(cycles))[0]

    def reset(self) -> str:
        return self._reset() if self._reset is not None else self.call("reset")[0]
