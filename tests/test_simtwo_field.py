"""The simtwo2022 field model against what SimTwo builds, read back from SimTwo (simtwo/linux/field_dump.pas,
robotatfactory.simtwo_linux.fielddump): walls, ribs, markers, slots, the start pose.

The real-SimTwo test runs the dump once (one SimTwo start, ~25 s). The others compare a recorded dump
(tests/data/simtwo_field_dump.txt: the FIELD lines of such a run, without its camera frames) and check that
the comparison sees a difference of the size that matters (a rib 2 mm off, a marker turned 90 degrees)."""
from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest

from robotatfactory.field import load_field
from robotatfactory.simtwo_linux import build, fielddump

DATA = Path(__file__).resolve().parent / "data" / "simtwo_field_dump.txt"


@pytest.fixture(scope="module")
def recorded():
    return fielddump.parse(DATA.read_text().splitlines())


@pytest.fixture(scope="module")
def scene_dir():
    return fielddump.scene_dir()


def test_expressions_as_simtwo_reads_them():
    c = {"cell_x": 0.15, "wall_thickness": 0.02}
    assert fielddump.evaluate("4 * cell_x + wall_thickness", c) == pytest.approx(0.62)
    assert fielddump.evaluate("-2 * cell_x", c) == pytest.approx(-0.3)
    assert fielddump.evaluate("0.695/2", c) == pytest.approx(0.3475)
    with pytest.raises(ValueError):
        fielddump.evaluate("__import__('os')", c)


def test_the_probe_block_is_written_from_the_model():
    f = load_field("simtwo2022")
    text = fielddump.script_text(f)
    n = len(fielddump.probes(f))
    assert f"result := {n};" in text and "PName := 'machine_B_4';" in text
    assert n == len(f.slots) + 12  # every slot; 8 warehouse fronts, 4 machine faces


def test_recorded_dump_has_every_obstacle_named(recorded, scene_dir):
    scene = fielddump.scene_obstacles(scene_dir)
    assert recorded.done and recorded.count == len(recorded.obstacles) == len(scene) == 41
    assert {o.id for o in recorded.obstacles} == {s.id for s in scene}
    assert {s.marker_id for s in scene if s.marker_id is not None} == set(range(50, 66))


def test_model_matches_the_recorded_dump(recorded, scene_dir):
    rep = fielddump.compare(recorded, load_field("simtwo2022"), scene_dir, camera=False)
    assert not rep.differences, fielddump.format_report(rep)
    assert rep.checked["wall"] == 20 and rep.checked["marker"] == 12 and rep.checked["mirrored marker"] == 4
    assert rep.checked["slot"] == 16 and rep.checked["lidar"] == 12 and rep.checked["start"] == 1


def test_a_rib_two_mm_off_is_a_difference(recorded, scene_dir):
    d = copy.deepcopy(recorded)
    d.obstacle("output_whareouse_left_wall").pos[1] += 0.002  # outgoing rib at x 0.17, 2 mm towards the field
    rep = fielddump.compare(d, load_field("simtwo2022"), scene_dir, camera=False)
    got = {(x.name, x.quantity): x.size for x in rep.differences if x.what == "wall"}
    assert got == {("outgoing_wh_rib0", "ymin"): pytest.approx(0.002),
                   ("outgoing_wh_rib0", "ymax"): pytest.approx(0.002)}


def test_the_rules_marker_turns_are_differences(recorded, scene_dir, tmp_path):
    """The model before it followed SimTwo: the rules' in-plane turns and 62-65 facing the field."""
    import json

    raw = json.loads((Path(fielddump.__file__).parents[1] / "data" / "field_simtwo2022.json").read_text())
    for k in ("50", "56", "58"):
        for a in ("rx", "ry", "rz"):
            raw["marker_overrides"][k].pop(a)
    raw["remove_ids"] = [63, 64, 65]
    p = tmp_path / "old.json"
    p.write_text(json.dumps(raw))
    rep = fielddump.compare(recorded, load_field(str(p)), scene_dir, camera=False)
    got = {(x.name, x.quantity): x.size for x in rep.differences if x.what == "marker"}
    assert got == {("50", "in-plane"): pytest.approx(90), ("56", "in-plane"): pytest.approx(-90),
                   ("58", "in-plane"): pytest.approx(-90), ("62", "readable"): -1}


def test_slot_and_start_differences(recorded, scene_dir):
    d = copy.deepcopy(recorded)
    d.slots["outgoing_1"].y = -0.492                     # the part stopped short, as once seen with a robot
    d.robots0["AGV"].x += 0.002                          # SimTwo's is 0.65 mm off the model's -0.725 (its CoM)
    rep = fielddump.compare(d, load_field("simtwo2022"), scene_dir, camera=False)
    got = {(x.what, x.name, x.quantity): x.size for x in rep.differences}
    assert got == {("slot", "outgoing_1", "part y"): pytest.approx(0.043),
                   ("start", "AGV", "x"): pytest.approx(0.002 - 0.000651, abs=1e-6)}


@pytest.mark.simtwo
def test_simtwo_builds_the_simtwo2022_field():
    """One SimTwo start: every obstacle, marker, slot (a part set down there stays), LIDAR sweep and camera frame
    agrees with simtwo2022 within 1 mm / 1 degree (fielddump's TOL_* say why)."""
    fld = load_field("simtwo2022")
    b = build.require()
    dump = fielddump.run_dump(fld, b)
    rep = fielddump.compare(dump, fld, fielddump.scene_dir(b))
    print(fielddump.format_report(rep))
    assert not rep.differences, fielddump.format_report(rep)
    assert rep.checked.get("camera marker", 0) >= 8  # the incoming markers and floor markers seen as the model
    for name, p in dump.slots.items():  # a part set down at each slot stays there (a wall would push it away)
        zone, number = name.rsplit("_", 1)
        s = fld.slot(zone, int(number))
        assert math.hypot(p.x - s.xy[0], p.y - s.xy[1]) < fielddump.SLOT_MOVE_M, name
    assert np.isfinite([r.x for r in dump.robots0.values()]).all()
