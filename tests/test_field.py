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
        np.testing.assert_allclose(f22.marker(a).position, field.marker(b).position)
        np.testing.assert_allclose(f22.marker(b).normal, field.marker(a).normal)
    for a, b in zip([62, 63, 64, 65], [65, 64, 63, 62]):
        np.testing.assert_allclose(f22.marker(a).position, field.marker(b).position)
    for i in range(0, 27):
        np.testing.assert_allclose(f22.marker(i).pose, field.marker(i).pose)


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
