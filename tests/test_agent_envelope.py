"""The carry envelope the agent drives in (``raf experiment envelope``): under the stand-in's default magnet
(SimTwo's force, SimTwo's part feet) a part on the magnet survives the agent's carrying limits, and slides
sideways on the magnet's face the more the faster the robot turns."""
import math

from robotatfactory.agent.settings import Carrying
from robotatfactory.experiments.envelope import Trial, run_trial


def test_the_agents_carrying_turn_on_the_spot_keeps_the_part(field, robot):
    held, slide = run_trial(field, robot, Trial("spin", 0.0, Carrying.w_max, 0.8, Carrying.alpha_max,
                                          turn=math.pi))
    assert held and slide < 0.015  # measured 9 mm


def test_a_faster_turn_slides_the_part_farther(field, robot):
    slow = run_trial(field, robot, Trial("spin", 0.0, 0.5, 0.8, 6.0, turn=math.pi))
    fast = run_trial(field, robot, Trial("spin", 0.0, 3.0, 0.8, 11.85, turn=math.pi))
    assert slow[0] and slow[1] < 0.002  # measured 0.8 mm
    assert fast[1] > 0.01 and fast[1] > 5 * slow[1]  # measured 30 mm (held in this trial, lost on the agent's legs)


def test_straight_carrying_and_backing_out_keep_the_part_centred(field, robot):
    for v, a in ((Carrying.v_max, 0.8), (-Carrying.back_speed, max(0.8, Carrying.back_accel))):
        held, slide = run_trial(field, robot, Trial("straight", v, 0.0, a, 11.85, hold=10))
        assert held and slide < 0.001, v
