"""The competition core of RobotAtFactory 4.0: part types, round setups, the factory (slots and machines),
the factory-state server (UDP) and the referee. Plain Python: no ROS, no MuJoCo.

>>> from robotatfactory.field import load_field
>>> from robotatfactory.competition import Factory, Referee, RoundSetup
>>> factory = Factory(load_field(), RoundSetup.make(3, seed=0))
>>> factory.start(0.0)
True
>>> teleports = factory.step(0.04, part_xy={1: (-0.695, 0.535)}, robot_xy=(-0.725, -0.4), held=set())

docs/competition.md has the rules as implemented and every decision.
"""
from .factory import (DEFAULT_ROBOT_CLEARANCE, DEFAULT_TOLERANCE, MACHINE_ACCEPTS, ZONES, Factory, FactoryEvent, Job,
                      Lane, PartState, Teleport, machine_lanes, slot_label)
from .kinematic import KinematicWorld
from .parts import EMPTY, PartType, letter_of, letters_of
from .referee import Referee, ScoreEvent, ScoreReport, is_delivery
from .rounds import (DEFAULT_DURATION, DEFAULT_PROCESSING_DELAY, ROUND_RULES, ROUNDS, RoundSetup, draw_parts,
                     parse_parts)
from .server import MAX_REQUEST, REQUESTS, ZONE_OF, FactoryServer, ctl_reply, query

X = EMPTY

__all__ = ["DEFAULT_ROBOT_CLEARANCE", "DEFAULT_TOLERANCE", "MACHINE_ACCEPTS", "ZONES", "Factory", "FactoryEvent",
           "Job", "KinematicWorld", "Lane", "PartState", "Teleport", "machine_lanes", "slot_label", "EMPTY", "X", "PartType",
           "letter_of", "letters_of", "Referee", "ScoreEvent", "ScoreReport", "is_delivery", "DEFAULT_DURATION",
           "DEFAULT_PROCESSING_DELAY", "ROUND_RULES", "ROUNDS", "RoundSetup", "draw_parts", "parse_parts",
           "MAX_REQUEST", "REQUESTS", "ZONE_OF", "FactoryServer", "ctl_reply", "query"]
