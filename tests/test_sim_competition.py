"""The competition inside the simulator: round setup placing parts, a machine turning a red part green."""
import math

import numpy as np
import pytest

from robotatfactory.sim import SimConfig
from robotatfactory.simtwo import Command


def make(field, robot, **kw):
    from robotatfactory.sim import Simulator

    kw.setdefault("camera", False)
    kw.setdefault("lidar", False)
    return Simulator(field, robot, SimConfig(**kw))


def test_round_setup_places_the_parts_in_the_incoming_warehouse(field, robot):
    sim = make(field, robot, round_no=3, parts="RGXB")
    assert sim.factory.letters("incoming") == "RGXB"
    slots = field.slots_of("incoming")
    for pid, letter, slot in ((1, "R", slots[0]), (2, "G", slots[1]), (4, "B", slots[3])):
        x, y, facing = sim.part_pose(pid)
        assert (x, y) == pytest.approx(slot.xy, abs=0.001)
        assert math.cos(facing - slot.facing) > 0.9999
        assert sim.part_letter(pid) == letter
    assert sorted(sim.parts.ids) == [1, 2, 4]
    sim.close()


def test_machine_a_turns_a_red_part_green_at_its_output(field, robot):
    sim = make(field, robot, round_no=3, parts="RXXX", processing_delay=0.5)
    inp, out = field.slot("machine_A", 1), field.slot("machine_A", 2)
    sim.place_part(1, *inp.xy, inp.facing)
    red = sim.model.geom_rgba[sim.parts.visual_geom[1]].copy()
    for _ in range(3):
        sim.step_cycle(Command(0.0, 0.0, False))
    assert sim.factory.letters("machine_A") == "RXXX"  # taken in, being processed
    assert sim.part_letter(1) == "R"
    for _ in range(15):  # 0.6 s > the 0.5 s processing delay
        sim.step_cycle(Command(0.0, 0.0, False))
    x, y, facing = sim.part_pose(1)
    assert (x, y) == pytest.approx(out.xy, abs=0.003)
    assert math.cos(facing - out.facing) > 0.999
    assert sim.part_letter(1) == "G"
    green = sim.model.geom_rgba[sim.parts.visual_geom[1]]
    assert green[1] > green[0] and not np.allclose(green, red)
    assert sim.factory.letters("machine_A") == "XGXX"
    # the part came back as a physical body at rest on the floor (the simulator moved it, not just the state)
    for _ in range(5):
        sim.step_cycle(Command(0.0, 0.0, False))
    assert sim.part_pose(1)[:2] == pytest.approx(out.xy, abs=0.003)
    assert abs(sim.data.qpos[sim.parts.qadr[1] + 2]) < 0.001
    rep = sim.referee.report(sim.time)
    assert rep.points >= 1  # the red part delivered to machine A scored
    sim.close()


def test_machine_waits_while_the_robot_is_next_to_its_input(field, robot):
    inp = field.slot("machine_A", 1)
    # the robot 12 cm from the input slot, facing away from the machine
    sim = make(field, robot, round_no=3, parts="RXXX", processing_delay=0.2,
               start_pose=(inp.xy[0] - 0.12, inp.xy[1] - 0.1, math.pi))
    sim.place_part(1, *inp.xy, inp.facing)
    for _ in range(15):
        sim.step_cycle(Command(0.0, 0.0, False))
    assert sim.part_letter(1) == "R" and sim.factory.letters("machine_A") == "RXXX"
    for _ in range(15):  # drive away: the machine starts, and finishes 0.2 s later
        sim.step_cycle(Command(0.3, 0.0, False))
    for _ in range(10):
        sim.step_cycle(Command(0.0, 0.0, False))
    assert sim.part_letter(1) == "G" and sim.factory.letters("machine_A") == "XGXX"
    sim.close()


def test_no_run_before_start_after(field, robot):
    sim = make(field, robot, round_no=1, parts="BXXX", start_after=0.2)
    assert not sim.factory.started
    for _ in range(5):
        sim.step_cycle(Command(0.0, 0.0, False))
    assert not sim.factory.started
    sim.step_cycle(Command(0.0, 0.0, False))
    assert sim.factory.started and sim.factory.start_time == pytest.approx(0.2)
    sim.close()
