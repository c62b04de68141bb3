"""The competition experiment's collision check (experiments/_competition_observe.py): the robot's outline,
and a held part at its real pose once it has left its slot; a part still in its slot (being picked) stands
between ribs and against the slot's back, which is not a collision."""
from robotatfactory.agent.footprint import dock_distance, pose_in_front
from robotatfactory.experiments._competition_observe import RunObserver


def test_a_part_in_its_slot_is_not_a_collision_one_against_a_rib_is(field, robot):
    obs = RunObserver(field, robot)
    slot = field.slot("incoming", 2)
    pose = pose_in_front(slot, dock_distance(robot, field.part))  # docked, the part on the magnet
    part_in_slot = (slot.xy[0], slot.xy[1], slot.facing)
    obs.cycle(0.0, 0, pose, 7, (0, 0), {7: part_in_slot})
    obs.cycle(0.2, 5, pose, 7, (0, 0), {7: part_in_slot})
    assert obs.touched == 0
    # the same part held 4 cm to the side of the slot's centre: its body is in the rib between two slots
    rib = field.slot("incoming", 3)
    half = ((slot.xy[0] + rib.xy[0]) / 2, (slot.xy[1] + rib.xy[1]) / 2, slot.facing)
    obs.cycle(0.4, 10, pose, 7, (0, 0), {7: half})
    assert obs.touched == 1 and "held part" in obs.hits[-1][3]
    # and the robot's own outline in a wall counts whatever it holds
    obs.cycle(0.6, 15, (slot.xy[0], slot.xy[1], slot.facing), None, (0, 0), {7: part_in_slot})
    assert obs.touched == 2 and obs.hits[-1][3] == "wall"


def test_a_part_that_leaves_its_slot_unheld_is_knocked_out_a_machines_move_or_a_pick_is_not(field, robot):
    obs = RunObserver(field, robot)
    a, b = field.slot("machine_A", 1), field.slot("machine_A", 2)
    far = (0.0, -0.3, 0.0)
    obs.cycle(0.0, 0, far, None, (0, 0), {1: (*a.xy, a.facing), 2: (*a.xy, a.facing)})
    obs.cycle(0.2, 5, far, None, (0, 0), {1: (*b.xy, b.facing), 2: (*a.xy, a.facing)})  # processed: input -> output
    assert obs.knocked_out == 0
    obs.cycle(0.4, 10, far, 2, (0, 0), {1: (*b.xy, b.facing), 2: (a.xy[0] + 0.1, a.xy[1], a.facing)})  # picked
    assert obs.knocked_out == 0
    obs.cycle(0.6, 15, far, None, (0, 0), {1: (b.xy[0] + 0.05, b.xy[1] + 0.02, b.facing),
                                           2: (a.xy[0] + 0.1, a.xy[1], a.facing)})  # shoved 5 cm
    assert obs.knocked_out == 1 and obs.knocks[0][1] == 1
    assert obs.figures()["parts_knocked_out"] == 1
