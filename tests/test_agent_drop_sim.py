"""A part knocked off the magnet on the bare stand-in is found with the LIDAR, picked up from the floor and
scored (issue 20 item 5): the competition experiment's bare loop (play_round: the MuJoCo stand-in with its
SimTwo-like defaults, SimTwo's force magnet, the real FactoryServer and referee) with the LIDAR on, the agent
fed its sweeps as the bridge stamps them; the simulator's ground-truth pose stands in for the EKF."""
import math

from robotatfactory.bench.drops import KnockOff
from robotatfactory.experiments.competition import play_round


def test_a_part_knocked_off_the_magnet_is_found_picked_up_and_scored(field, robot):
    """Round 1, seed 0: a second after the first pick the carried part is knocked off: it comes to rest 14 cm to
    the robot's right, turned by 0.5 rad (the simulator's place_part: off the magnet, at rest on the floor). The
    agent notices (contact switch), stops, finds it with the LIDAR, picks it up and the round still ends at the
    maximum score."""
    knock = KnockOff(field, robot, after=1.0, side=-1, lateral=0.14, turn=0.5, fallback=False)
    r = play_round(1, 0, record_path=True, lidar=True, on_cycle=knock)
    assert knock.refused is None, "the spot it falls on is free floor"
    assert knock.t is not None, "the part was knocked off"
    ev = [(t, text) for t, text, *_ in r["events"]]
    after = [text for t, text in ev if t >= knock.t]
    print(f"\nknocked off at {knock.t:.2f} s; {r['points']}/{r['max_points']} points, last at {r['last_score_s']:.2f} s")
    for t, text in ev:
        if knock.t <= t <= knock.t + 20:
            print(f"  {t:6.2f} {text}")
    # noticed, found with the LIDAR where it lies (within 1 cm of where it came to rest), picked up, placed
    assert (r["parts_lost"], r["parts_refound"], r["floor_picks"], r["floor_pick_failures"], r["parts_left"]) == \
        (1, 1, 1, 0, 0), after
    t_lost = next(t for t, text in ev if text.startswith("lost the blue part"))
    t_found, found = next((t, text) for t, text in ev if text.startswith("LIDAR: found the lost blue part"))
    t_picked = next(t for t, text in ev if text.startswith("picked the lost blue part up from the floor"))
    t_placed = next(t for t, text in ev if t > t_picked and text.startswith("placed the blue part"))
    assert knock.t < t_lost < t_found < t_picked < t_placed
    assert t_lost - knock.t < 0.5  # the contact switch's 5 cycles and the loop
    assert t_picked - t_lost < 15.0, f"{t_picked - t_lost:.1f} s from the loss to the pick"
    xy = found.split(" at (")[1].split(")")[0]
    fx, fy = (float(v) for v in xy.split(", "))
    assert math.hypot(fx - knock.at[0], fy - knock.at[1]) < 0.01
    # the round: every part scored, nothing hit, nothing knocked out of a slot
    assert r["points"] == r["max_points"] == 4 and r["agent_done"] and not r["notes"]
    assert r["collision_checks_hit"] == 0 and r["parts_knocked_out"] == 0
