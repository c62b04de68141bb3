"""The stand-in simulator: the RobotAtFactory 4.0 scene in MuJoCo, speaking SimTwo's protocol.

>>> from robotatfactory.field import load_field
>>> from robotatfactory.robot import load_robot
>>> from robotatfactory.sim import SimConfig, Simulator
>>> from robotatfactory.simtwo import Command
>>> sim = Simulator(load_field(), load_robot(), SimConfig(camera=False))
>>> frame = sim.step_cycle(Command(0.2, 0.0, False))   # one 40 ms control cycle
>>> frame.seq, frame.time_ms
(0, 40)

``Simulator`` is deterministic and does no I/O; ``SimRunner`` adds the UDP endpoints, the camera's ZMQ
publisher, the factory-state server and pacing (``raf sim``). See docs/simulator.md.
"""
import os

os.environ.setdefault("MUJOCO_GL", "egl")

from .config import PartPlacement, SimConfig, parse_pose  # noqa: E402
from .motor import DCMotor, MotorParams, SpeedControllerParams, SpeedPI  # noqa: E402


def __getattr__(name):  # heavy imports (MuJoCo, OpenGL) only when used
    if name == "Simulator":
        from .simulator import Simulator

        return Simulator
    if name in ("SimRunner", "RunnerConfig"):
        from . import runner

        return getattr(runner, name)
    if name == "CameraFrame":
        from .camera import CameraFrame

        return CameraFrame
    raise AttributeError(name)


__all__ = ["SimConfig", "PartPlacement", "parse_pose", "Simulator", "SimRunner", "RunnerConfig", "CameraFrame",
           "DCMotor", "MotorParams", "SpeedControllerParams", "SpeedPI"]
