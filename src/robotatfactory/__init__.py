"""robotatfactory: a ROS 1 framework for the RobotAtFactory 4.0 competition on SimTwo.

Core packages have no ROS import: :mod:`robotatfactory.field` (the competition map),
:mod:`robotatfactory.simtwo` (SimTwo's wire formats), :mod:`robotatfactory.sim` (the MuJoCo
stand-in simulator), :mod:`robotatfactory.localization` and :mod:`robotatfactory.competition`.
:mod:`robotatfactory.ros` holds the thin rospy adapters.
"""

__version__ = "0.1.0"
