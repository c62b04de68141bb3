"""The competition map against the rules (tests/data/raf4-*.json are copies of the reference tables)."""
import json
import math
from pathlib import Path

import numpy as np
import pytest

from robotatfactory.field import FieldError, available_fields, load_field

DATA = Path(__file__).parent / "data"
REF = json.loads((DATA / "raf4-markers.json").read_text())


def test_shipped_fields():
    assert {"rules2026", "simtwo2022"} <= set(available_fields())


def test_all_49_markers_with_unique_ids(field):
    ids = [m.id for m in field.markers]
    assert len(ids) == 49 and len(set(ids)) == 49
    assert len(field.floor_markers()) == 33 and len(field.wall_markers()) == 16
    assert set(ids) == set(range(0, 27)) | set(range(30, 36)) | set(range(50, 66))


def test_marker_sizes(field):
    assert {m.size for m in field.floor_markers()} == {0.06}
    assert {m.size for m in field.wall_markers()} == {0.04}


@pytest.mark.parametrize("ref", REF["markers"], ids=lambda r: f"id{r['id']}")
def test_corners_match_rules_table(field, ref):
    m = field.marker(ref["id"])
    np.testing.assert_allclose(m.corners, np.array(ref["corners"]), atol=1e-9)
    np.testing.assert_allclose(m.position, [ref["x"], ref["y"], ref["z"]], atol=1e-12)
    np.testing.assert_allclose(m.normal, ref["normal"], atol=1e-9)
    q = m.quaternion_xyzw
    assert abs(abs(np.dot(q, ref["quat_xyzw"])) - 1) < 1e-5  # same rotation (q and -q); table rounded to 1e-6


def test_pose_is_rigid_and_corner_order(field):
    for m in field.markers:
        R = m.rotation
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        c = m.corners
        # OpenCV order: TL, TR, BR, BL -> (TR - TL) x (BL - TL) points INTO the face (clockwise seen from the front)
        n = np.cross(c[1] - c[0], c[3] - c[0])
        assert np.dot(n, m.normal) < 0
        np.testing.assert_allclose(np.linalg.norm(c[1] - c[0]), m.size)


def test_floor_markers_lie_flat_top_edge_towards_plus_y(field):
    for m in field.floor_markers():
        assert m.position[2] == 0 and m.normal[2] == pytest.approx(1)
        top_mid = (m.corners[0] + m.corners[1]) / 2
        assert top_mid[1] > m.position[1]


def _inside_box(p, box, margin=0.0):
    c, h = np.asarray(box.center), box.half_extents
    assert box.yaw == 0
    return bool(np.all(np.abs(np.asarray(p) - c) < h + margin))


def test_every_wall_marker_sits_on_a_wall_face_facing_the_open_side(field):
    for m in field.wall_markers():
        p, n = m.position, m.normal
        assert abs(n[2]) < 1e-9, f"marker {m.id} should face horizontally"
        behind = p - n * 0.005
        front = p + n * 0.005
        assert any(_inside_box(behind, b) for b in field.boxes), f"marker {m.id}: no wall behind it"
        # the open side: the space in front is free of walls and ribs for at least 5 cm
        for d in np.linspace(0.002, 0.05, 25):
            q = p + n * d
            assert not any(_inside_box(q, b) for b in field.boxes), f"marker {m.id} faces a wall at {d:.3f} m"
        assert not any(_inside_box(front, b) for b in field.boxes)
        # markers centred 0.10 m above the floor
        assert p[2] == pytest.approx(0.10)


def test_wall_marker_facing_directions(field):
    expect = {**{i: (0, -1) for i in range(50, 54)}, **{i: (0, 1) for i in range(62, 66)},
              54: (-1, 0), 56: (-1, 0), 58: (-1, 0), 60: (-1, 0), 55: (1, 0), 57: (1, 0), 59: (1, 0), 61: (1, 0)}
    for i, (nx, ny) in expect.items():
        np.testing.assert_allclose(field.marker(i).normal[:2], (nx, ny), atol=1e-9)


def test_markers_54_55_at_y_0150_in_2026(field):
    assert field.marker(54).position[1] == pytest.approx(0.150)
    assert field.marker(55).position[1] == pytest.approx(0.150)


def test_slots_and_server_numbering(field):
    assert len(field.slots_of("incoming")) == 4 and len(field.slots_of("outgoing")) == 4
    for zone in ("incoming", "outgoing"):
        xs = [s.xy[0] for s in field.slots_of(zone)]
        assert xs == sorted(xs), "warehouse slots are numbered by increasing x"
    for zone in ("machine_A", "machine_B"):
        s = {n: field.slot(zone, n) for n in (1, 2, 3, 4)}
        # 1 2 / 3 4 with 1 upper left: 1 left of 2, 1 above 3; inputs on the -x side, outputs on +x
        assert s[1].xy[0] < s[2].xy[0] and s[3].xy[0] < s[4].xy[0]
        assert s[1].xy[1] > s[3].xy[1] and s[2].xy[1] > s[4].xy[1]
        assert s[1].role == s[3].role == "input" and s[2].role == s[4].role == "output"
    assert field.slot("machine_A", 1).xy == (-0.3875, 0.0)
    assert field.slot("machine_B", 4).xy == (0.3875, 0.0)
    assert field.slot("incoming", 1).xy == (-0.695, 0.535)
    assert field.slot("outgoing", 4).xy == (0.695, -0.535)


def _part_footprint(field, slot):
    c, s = math.cos(slot.facing), math.sin(slot.facing)
    hx, hy = field.part.depth / 2, field.part.width / 2
    local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    return local @ np.array([[c, s], [-s, c]]) + np.asarray(slot.xy)


def test_parts_in_slots_touch_their_wall_and_hit_nothing(field):
    """A part's back touches the wall (warehouses: back wall; machines: central wall), plate towards the field."""
    for slot in field.slots:
        back = np.asarray(slot.xy) - np.array([math.cos(slot.facing), math.sin(slot.facing)]) * field.part.depth / 2
        wall = {"incoming": "incoming_wh_back_wall", "outgoing": "outgoing_wh_back_wall",
                "machine_A": "machine_A_center_wall", "machine_B": "machine_B_center_wall"}[slot.zone]
        box = next(b for b in field.boxes if b.name == wall)
        lo = np.asarray(box.center[:2]) - box.half_extents[:2]
        hi = np.asarray(box.center[:2]) + box.half_extents[:2]
        dist = np.max(np.maximum(lo - back, back - hi))  # 0 on the box surface
        assert abs(dist) < 1e-9, f"{slot.name}: back is {dist:.4f} m from {wall}"
        fp = _part_footprint(field, slot)
        for b in field.boxes:
            blo = np.asarray(b.center[:2]) - b.half_extents[:2]
            bhi = np.asarray(b.center[:2]) + b.half_extents[:2]
            overlap = np.all(fp.max(0) > blo + 1e-9) and np.all(fp.min(0) < bhi - 1e-9)
            assert not overlap, f"{slot.name} overlaps {b.name}"


def test_start_area_and_pose(field):
    sp = field.start_pose
    assert field.start_area.contains(sp.x, sp.y)
    assert sp.theta == pytest.approx(math.pi / 2)
    assert len(field.team_areas) == 6
    for (bx, by) in field.beacons:
        assert any(t.contains(bx, by) for t in field.team_areas)
        assert not field.floor.contains(bx, by)


def test_simtwo2022_differences(field):
    f22 = load_field("simtwo2022")
    assert {m.size for m in f22.wall_markers()} == {0.055}
    assert {m.size for m in f22.floor_markers()} == {0.06}
    for a, b in [(56, 61), (54, 59)]:
        np.testing.assert_allclose(f22.marker(a).position[1], field.marker(b).position[1])
        np.testing.assert_allclose(f22.marker(b).normal, field.marker(a).normal, atol=1e-12)
    # 62-65: SimTwo shows them mirrored (their readable face lies against the wall: tests/test_simtwo_field.py)
    assert not any(f22.has_marker(i) for i in range(62, 66))
    for m in field.wall_markers():  # same facings as the rules' marker of that pose
        if f22.has_marker(m.id):
            np.testing.assert_allclose(np.abs(f22.marker(m.id).normal), np.abs(m.normal), atol=1e-12)
    # in-plane, as SimTwo turns its marker plates (read back from SimTwo and seen by its camera): the incoming
    # warehouse's top edges point -x, the machines' +y on their east faces and -y on their west faces
    for i in range(50, 54):
        np.testing.assert_allclose(f22.marker(i).rotation[:, 1], [-1, 0, 0], atol=1e-12)
    for i in (54, 55, 56, 57):
        np.testing.assert_allclose(f22.marker(i).rotation[:, 1], [0, 1, 0], atol=1e-12)
    for i in (58, 59, 60, 61):
        np.testing.assert_allclose(f22.marker(i).rotation[:, 1], [0, -1, 0], atol=1e-12)


# SimTwo's RobotFactoryPro2022 scene (P33a/SimTwo): scene.xml places the incoming warehouse at (-0.47, 0.54),
# the outgoing one at (0.47, -0.54) turned 180 degrees, machine A at (-0.695/2, -0.075) and B at
# (0.695/2, 0.075) turned -90 degrees; wharehouse*.xml and machines*.xml build them from these constants.
# The map's z = 0 is the surface the robot drives on: the top of field_pro.xml's 1 mm field cuboid.
XML = dict(base_height=0.002, cell_x=0.15, cell_y=0.08, wall_height=0.065, wall_thickness=0.02,
           marker_thickness=0.001, field_height=0.001, wh_y=0.54, machine_x=0.695 / 2)


def test_simtwo2022_wall_markers_where_simtwos_scene_puts_them():
    """Warehouse markers on the back wall's field side (cell_y/2 - wall_thickness/2 out, minus the 1 mm
    marker plate): |y| = 0.569 (the 1 mm plate's centre is SimTwo's 0.5695); machine markers 1 mm off the
    machine wall's faces; all at base_height + 1.5 wall_height above the floor cuboid (world 0.0995)."""
    x = XML
    f22 = load_field("simtwo2022")
    face_y = x["wh_y"] + x["cell_y"] / 2 - x["wall_thickness"] / 2 - x["marker_thickness"]
    z = x["base_height"] + 1.5 * x["wall_height"] - x["field_height"]
    assert face_y == pytest.approx(0.569) and z == pytest.approx(0.0985)
    for m in f22.wall_markers():
        p, n = m.position, m.normal
        assert p[2] == pytest.approx(z)
        if m.id in range(50, 54) or m.id in range(62, 66):
            assert abs(p[1]) == pytest.approx(face_y) and n[1] == pytest.approx(-np.sign(p[1]))
        else:
            off = x["wall_thickness"] / 2 + x["marker_thickness"]
            assert abs(p[0]) == pytest.approx(x["machine_x"] + (off if abs(p[0]) > x["machine_x"] else -off))
            assert n[0] == pytest.approx(np.sign(abs(p[0]) - x["machine_x"]) * np.sign(p[0]))
        # the marker plate (1 mm) stands on a wall face; in front of it 5 cm are free
        assert any(_inside_box(p - n * 0.0015, b) for b in f22.boxes), m.id
        assert not any(_inside_box(p - n * 0.0005, b) for b in f22.boxes), m.id
        for d in np.linspace(0.001, 0.05, 25):
            assert not any(_inside_box(p + n * d, b) for b in f22.boxes), (m.id, d)
    # IDs by position as in SimTwo's textures
    assert f22.marker(56).position[:2] == pytest.approx([-0.3365, -0.15])  # machinesA.xml BR
    assert f22.marker(54).position[:2] == pytest.approx([0.3585, 0.0])  # machinesB.xml BR


def test_simtwo2022_walls_and_ribs():
    """Warehouse back walls 5 mm further out (centre |y| 0.58) and 0.13 m tall from 1 mm above the floor;
    warehouse ribs 0.08 m deep reaching into the back wall; machine ribs 0.18 m long (rules: 0.16)."""
    f22, rules = load_field("simtwo2022"), load_field("rules2026")
    b = {x.name: x for x in f22.boxes}
    r = {x.name: x for x in rules.boxes}
    assert set(b) == set(r)
    for side, s in (("incoming", 1), ("outgoing", -1)):
        w = b[f"{side}_wh_back_wall"]
        assert w.center[1] == pytest.approx(0.58 * s) and w.size == pytest.approx((0.62, 0.02, 0.13))
        assert w.center[2] - w.size[2] / 2 == pytest.approx(0.001)
        for i in range(5):
            rib = b[f"{side}_wh_rib{i}"]
            assert rib.center[0] == pytest.approx(r[f"{side}_wh_rib{i}"].center[0])
            assert rib.center[1] == pytest.approx(0.54 * s) and rib.size[:2] == pytest.approx((0.02, 0.08))
            assert rib.center[2] + rib.size[2] / 2 == pytest.approx(0.064)
    for mach in ("A", "B"):
        for i in range(3):
            rib, rr = b[f"machine_{mach}_rib{i}"], r[f"machine_{mach}_rib{i}"]
            assert rib.size[:2] == pytest.approx((0.18, 0.02)) and rib.center[:2] == pytest.approx(rr.center[:2])
        cw = b[f"machine_{mach}_center_wall"]
        assert cw.size == pytest.approx((0.02, 0.32, 0.13)) and cw.center[:2] == pytest.approx(
            r[f"machine_{mach}_center_wall"].center[:2])
    assert f22.floor.x == (-0.84, 0.84) and f22.floor.y == (-0.59, 0.59)  # field_pro.xml: 1.68 x 1.18 m


def test_simtwo2022_floor_markers_shifted_as_printed_in_the_field_texture(field):
    """field_pro.jpg as SimTwo maps it puts every floor marker 6.75 mm towards -y of the rules' map, x and
    rotation unchanged; side 0.06 m (measured 0.0598-0.0600 m)."""
    f22 = load_field("simtwo2022")
    assert len(f22.floor_markers()) == len(field.floor_markers()) == 33
    for m in field.floor_markers():
        g = f22.marker(m.id)
        np.testing.assert_allclose(g.position, m.position + [0.0, -0.00675, 0.0], atol=1e-12)
        np.testing.assert_allclose(g.rotation, m.rotation, atol=1e-12)
        assert g.size == m.size == 0.06


def test_overlay_errors_name_what_is_wrong(tmp_path):
    base = {"name": "x", "base": "rules2026"}
    for extra, msg in [({"marker_overrides": {"99": {"y": 0.1}}}, "overrides marker 99"),
                       ({"marker_overrides": {"50": {"colour": 1}}}, "unknown keys"),
                       ({"box_overrides": {"no_such_wall": {"size": [1, 1, 1]}}}, "overrides box 'no_such_wall'"),
                       ({"box_overrides": {"machine_A_rib0": {"height": 1}}}, "unknown keys")]:
        p = tmp_path / "f.json"
        p.write_text(json.dumps({**base, **extra}))
        with pytest.raises(FieldError, match=msg):
            load_field(str(p))


@pytest.mark.render
def test_stand_in_builds_simtwo2022_and_its_camera_sees_the_shifted_markers(robot):
    """raf --field simtwo2022: the stand-in's scene has SimTwo's ribs and walls, and a floor marker seen by
    the robot camera lies where the simtwo2022 map says (within 1 px), 6.75 mm off the rules' position."""
    import cv2

    from robotatfactory.sim import SimConfig, Simulator

    f22, rules = load_field("simtwo2022"), load_field("rules2026")
    s = Simulator(f22, robot, SimConfig(competition=False, lidar=False))
    try:
        m = s.model
        assert m.geom("machine_A_rib0").size == pytest.approx([0.09, 0.01, 0.0325])
        assert m.geom("incoming_wh_back_wall").pos[1] == pytest.approx(0.58)
        pose = (-0.60, -0.20, 0.3)
        s.set_pose(*pose)
        img = s.render_camera()
        T = np.linalg.inv(s.camera_pose())
    finally:
        s.close()
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_100),
                                  cv2.aruco.DetectorParameters())
    corners, ids, _ = det.detectMarkers(img)
    found = {int(i): c.reshape(4, 2) for c, i in zip(corners, ids.ravel())}
    rvec, _ = cv2.Rodrigues(T[:3, :3])
    assert 18 in found

    def err(fld):
        uv, _ = cv2.projectPoints(fld.marker(18).corners, rvec, T[:3, 3], robot.camera.K, np.zeros(5))
        return np.abs(uv.reshape(4, 2) - found[18]).max()

    assert err(f22) < 1.0 < err(rules)


def test_bad_field_files_raise_field_error(tmp_path):
    with pytest.raises(FieldError, match="unknown field"):
        load_field("nonexistent")
    raw = json.loads((Path(__file__).parents[1] / "src/robotatfactory/data/field_rules2026.json").read_text())
    raw["markers"].append(dict(raw["markers"][0]))
    p = tmp_path / "dup.json"
    p.write_text(json.dumps(raw))
    with pytest.raises(FieldError, match=r"duplicate marker ids \[0\]"):
        load_field(str(p))
    p.write_text("{ not json")
    with pytest.raises(FieldError, match="invalid JSON"):
        load_field(str(p))
    raw["markers"].pop()
    del raw["slots"]
    p.write_text(json.dumps(raw))
    with pytest.raises(FieldError, match="malformed"):
        load_field(str(p))
