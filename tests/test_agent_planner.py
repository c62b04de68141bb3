"""Paths on the field with the robot's footprint, and approach/dock poses for every slot."""
import math

import numpy as np
import pytest

from robotatfactory.agent.footprint import (carrying_footprint, dock_distance, pose_in_front, robot_footprint,
                                            wrap)
from robotatfactory.agent.obstacles import FieldObstacles, PartObstacle, part_polygon, polygons_overlap
from robotatfactory.agent.planner import NoPath, PathPlanner


@pytest.fixture(scope="module")
def geo(field, robot):
    return robot_footprint(robot), carrying_footprint(robot, field.part), dock_distance(robot, field.part)


def samples(path, step=0.01):
    """(x, y, heading) every ``step`` m along each segment, heading along the segment."""
    pts = np.asarray(path.points)
    for a, b in zip(pts[:-1], pts[1:]):
        L = float(np.hypot(*(b - a)))
        th = math.atan2(b[1] - a[1], b[0] - a[0])
        for u in np.linspace(0.0, 1.0, max(2, int(L / step) + 1)):
            yield (*(a + u * (b - a)), th)


def assert_path_clear(ob, path, footprint, start_end_slack=0.0):
    """Driving each segment (heading along it) never touches an obstacle; turning in place at every
    inner waypoint is clear (its turning circle)."""
    for pose in samples(path):
        assert not ob.collides(footprint, pose), f"collision at {pose}"
    for p in path.points[1:-1]:
        assert ob.clearance_at(*p) >= footprint.radius, p


def test_footprint_from_the_robot_file(field, robot, geo):
    fp, fc, d = geo
    assert fp.front == pytest.approx(robot.electromagnet["x"]) and fp.back == pytest.approx(-0.07)
    assert fp.radius == pytest.approx(math.hypot(0.07, 0.0525))  # the base box's corner
    assert fc.front == pytest.approx(0.08 + 0.0005 + 0.002 + 0.06) and fc.radius > 0.14
    assert d == pytest.approx(0.03 + 0.002 + 0.08 + 0.003)


def test_approach_and_dock_poses_of_every_slot(field, robot, geo):
    """Pick: the empty robot from the approach pose straight to 3 mm of the plate, the part in its slot;
    place: the loaded robot straight to the pose that leaves the part on the slot centre. Both face the
    plate, both lines are clear with the exact outline, the approach pose clears the turning circle."""
    fp, fc, d = geo
    for slot in field.slots:
        part_here = PartObstacle(*slot.xy, slot.facing)
        for footprint, parts in ((fp, [part_here]), (fc, [])):
            ob = FieldObstacles(field, parts)
            pl = PathPlanner(ob)
            ax, ay, ath = pl.approach_pose(slot, d, footprint)
            dock = pose_in_front(slot, d)
            assert abs(wrap(ath - slot.facing - math.pi)) < 1e-9 and dock[2] == ath
            # the approach pose is on the plate's normal, behind the dock pose
            u = (math.cos(slot.facing), math.sin(slot.facing))
            along = (ax - slot.xy[0]) * u[0] + (ay - slot.xy[1]) * u[1]
            across = -(ax - slot.xy[0]) * u[1] + (ay - slot.xy[1]) * u[0]
            assert abs(across) < 1e-9 and d <= along <= d + 0.12, (slot.name, along)
            assert ob.clearance_at(ax, ay) >= footprint.radius
            for k in np.linspace(0.0, 1.0, 30):  # straight in, with 5 mm of lateral error either side
                for lat in (-0.005, 0.0, 0.005):
                    pose = (ax + k * (dock[0] - ax) - lat * u[1], ay + k * (dock[1] - ay) + lat * u[0], ath)
                    assert not ob.collides(footprint, pose), (slot.name, footprint is fc, k, lat)
        # the magnet touches the plate at the dock pose minus the 3 mm gap, not before
        ob = FieldObstacles(field, [PartObstacle(*slot.xy, slot.facing)])
        assert ob.collides(fp, pose_in_front(slot, d - 0.004))


def test_paths_from_the_start_and_between_slots_are_clear(field, geo):
    fp, fc, d = geo
    parts = [PartObstacle(*s.xy, s.facing) for s in field.slots_of("incoming")]
    ob = FieldObstacles(field, parts)
    pl = PathPlanner(ob)
    start = (field.start_pose.x, field.start_pose.y)
    for slot in field.slots:
        goal = pl.approach_pose(slot, d, fp)
        path = pl.plan(start, goal[:2], fp)
        assert path.points[0] == start and path.points[-1] == pytest.approx(goal[:2])
        assert path.length < 3.0
        assert_path_clear(ob, path, fp)
    # loaded: from each incoming slot to every place it may go (inside the grid's margin of the start
    # and the goal, the robot moves along the slot's normal, which the dock test covers)
    ob_empty_slots = FieldObstacles(field, [])
    pl = PathPlanner(ob_empty_slots)
    for src in field.slots_of("incoming"):
        a = pl.approach_pose(src, d, fc)
        for dst in field.slots_of("outgoing") + [s for s in field.slots if s.role == "input"]:
            b = pl.approach_pose(dst, d, fc)
            path = pl.plan(a[:2], b[:2], fc)
            assert_path_clear(ob_empty_slots, path, fc)


def test_parts_on_the_floor_are_avoided_and_walls_block(field, geo):
    fp, _, _ = geo
    stray = PartObstacle(0.0, -0.38, 0.3)  # a part knocked into the corridor below machine B
    ob = FieldObstacles(field, [stray])
    pl = PathPlanner(ob)
    path = pl.plan((-0.2, -0.38), (0.2, -0.38), fp)
    assert len(path.points) > 2  # not the straight line through the part
    assert_path_clear(ob, path, fp)
    poly = part_polygon(field.part, stray)
    assert all(not polygons_overlap(p, poly) for pose in samples(path) for p in fp.polygons(*pose))
    # a footprint too large for every corridor has no path
    with pytest.raises(NoPath):
        pl.plan((-0.6, 0.0), (0.6, 0.0), 0.4)


@pytest.mark.parametrize("src,dst,carry", [(("incoming", 1), ("outgoing", 3), True),
                                           (("outgoing", 2), ("incoming", 3), False),
                                           (("machine_A", 2), ("machine_B", 1), True),
                                           (("incoming", 4), ("machine_B", 3), True)])
def test_rounded_paths_keep_the_exact_outline_clear(field, robot, src, dst, carry):
    """Corners rounded into arcs (PathPlanner.smooth): the outline heading along the arc, exactly, touches
    nothing anywhere on the path; the path still ends on the slot's normal (plan_to_pose)."""
    from robotatfactory.agent.footprint import carrying_footprint, dock_distance, robot_footprint, wrap

    fp = carrying_footprint(robot, field.part) if carry else robot_footprint(robot)
    ob = FieldObstacles(field, [])
    pl = PathPlanner(ob)
    d = dock_distance(robot, field.part)
    start = pl.approach_pose(field.slot(*src), d, fp)
    goal = pl.approach_pose(field.slot(*dst), d, fp)
    path, aligned = pl.plan_to_pose(start[:2], goal, fp)
    sp = pl.smooth(path, fp, final_straight=0.03 if aligned else 0.0, final_min_radius=0.08)
    arcs = sum(int(np.any(p.kappa != 0)) for p in sp.pieces)
    assert sp.stops <= max(len(path.points) - 2, 0)
    if src == ("incoming", 1):  # its corners are rounded (measured: two arcs, no stop)
        assert arcs >= 1
    for p in sp.pieces:
        for (x, y), h in zip(p.xy, p.psi):
            if math.hypot(x - start[0], y - start[1]) > 0.02:  # (the start: turning there is checked already)
                assert not ob.collides(fp, (float(x), float(y), float(h))), (x, y, h)
    last = sp.pieces[-1]
    assert np.hypot(*(last.xy[-1] - goal[:2])) < 1e-6 and np.all(last.kappa[-3:] == 0)
    if aligned:  # the last leg along the slot's normal: docking follows on without a turn
        assert abs(wrap(last.psi[-1] - goal[2])) < 1e-6


def test_the_join_onto_a_slots_normal_may_pass_where_only_the_exact_outline_is_clear(field, robot):
    """Carrying from machine B's output 2 to outgoing 3: the slot's normal is too near the machine's rib end for
    the turning circle higher up, so with the circle everywhere the path jogs sideways (two corners, two turns on
    the spot with the part); with ``join_inflate`` the line onto the normal needs only the exact outline (grown
    by that much) clear, and the path has no stop. Driving it, the exact outline touches nothing."""
    fp = carrying_footprint(robot, field.part)
    ob = FieldObstacles(field, [])
    pl = PathPlanner(ob, margin=0.01)
    d = dock_distance(robot, field.part)
    start = pl.approach_pose(field.slot("machine_B", 2), d, fp)
    g = pl.approach_pose(field.slot("outgoing", 3), d, fp)
    goal = (g[0] - 0.05 * math.cos(g[2]), g[1] - 0.05 * math.sin(g[2]), g[2])  # the place's standoff
    jog, aligned = pl.plan_to_pose(start[:2], goal, fp)
    assert aligned and pl.smooth(jog, fp, final_straight=0.03, final_min_radius=0.08).stops >= 1
    path, aligned = pl.plan_to_pose(start[:2], goal, fp, join_inflate=0.015)
    sp = pl.smooth(path, fp, final_straight=0.03, final_min_radius=0.08)
    assert aligned and sp.stops == 0 and sp.length < pl.smooth(jog, fp, final_straight=0.03).length
    for p in path.points[1:-1]:  # it may still turn on the spot at every corner
        assert ob.clearance_at(*p) >= fp.radius, p
    for p in sp.pieces:
        for (x, y), h in zip(p.xy, p.psi):
            if math.hypot(x - start[0], y - start[1]) > 0.02:
                assert not ob.collides(fp, (float(x), float(y), float(h))), (x, y, h)


def _leg_to(field, robot, slot: int, arc_join: float):
    from robotatfactory.agent.behaviour import RoundAgent
    from robotatfactory.agent.settings import agent_settings
    from robotatfactory.agent.state import SlotRef

    legs = RoundAgent(field, robot, agent_settings({"legs": {"arc_join": arc_join, "via_grid": 0.0}})).legs
    ob = FieldObstacles(field, [])
    return legs, ob, legs.plan(ob, (-0.24, 0.33, 0.0), SlotRef("outgoing", slot), True, "place")


def test_a_place_under_a_machine_is_joined_on_an_arc_with_arc_join(field, robot):
    """Carrying from incoming 4 to outgoing 3, below machine B: no point of the slot's normal far enough out for
    an arc has a clear turning circle, so the leg stops and turns on the spot with the part 6 cm out. With
    ``legs.arc_join`` (the default) the normal is joined farther out on an arc along which the exact outline is clear: no stop,
    the robot arrives along the normal, and driving it the exact outline touches nothing."""
    _, _, before = _leg_to(field, robot, 3, 0.0)
    assert before.aligned and before.smooth.stops == 1
    legs, ob, leg = _leg_to(field, robot, 3, 0.012)
    fp = legs.footprint(True)
    assert leg.aligned and leg.smooth.stops == 0
    pre = leg.path.points[-2]
    assert ob.clearance_at(*pre) < fp.radius  # (where it could not turn on the spot)
    last = leg.smooth.pieces[-1]
    assert abs(wrap(last.psi[-1] - leg.goal[2])) < 1e-6
    for p in leg.smooth.pieces:
        for (x, y), h in zip(p.xy, p.psi):
            if math.hypot(x + 0.24, y - 0.33) > 0.02:
                assert not ob.collides(fp, (float(x), float(y), float(h))), (x, y, h)


def test_arc_join_keeps_the_turn_where_no_arc_fits(field, robot, monkeypatch):
    """Outgoing 2, right under machine B: no arc onto its normal is clear either, and the leg is the one planned
    without ``legs.arc_join`` (a turn on the spot where the turning circle is clear), from the same searches
    (not planned a second time: only the arcs tried are added)."""
    searches = []
    plan_to_pose = PathPlanner.plan_to_pose

    def counted(self, *a, **kw):
        searches.append("arc" if "distances" in kw else "leg")
        return plan_to_pose(self, *a, **kw)

    monkeypatch.setattr(PathPlanner, "plan_to_pose", counted)
    _, _, before = _leg_to(field, robot, 2, 0.0)
    plain, searches[:] = list(searches), []
    _, _, leg = _leg_to(field, robot, 2, 0.012)
    assert leg.smooth.stops == before.smooth.stops == 1
    assert leg.path.points == before.path.points and leg.goal == before.goal
    assert searches.count("leg") == plain.count("leg") and "arc" in searches


def test_the_fast_exact_checks_agree_with_the_reference_ones(field, geo):
    """The planner's checks run thousands of times a decision, so they are vectorised: the stacked
    separating-axis test agrees with :func:`polygons_overlap` on random rectangles (touching, crossing,
    apart), a line of poses with the pose-by-pose test, and the clearance of many points with the single one."""
    from robotatfactory.agent.obstacles import _edge_normals, _quads_overlap, _rect_polygon

    rng = np.random.default_rng(7)

    def rect():
        c, (w, h), yaw = rng.uniform(-0.2, 0.2, 2), rng.uniform(0.01, 0.15, 2), rng.uniform(-math.pi, math.pi)
        return _rect_polygon(c[0], c[1], w, h, yaw)

    a, b = np.array([rect() for _ in range(120)]), np.array([rect() for _ in range(80)])
    b[0] = a[0] + (a[0][1] - a[0][0])  # one shifted by its own edge: touching counts as overlap
    fast = _quads_overlap(a, b, _edge_normals(b))
    slow = np.array([[polygons_overlap(p, q) for q in b] for p in a])
    assert (fast == slow).all() and 0 < slow.sum() < slow.size and fast[0, 0]
    empty, carrying, _ = geo
    ob = FieldObstacles(field, [PartObstacle(s.xy[0], s.xy[1], s.facing) for s in field.slots[::3]])
    for fp in (empty, carrying):
        for _ in range(60):
            x0, y0 = rng.uniform(-0.85, 0.85), rng.uniform(-0.6, 0.6)
            h = rng.uniform(-math.pi, math.pi)
            xs, ys = x0 + np.linspace(0, 0.2, 21) * math.cos(h), y0 + np.linspace(0, 0.2, 21) * math.sin(h)
            assert ob.collides_any(fp, xs, ys, h) == any(ob.collides(fp, (x, y, h)) for x, y in zip(xs, ys))
            assert np.allclose(ob.clearance_of(xs, ys), [ob.clearance_at(x, y) for x, y in zip(xs, ys)], atol=1e-12)


def test_a_search_is_remembered_with_its_obstacles(field, geo):
    """A decision plans the same legs several times (timing each destination, then the chosen one): the second
    plan on the same obstacles finds the search remembered and gives the same path; other obstacles search anew;
    a search that found no path says so again."""
    empty, _, _ = geo
    ob = FieldObstacles(field, [])
    start, goal = (-0.6, -0.35), (0.55, 0.3)
    first = PathPlanner(ob).plan(start, goal, empty)
    kept = dict(ob.searches)
    assert len(kept) >= 1
    again = PathPlanner(ob).plan(start, goal, empty)
    assert again.points == first.points and ob.searches.keys() == kept.keys()
    other = FieldObstacles(field, [])
    assert PathPlanner(other).plan(start, goal, empty).points == first.points and len(other.searches) >= 1
    walled = FieldObstacles(field, [], extra=[[(-0.05, -0.7), (0.05, -0.7), (0.05, 0.7), (-0.05, 0.7)]])
    for _ in range(2):
        with pytest.raises(NoPath):
            PathPlanner(walled).plan(start, goal, empty)
    assert any(isinstance(v, NoPath) for v in walled.searches.values())


def test_the_search_memo_is_bounded_for_every_kind_of_entry(field, geo, monkeypatch):
    """Grid searches and string pulls both go through FieldObstacles.remember: past SEARCHES_KEPT entries the
    memo starts again, whichever kind filled it, and the paths stay the same."""
    from robotatfactory.agent import obstacles

    empty, _, _ = geo
    monkeypatch.setattr(obstacles, "SEARCHES_KEPT", 3)
    ob = FieldObstacles(field, [])
    planner = PathPlanner(ob)
    reference = PathPlanner(FieldObstacles(field, [])).plan((-0.6, -0.35), (0.55, 0.3), empty).points
    kinds, remember = set(), ob.remember

    def spy(key, value):
        kinds.add("pull" if key[0] == "shortcut" else "search")
        out = remember(key, value)
        assert len(ob.searches) <= 3
        return out

    monkeypatch.setattr(ob, "remember", spy)
    for gx in (0.55, 0.5, 0.45, 0.4, 0.35):
        planner.plan((-0.6, -0.35), (gx, 0.3), empty)
    assert kinds == {"pull", "search"}
    assert planner.plan((-0.6, -0.35), (0.55, 0.3), empty).points == reference


def test_the_swept_check_of_a_straight_line_is_exact(field, geo):
    """:meth:`PathPlanner.swept_clear` checks the area the outline sweeps along a line at once (the hull of its
    rectangles at both ends): on random lines it says clear only where the outline at every millimetre is clear,
    and where the sampled check finds a touch it finds it too; a hexagon against quadrilaterals agrees with
    :func:`polygons_overlap`; the hull of a rectangle moved along its own side has its four corners."""
    from robotatfactory.agent.obstacles import _edge_normals, _quads_overlap
    from robotatfactory.agent.obstacles import _hull8

    rng = np.random.default_rng(11)
    empty, carrying, _ = geo
    ob = FieldObstacles(field, [PartObstacle(s.xy[0], s.xy[1], s.facing) for s in field.slots[::2]])
    pl = PathPlanner(ob)
    seen = {True: 0, False: 0}
    for fp in (empty, carrying):
        for _ in range(80):
            a = rng.uniform((-0.8, -0.55), (0.8, 0.55))
            b = a + rng.uniform(0.05, 0.5) * np.array([math.cos(h := rng.uniform(-math.pi, math.pi)), math.sin(h)])
            swept = pl.swept_clear(a, b, fp, 0.01)
            fine = not any(ob.collides(fp.inflated(0.01), (*(a + u * (b - a)), h))
                           for u in np.linspace(0, 1, int(np.hypot(*(b - a)) / 0.001) + 2))
            assert not swept or fine, (a, b)
            if not pl.straight_clear(a, b, fp, 0.01):
                assert not swept, (a, b)
            seen[swept] += 1
    assert seen[True] > 10 and seen[False] > 10  # both kinds of line were met
    hexa = np.array([_hull8(np.concatenate([q, q + (0.1, 0.03)])) for q in ob._quads[:6]])
    fast = _quads_overlap(hexa, ob._quads, _edge_normals(ob._quads))
    slow = np.array([[polygons_overlap(p, q) for q in ob._quads] for p in hexa])
    assert (fast == slow).all() and slow.any()
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    assert {tuple(p) for p in _hull8(np.concatenate([sq, sq + (2, 0)]))} == {(0, 0), (3, 0), (3, 1), (0, 1)}


def test_a_carrying_leg_may_go_round_a_machine_through_a_grid_point(field, robot):
    """``legs.via_grid``: carrying from incoming 4 to outgoing 4 the planner's leg runs between the machines, turning
    the part one way and back (an S); through a grid point over machine B it turns one way only and takes
    seconds less by the follower's kinematic run. That leg arrives along the slot's normal without a stop, and
    driving it the exact outline touches nothing. Off (0), the leg is the planner's."""
    from robotatfactory.agent.behaviour import RoundAgent
    from robotatfactory.agent.settings import agent_settings
    from robotatfactory.agent.state import FactoryState, SlotRef

    def leg(grid):
        legs = RoundAgent(field, robot, agent_settings({"legs": {"via_grid": grid}})).legs
        ob = legs.obstacles(FactoryState.from_letters("BBBB"), exclude=SlotRef("incoming", 4))
        pose = pose_in_front(field.slot("incoming", 4), legs.retreat(ob, SlotRef("incoming", 4), True))
        return legs, ob, pose, legs.plan(ob, pose, SlotRef("outgoing", 4), True, "place")

    legs, ob, pose, before = leg(0.0)
    _, _, _, after = leg(0.05)
    t0, t1 = legs.leg_time(before, pose, True), legs.leg_time(after, pose, True)
    assert t1 < t0 - 1.0, (t0, t1)
    assert after.aligned and after.smooth.stops == 0 and after.path.points[1][0] > 0.4  # (east of machine B)
    fp = legs.footprint(True)
    for p in after.smooth.pieces:
        for (x, y), h in zip(p.xy, p.psi):
            if math.hypot(x - pose[0], y - pose[1]) > 0.02:
                assert not ob.collides(fp, (float(x), float(y), float(h))), (x, y, h)
    assert abs(wrap(after.smooth.pieces[-1].psi[-1] - after.goal[2])) < 1e-6


def test_the_least_clearance_of_many_segments_agrees_with_the_single_check(field, geo):
    """``segments_clearance`` (every segment from a point at once, for the legs through grid points) says clear
    exactly where ``segment_clear`` does, for radii around the clearances met."""
    rng = np.random.default_rng(3)
    ob = FieldObstacles(field, [PartObstacle(s.xy[0], s.xy[1], s.facing) for s in field.slots[::2]])
    a = (0.05, 0.31)
    ends = rng.uniform((-0.8, -0.55), (0.8, 0.55), (200, 2))
    least = ob.segments_clearance(a, ends)
    for r in (0.05, 0.1, 0.15):
        assert [bool(v >= r) for v in least] == [ob.segment_clear(a, e, r) for e in ends]
    assert 0 < (least >= 0.1).sum() < len(ends)
