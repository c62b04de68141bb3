from ._GetSimulationState import *
from ._PlacePart import *
from ._ResetSimulation import *
from ._SetRobotPose import *
from ._StepSimulation import *
from ._Trigger import *
