"""The agent's settings: one typed object (:class:`AgentSettings`) for the round agent and its node.

Every setting has its default, meaning and allowed values here and nowhere else. ``raf agent`` fills it from
``--config FILE`` (the shape of ``config/agent.yaml``) and ``--set dock.approach_speed=0.16``, the node from
its ROS parameters (``~dock/approach_speed`` on ROS 1, ``dock.approach_speed`` on ROS 2), the competition
experiment from ``--agent dock.approach_speed=0.16``: all through :func:`robotatfactory.settings.build`.
:class:`~.behaviour.RoundAgent` takes the object whole. Plain Python, no ROS.

The figures quoted are measurements on the stand-in (docs/agent.md has the runs).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..field import DEFAULT_FIELD
from ..pace import PaceSettings
from ..settings import build, section, setting
from ..simtwo.ports import LOCALHOST, SERVER_UDP_PORT


@dataclass(frozen=True)
class Docking:
    """The final approach to a slot (``dock.*``)."""

    approach_speed: float = setting(0.1, "m/s, the pick approach (the contact switch stops it; braking from "
                                         "there takes ~6 mm)", lo=0.0, hi=0.5, lo_open=True)
    place_speed: float = setting(0.16, "m/s, the place approach (the part enters between ribs): 0.16 was 1-2 s "
                                       "a round faster than 0.12, 0.2 no faster", lo=0.0, hi=0.5, lo_open=True)
    timeout: float = setting(20.0, "s for one docking manoeuvre before it backs out", lo=0.0, hi=600.0,
                             lo_open=True)
    retries: int = setting(2, "docking attempts per pick before the task is decided again", lo=0, hi=20)
    magnet_early: bool = setting(False, "the magnet on from the start of the pick approach (false: at the grip, "
                                        "after the press)")
    press_time: float = setting(0.4, "s: picking, after the contact the robot drives on to the dock pose for at "
                                     "most this long, squaring a part that stands out of its slot against the "
                                     "slot's back wall (0: it stops at the contact)", lo=0.0, hi=2.0)
    place_gate: float = setting(0.015, "m: a place whose carried part is more than this to the side of the slot's "
                                       "centre line (the pose estimate) before it reaches the slot is not "
                                       "entered: the robot backs out along the normal and plans the place again "
                                       "(on SimTwo a part 27 mm off met a rib and fell beside the slot; 0: off)",
                                 lo=0.0, hi=0.1)
    place_gate_tries: int = setting(3, "places of one carried part the place gate may stop in a row; the next is "
                                       "entered ungated (a place that may graze a rib beats one never made: a part "
                                       "that falls is looked for and picked up again; 0: no bound)", lo=0, hi=100)
    pick_gate: float = setting(0.015, "m: a pick approach that has not met its part 6 mm before the dock pose, "
                                      "base_link more than this to the side of the slot's centre line (the pose "
                                      "estimate), is not driven on: past the dock pose the contact switch's bumper "
                                      "goes in between the ribs (12 mm clearance either side); it backs out and "
                                      "tries again from a fresh approach (stand-in, round 3: 19 mm off, it touched "
                                      "machine A's rib; 12 mm also stopped picks 7 mm off by the truth, the "
                                      "estimate 13-14 mm; 0: off)", lo=0.0, hi=0.1)


@dataclass(frozen=True)
class Legs:
    """How a leg to a slot is planned (``legs.*``). The last leg before docking runs at least ``*_straight`` m
    along the slot's normal after an arc no tighter than ``*_min_radius`` m (else a stop and a turn in place)."""

    smooth: bool = setting(True, "paths with arcs, the last leg along the slot's normal (false: stop and turn at "
                                 "every corner, the earlier behaviour)")
    min_radius: float = setting(0.045, "m, the tightest arc of any leg", lo=0.0, hi=1.0)
    pick_straight: float = setting(0.015, "m of straight line along the slot's normal before a pick", lo=0.0,
                                   hi=0.5)
    pick_min_radius: float = setting(0.045, "m, the tightest arc right before a pick", lo=0.0, hi=1.0)
    place_straight: float = setting(0.03, "m of straight line along the slot's normal before a place", lo=0.0,
                                    hi=0.5)
    place_min_radius: float = setting(0.08, "m, the tightest arc right before a place (0.035 let the carried "
                                            "part graze ribs)", lo=0.0, hi=1.0)
    place_standoff: float = setting(0.05, "m: a place's leg ends this much farther out (the docker settles on "
                                          "the normal)", lo=0.0, hi=0.3)
    join_inflate: float = setting(0.03, "m, carrying: the straight line onto the slot's normal may pass where "
                                        "the exact outline grown by this is clear (0: the turning circle "
                                        "everywhere; 0.015 let a carried part catch machine A's rib end)",
                                  lo=0.0, hi=0.2)
    arc_join: float = setting(0.012, "m, carrying, where no point on the slot's normal far enough out for an arc "
                                     "has a clear turning circle (under a machine): the leg may join the normal on "
                                     "an arc along which the exact outline grown by this is clear, instead of a "
                                     "turn on the spot with the part (0: off; its measured effect: docs/benchmarks.md)",
                              lo=0.0, hi=0.2)
    via_grid: float = setting(0.05, "m: a leg may instead run straight to one point of a grid this fine and on "
                                    "to the slot's normal, where the follower's kinematic run finds that faster "
                                    "(a carrying turn is slow: over a machine, not in an S between them; 0: off, "
                                    "the default until stop 46: docs/agent.md)", lo=0.0, hi=0.5)


@dataclass(frozen=True)
class Carrying:
    """Driving with a part on SimTwo's force magnet (``carry.*``): the part slides sideways on the magnet's
    face the more the faster the robot turns (docs/agent.md, "The carry envelope")."""

    arcs: bool = setting(False, "forward arcs of at least carry.radius and straight reversing only, never a turn "
                                "on the spot")
    radius: float = setting(0.3, "m, the tightest arc with carry.arcs", lo=0.05, hi=2.0)
    a_lat: float = setting(0.2, "m/s^2 lateral acceleration on those arcs", lo=0.0, hi=5.0, lo_open=True)
    w_max: float = setting(1.5, "rad/s while a part is on the magnet (0: the normal limit; 1.75-3 lost parts)",
                           lo=0.0, hi=10.0)
    alpha_max: float = setting(6.0, "rad/s^2 while a part is on the magnet (0: the normal limit; 11.85 lost one "
                                    "part in 12 runs)", lo=0.0, hi=50.0)
    v_max: float = setting(0.4, "m/s while a part is on the magnet (0: the normal limit)", lo=0.0, hi=2.0)
    back_speed: float = setting(0.25, "m/s backing out of a slot with the part (0: the docker's own)", lo=0.0,
                                hi=1.0)
    back_accel: float = setting(0.8, "m/s^2: backing out with the part, the speed ramps up and down at most at this "
                                     "rate (and at most drive.a_max): SimTwo's magnet let the part go setting off "
                                     "at 2; 0.8 was 1-3 s a round faster than 0.4 (stop 49, docs/agent.md)", lo=0.0,
                                hi=5.0, lo_open=True)
    long_spin: float = setting(2.4, "rad: a turn on the spot with a part longer than this runs at "
                                    "carry.w_long_spin (0: off)", lo=0.0, hi=2 * math.pi)
    w_long_spin: float = setting(1.1, "rad/s of those long turns", lo=0.0, hi=10.0)
    spin_settle: float = setting(0.03, "rad: a turn on the spot with a part ends standing within this of the "
                                       "heading before the robot drives off (0: it drives off still turning)",
                                 lo=0.0, hi=0.5)
    spin_settle_within: float = setting(0.3, "m: carry.spin_settle only for a turn with at most this much path "
                                              "left after it (0: every turn)", lo=0.0, hi=5.0)
    margin: float = setting(0.01, "m kept clear around the carrying turning circle (0.02: outgoing 4 has no "
                                  "approach pose)", lo=0.0, hi=0.2)
    inflate: float = setting(0.015, "m around the loaded outline (the part swings on the face)", lo=0.0, hi=0.2)


@dataclass(frozen=True)
class Tasks:
    """Choosing the next task (``tasks.*``)."""

    state_period: float = setting(0.5, "s between factory-state server polls (5 requests each)", lo=0.0,
                                  hi=60.0, lo_open=True)
    give_up_after: int = setting(3, "failures at one slot before its part is left alone", lo=1, hi=100)
    choose_by_time: bool = setting(True, "a carried part goes to the free destination (of the best rank) the leg "
                                         "reaches soonest (false: the nearest to the part's source)")
    choose_ahead: bool = setting(True, "with choose_by_time, a picked part's destination is chosen on a thread "
                                       "while the robot grips and backs out, from where the back-out ends (false: "
                                       "after the back-out, standing still: 0.85 s in round 1's longest cycle)")
    pick_by_time: bool = setting(False, "of the parts of the best rank the next is the one whose pick leg and "
                                        "carrying leg take the least time (false: the nearest to the robot; on, "
                                        "round 1 was 1.2 s slower: docs/agent.md); only with tasks.plan_order "
                                        "off")
    plan_order: bool = setting(True, "the moves left are ordered by a search over every order (agent/order.py: the "
                                     "last place soonest, on a table of leg times measured once per map, robot and "
                                     "settings); the rules' next part is kept unless that order ends "
                                     "tasks.plan_margin s sooner, and each part goes to the slot the order chose "
                                     "(false: the rules alone)")
    plan_margin: float = setting(1.0, "s: the order starting with another part than the rules' is taken only when it "
                                      "ends at least this much sooner than the best order starting with the rules' "
                                      "(the table's legs are a second either way: 0 was slower in round 3)", lo=0.0,
                                 hi=60.0)
    reserve_outgoing: bool = setting(True, "a blue part from elsewhere than a machine output leaves the outgoing "
                                           "slots nearest machine B's outputs to the parts still to come from there")


#: m: the last stretch of a leg to a place on which a pose less sure than recovery.place_uncertainty_limit stops
#: the robot to look at markers (the last straight and room to brake before the part reaches the slot)
PLACE_LOOK = 0.15


@dataclass(frozen=True)
class Recovery:
    """Getting out of trouble (``recovery.*``)."""

    escape_tries: int = setting(3, "drives to the nearest clear point before a target without a path counts as "
                                   "failed", lo=0, hi=20)
    escape_time: float = setting(4.0, "s an escape drive may take", lo=0.0, hi=60.0, lo_open=True)
    uncertainty_limit: float = setting(0.03, "m (position std) above which the robot stops to re-localize (with "
                                             "a pose that has a covariance)", lo=0.0, hi=10.0, lo_open=True)
    heading_uncertainty_limit: float = setting(0.1, "rad (heading std), likewise", lo=0.0, hi=math.pi,
                                               lo_open=True)
    place_uncertainty_limit: float = setting(0.01, f"m (position std): on the last {PLACE_LOOK * 100:.0f} cm of a "
                                                   "leg to a place, a less sure pose stops the robot to look at "
                                                   "markers until the std is at most 60 % of this (real SimTwo: 2.2 "
                                                   "mm median, 4.3 max in 75 good places, 18.6 before the one that "
                                                   "dropped its part; 0: off)", lo=0.0, hi=0.5)
    relocalize_timeout: float = setting(12.0, "s looking at markers before it goes on regardless", lo=0.0,
                                        hi=600.0)
    look_patience: float = setting(3.0, "s: looking at markers with a part on (it does not turn towards them), it "
                                        "goes on once the position std has not fallen by 5 % for this long: no fix "
                                        "is coming from here (0: it waits for relocalize_timeout)", lo=0.0,
                                   hi=600.0)
    go_on_after_look: bool = setting(True, "after the look at markers before a place, on along the leg's path from "
                                           "where the robot stopped (false: the leg planned again from there, as "
                                           "until stop 58: from a few cm before its end it often began the place "
                                           "off the slot's normal; raf bench looks)")
    replans: int = setting(2, "re-plans of one leg around a blocked spot before the leg counts as failed", lo=0,
                           hi=20)
    block_memory: float = setting(20.0, "s a blocked spot stays an obstacle", lo=0.0, hi=3600.0)
    lost_cycles: int = setting(5, "control cycles without contact while carrying = the part was lost", lo=1,
                               hi=1000)
    refind: bool = setting(True, "a part lost on the way is looked for (LIDAR; else where it fell) and picked up "
                                 "from the floor again (false: forgotten; the server does not list a part on "
                                 "the floor, so it never scores)")
    check_place: bool = setting(True, "the first server state after a place must list the part in its slot; if it "
                                      "does not, the part is looked for near the slot as a lost one (with "
                                      "recovery.refind)")
    refind_tries: int = setting(3, "floor picks of a lost part before it is left where it lies", lo=1, hi=20)
    refind_radius: float = setting(0.35, "m around where the part fell within which a LIDAR return may be it",
                                   lo=0.05, hi=2.0)
    refind_margin: float = setting(0.02, "m: LIDAR returns this near a wall, rib or listed part are the map's",
                                   lo=0.0, hi=0.2)
    refind_scan_wait: float = setting(1.5, "s standing still for a LIDAR sweep taken since (none: the part is "
                                           "looked for where it fell)", lo=0.0, hi=30.0)
    refind_turn: float = setting(0.8, "rad: a part seen farther off the heading than this is looked at again "
                                      "after turning towards it (the robot's own wheels hide the LIDAR's view "
                                      "to the sides)", lo=0.0, hi=math.pi)
    refind_speed: float = setting(0.06, "m/s, the approach to a part on the floor (the contact switch stops it)",
                                  lo=0.0, hi=0.5, lo_open=True)


@dataclass(frozen=True)
class Drive:
    """The base's limits and the path follower's gains (``drive.*``; :class:`~.follower.DriveLimits`). Unset
    (null): from the robot file (``DriveLimits.from_robot``: a share of the wheels' top speed)."""

    v_max: float | None = setting(None, "m/s", lo=0.0, hi=2.0, lo_open=True, kind=float)
    w_max: float | None = setting(None, "rad/s", lo=0.0, hi=20.0, lo_open=True, kind=float)
    a_max: float | None = setting(None, "m/s^2", lo=0.0, hi=20.0, lo_open=True, kind=float)
    alpha_max: float | None = setting(None, "rad/s^2", lo=0.0, hi=100.0, lo_open=True, kind=float)
    v_final: float | None = setting(None, "m/s at the end of a path", lo=0.0, hi=1.0, kind=float)
    v_wheel: float | None = setting(None, "m/s at either wheel's rim", lo=0.0, hi=2.0, lo_open=True, kind=float)
    a_lat: float | None = setting(None, "m/s^2 lateral acceleration on arcs", lo=0.0, hi=20.0, lo_open=True,
                                  kind=float)
    slow_distance: float | None = setting(None, "m before the end where the profile slows down", lo=0.0, hi=2.0,
                                          kind=float)
    lookahead: float | None = setting(None, "m the follower looks ahead on the path", lo=0.0, hi=1.0,
                                      lo_open=True, kind=float)
    heading_tolerance: float | None = setting(None, "rad of heading error above which it turns on the spot first",
                                              lo=0.0, hi=math.pi, kind=float)
    k_heading: float | None = setting(None, "1/s, turning on the spot: w = k_heading x heading error", lo=0.0,
                                      hi=100.0, lo_open=True, kind=float)
    k_drive: float | None = setting(None, "1/s, driving: w = v kappa + k_drive x heading error", lo=0.0,
                                    hi=100.0, kind=float)

    def given(self) -> dict:
        """The limits set here (the rest come from the robot file)."""
        return {k: v for k, v in self.__dict__.items() if v is not None}


@dataclass(frozen=True)
class Server:
    """The factory-state server (``server.*``)."""

    host: str = setting(LOCALHOST, "the factory-state server's host")
    port: int = setting(SERVER_UDP_PORT, "the factory-state server's UDP port", lo=1, hi=65535)


@dataclass(frozen=True)
class AgentSettings:
    """Everything the agent and its node can be told."""

    field: str = setting(DEFAULT_FIELD, "competition map: a shipped field's name or a field .json")
    robot: str = setting("simtwo", "robot file name or path")
    map_frame: str = setting("map", "frame of agent/path and agent/markers")
    max_input_age: float = setting(0.5, "s after which the pose or odometry counts as stale (the robot stops)",
                                   lo=0.0, hi=60.0, lo_open=True)
    command_latency: float = setting(0.08, "s from publishing cmd_vel to the simulator's cycle that runs it: the "
                                           "pose is predicted that far ahead through the commands in flight "
                                           "(SimTwo's and raf sim's two cycles; 0: no prediction beyond now)",
                                     lo=0.0, hi=1.0)
    server: Server = section(Server, "the factory-state server")
    dock: Docking = section(Docking, "the final approach to a slot")
    legs: Legs = section(Legs, "how a leg to a slot is planned")
    carry: Carrying = section(Carrying, "driving with a part on the magnet")
    tasks: Tasks = section(Tasks, "choosing the next task")
    recovery: Recovery = section(Recovery, "getting out of trouble")
    drive: Drive = section(Drive, "the base's limits and the follower's gains (unset: from the robot file)")
    pace: PaceSettings = section(PaceSettings, "pacing by simulation time: one control cycle per paced frame, "
                                               "once the bridge's and the localization's paces are in, the "
                                               "factory-state server asked within the cycle (no timer, no "
                                               "polling thread)")


HEADER = """The agent's settings (raf agent --config FILE; the node's ROS parameters), every one with its default.
GENERATED from src/robotatfactory/agent/settings.py by `raf agent --print-params --defaults > config/agent.yaml`:
edit that file, then regenerate (tests/test_agent_settings.py fails while this one is out of date)."""


def agent_settings(values: dict | None = None) -> AgentSettings:
    """:class:`AgentSettings` from a nested mapping (what it lacks keeps its default), validated."""
    return build(AgentSettings, values)
