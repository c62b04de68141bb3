"""A world that is not the map (issue 20, sim/perturb.py): each perturbation happens, is seeded and
deterministic, does not change another's draw, and is off by default; the simulator builds the world from it
while its nominal map and robot stay as given."""
import dataclasses
import math

import numpy as np
import pytest

from robotatfactory.errors import ConfigError
from robotatfactory.field import load_field
from robotatfactory.robot import load_robot
from robotatfactory.sim import Simulator
from robotatfactory.sim import perturb as pt
from robotatfactory.sim.config import SimConfig, sim_config

FIELD, ROBOT = load_field(), load_robot()


def test_off_by_default():
    assert not SimConfig().perturb.any and SimConfig().perturb.describe() == "none"
    w = pt.World.draw(FIELD, ROBOT, pt.Perturb(), 3, 7)
    assert w.field is FIELD and w.robot is ROBOT and w.start is None and w.offsets(FIELD, ROBOT) == {}
    sim = Simulator(FIELD, ROBOT, sim_config({"round_no": 3, "seed": 7, "camera": False, "lidar": False}))
    assert sim.world is None and sim.field is FIELD and sim.robot is ROBOT
    for pid, _, slot in sim.factory.initial_parts():
        assert math.dist(sim.part_pose(pid)[:2], slot.xy) < 1e-4
    sim.close()


def test_the_field_is_displaced_rigidly_per_fixture_and_seeded():
    f1 = pt.displaced_field(FIELD, 0.003, 2, 100)
    f2 = pt.displaced_field(FIELD, 0.003, 2, 100)
    f3 = pt.displaced_field(FIELD, 0.003, 2, 101)
    d = [math.dist(a.xy, b.xy) for a, b in zip(FIELD.slots, f1.slots)]
    assert all(x > 0 for x in d) and max(d) < 0.02  # every slot moved, by a few mm (3 sigma + the turn at most)
    assert [s.xy for s in f1.slots] == [s.xy for s in f2.slots]  # deterministic
    assert [s.xy for s in f1.slots] != [s.xy for s in f3.slots]  # another seed, another world
    # rigid per fixture: distances between a fixture's slots are kept
    for zone in pt.FIXTURES:
        a, b = FIELD.slots_of(zone), f1.slots_of(zone)
        assert math.dist(a[0].xy, a[-1].xy) == pytest.approx(math.dist(b[0].xy, b[-1].xy), abs=1e-9)
    # wall markers move with their fixture, floor markers with their sheet; sizes and ids unchanged
    m = [float(np.linalg.norm(a.position - b.position)) for a, b in zip(FIELD.markers, f1.markers)]
    assert all(0 < x < 0.02 for x in m) and f1.marker_ids == FIELD.marker_ids
    assert f1.marker(50).position[2] == pytest.approx(FIELD.marker(50).position[2])
    assert all(0 < math.dist(a.center[:2], b.center[:2]) < 0.02 for a, b in zip(FIELD.boxes, f1.boxes))
    assert pt.displaced_field(FIELD, 0.0, 2, 100) is FIELD


def test_parts_are_put_in_off_centre_but_never_into_the_wall():
    p = pt.Perturb(parts_mm=3.0, parts_deg=2.0)
    slot = FIELD.slot("incoming", 2)
    poses = [pt.part_pose(FIELD, slot, pid, p, 3, s) for s in range(20) for pid in (1, 2)]
    assert len({q for q in poses}) == len(poses)
    assert pt.part_pose(FIELD, slot, 2, p, 3, 5) == pt.part_pose(FIELD, slot, 2, p, 3, 5)
    for x, y, f in poses:
        away = (x - slot.xy[0]) * math.cos(slot.facing) + (y - slot.xy[1]) * math.sin(slot.facing)
        dth = f - slot.facing
        assert away >= FIELD.part.width / 2 * abs(math.sin(dth)) - 1e-12  # its back corners clear the wall
        assert math.dist((x, y), slot.xy) < 0.015 and abs(math.degrees(dth)) <= 6.0 + 1e-9
    assert pt.part_pose(FIELD, slot, 2, pt.Perturb(), 3, 5) == (*slot.xy, slot.facing)


def test_the_start_pose_is_drawn_inside_the_start_area():
    p = pt.Perturb(start_cm=3.0, start_deg=3.0)
    sp = FIELD.start_pose
    poses = [pt.start_pose(FIELD, (sp.x, sp.y, sp.theta), p, 1, s) for s in range(30)]
    assert len(set(poses)) == 30 and poses[0] == pt.start_pose(FIELD, (sp.x, sp.y, sp.theta), p, 1, 0)
    a = FIELD.start_area
    for x, y, th in poses:
        assert a.x[0] + 0.15 - 1e-9 <= x <= a.x[1] - 0.15 + 1e-9 or a.x[1] - a.x[0] < 0.3
        assert a.contains(x, y) and abs(math.degrees(th - sp.theta)) <= 9.0 + 1e-9
    assert max(math.dist(q[:2], (sp.x, sp.y)) for q in poses) > 0.01


def test_the_rendering_camera_differs_from_the_robot_files():
    p = pt.Perturb(camera_pct=2.0, camera_px=3.0, camera_deg=1.0)
    c0 = ROBOT.camera
    c1, c2 = pt.true_camera(c0, p, 3, 100), pt.true_camera(c0, p, 3, 100)
    assert c1 == c2 and c1 != c0 and pt.true_camera(c0, p, 3, 101) != c1
    assert 0 < abs(c1.fx / c0.fx - 1) <= 0.06 and 0 < abs(c1.cx - c0.cx) <= 9.0
    assert 0 < abs(c1.pitch_down_deg - c0.pitch_down_deg) <= 3.0 and c1.width == c0.width
    assert pt.true_camera(c0, pt.Perturb(), 3, 100) is c0


def test_one_perturbation_does_not_change_anothers_draw():
    a = pt.World.draw(FIELD, ROBOT, pt.Perturb(field_mm=2.0), 2, 3)
    b = pt.World.draw(FIELD, ROBOT, pt.ISSUE_20, 2, 3)
    assert [s.xy for s in a.field.slots] == [s.xy for s in b.field.slots]


def test_the_simulator_builds_the_world_and_keeps_the_nominal_map():
    cfg = sim_config({"round_no": 3, "seed": 100, "camera": False, "lidar": False,
                      "perturb": dataclasses.asdict(pt.ISSUE_20)})
    sim = Simulator(FIELD, ROBOT, cfg)
    assert sim.nominal_field is FIELD and sim.nominal_robot is ROBOT and sim.world is not None
    assert sim.field is not FIELD and sim.factory.field is sim.field  # the referee scores in the world's slots
    assert sim.robot.camera != ROBOT.camera
    import mujoco  # the camera the scene renders with is the world's, not the robot file's

    cid = mujoco.mj_name2id(sim.model, mujoco.mjtObj.mjOBJ_CAMERA, sim._camera_name)
    assert sim.model.cam_intrinsic[cid][0] * 1e5 == pytest.approx(sim.robot.camera.fx, rel=1e-5)
    assert abs(sim.robot.camera.fx - ROBOT.camera.fx) > 0.01
    off = sim.world.offsets(FIELD, ROBOT)
    assert {"field_slot_max_mm", "start_error_cm", "camera_fx_error_pct"} <= set(off)
    sp = FIELD.start_pose
    assert math.dist(sim.pose[:2], (sp.x, sp.y)) == pytest.approx(off["start_error_cm"] / 100, abs=2e-3)
    for pid, _, slot in sim.factory.initial_parts():  # put in off centre, and they stayed there (not in a wall)
        drawn = pt.part_pose(sim.field, slot, pid, cfg.perturb, 3, 100)
        assert math.dist(sim.part_pose(pid)[:2], drawn[:2]) < 1e-3
        assert sim.factory.slot_of(pid) == slot
    sim.close()
    again = Simulator(FIELD, ROBOT, cfg)
    assert again.pose == pytest.approx(sim.pose) and [s.xy for s in again.field.slots] == [s.xy for s in sim.field.slots]
    again.close()


def test_sizes_are_checked_settings():
    assert sim_config({"perturb": {"parts_deg": 2}}).perturb.parts_deg == 2.0
    with pytest.raises(ConfigError, match="perturb.field_mm"):
        sim_config({"perturb": {"field_mm": -1}})
    with pytest.raises(ConfigError, match="perturb"):
        sim_config({"perturb": {"walls_mm": 1}})
