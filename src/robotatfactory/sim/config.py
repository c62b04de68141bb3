"""Settings of the stand-in simulator that affect physics, sensors and the competition (no I/O here)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..errors import ConfigError
from ..settings import section, setting
from .perturb import Perturb


@dataclass(frozen=True)
class PartPlacement:
    """A free part put on the field by hand (tests, experiments): type letter R/G/B, pose in metres/rad.

    ``facing`` is the world heading of the part's ferromagnetic plate, as :class:`field.Slot.facing`.
    """

    letter: str
    x: float
    y: float
    facing: float = 0.0

    def __post_init__(self):
        if self.letter not in ("R", "G", "B"):
            raise ConfigError(f"part type {self.letter!r}: expected R, G or B")


LIDAR_UPDATES = ("sweep", "per_ray")
CAMERA_TIMINGS = ("simtwo", "grid")
SPEED_CONTROLS = ("simtwo", "simtwo_per_cycle", "ideal_pi")
PID_TIMINGS = ("script_enabled", "scene_enabled", "script_holds_voltage")
MAGNETS = ("force", "weld")
REPLY_TIMINGS = ("simtwo", "every_cycle")
MAX_ROBOTS = 4  # robots in one scene (raf sim --robots)


@dataclass(frozen=True)
class SimConfig:
    """Everything that changes what :class:`~robotatfactory.sim.Simulator` computes.

    Same config (seed included) and same commands: same sensor frames and camera images, bit for bit.

    * ``start_pose``: (x, y, theta) in the field frame (m, rad); None = the field's start pose.
    * ``robots``: how many robots share the scene (1..4, ``MAX_ROBOTS``); ``start_poses``: one (x, y, theta)
      per robot (None: robot 1 at ``start_pose`` when N = 1, else the start area's cells, see
      :func:`robotatfactory.sim.scene.start_poses`). N = 1 builds and runs exactly the one-robot scene.
    * ``camera``: render the robot camera during :meth:`Simulator.step_cycle`, collected with
      ``take_frames()``; ``camera_timing`` says when: ``"simtwo"`` (default) as SimTwo's GUI loop does,
      ``"grid"`` on SimTwo's nominal 60 FPS clock decimated by 4 (k/15 s of simulation time).
    * ``lidar`` / ``lidar_noise``: cast the 2D LIDAR; add SimTwo's range noise a*exp(b*d) (seeded).
    * ``competition``: place the round's parts and run the machines and the referee
      (:mod:`robotatfactory.competition`); ``round_no``, ``parts`` (e.g. "RGBX"), ``processing_delay``
      (s), ``start_after`` (s of simulation time before the run may start; the factory server says STOP
      until then) and ``round_duration`` (s) configure it.
    * ``extra_parts``: more parts placed by hand (they take part in physics, LIDAR, camera and magnet).
    * ``perturb``: a world that is not the map (:mod:`robotatfactory.sim.perturb`): the field's fixtures and
      floor sheets displaced (``field_mm``), the parts put into their slots with an error (``parts_mm``,
      ``parts_deg``), the robot started off its nominal pose (``start_cm``, ``start_deg``), the rendering
      camera's intrinsics and mount off the robot file's (``camera_pct``, ``camera_px``, ``camera_deg``);
      seeded by round and seed; all 0 (off) by default. Only the simulated world changes: whatever reads the
      map or the robot file (agent, localization, bridge) keeps the nominal ones.

    SimTwo's behaviours are the defaults; the idealisations are named options (docs/simulator.md):

    * ``lidar_update``: ``"sweep"`` (SimTwo: rays measured in turn over the period, the values the script
      reads replaced all at once once per period, 0 before the first sweep) or ``"per_ray"`` (idealised:
      each ray's value is replaced as soon as it is measured, -1 before).
    * ``lidar_self_hits``: rays hit the robot's own wheels as SimTwo's ODE rays do (False: they pass
      through, an idealisation).
    * ``speed_control``: ``"simtwo"`` (SimTwo's CalcPID with the robot's ``simtwo_pid`` gains, enabled and
      set once at the start, as control.pas does), ``"simtwo_per_cycle"`` (the same, but the script calls
      SetMotorControllerState every control cycle, which resets the integral) or ``"ideal_pi"`` (the
      stand-in's own PI with feed-forward and a reference ramp, every 1 ms, ``speed_controller`` gains).
    * ``simtwo_pid_timing``: SimTwo zeroes every motor voltage before each script call and its controller
      runs on its own 10 ms clock, which counts only while the controller is on: ``"script_enabled"``
      (the script switched it on: it runs 9 ms after each script call and the motors get 0 V in between),
      ``"scene_enabled"`` (``active='1'`` in the scene XML: it runs in the script's own physics step, no
      gap) or ``"script_holds_voltage"`` (switched on by the script, which also re-applies the
      controller's last output each call, ``SetAxisVoltageRef(GetAxisU)``: no gap).
    * ``magnet``: ``"force"`` (SimTwo: a finite pull of 0.5*Vin*fmax/(1 + k2*d)^2 = 5 N along the magnet's
      single ray, at the part's centre of mass, recomputed every physics step, only while the ray's nearest
      hit is a part's plate: a part can hang askew, be pulled in from a small gap, slip or be lost; see
      :mod:`robotatfactory.sim.magnet`) or ``"weld"`` (idealised: a plate facing the magnet within 45 deg
      and within the beam is welded, centred and flat, and can never be lost).
    """

    seed: int = setting(0, "seed of the round draw and the sensor noise", lo=0)
    start_pose: tuple[float, float, float] | None = setting(None, "robot start pose x, y, theta (m, m, rad); "
                                                                  "unset: the field's start pose", kind=tuple)
    robots: int = setting(1, "robots in the scene", lo=1, hi=MAX_ROBOTS)
    start_poses: tuple[tuple[float, float, float], ...] | None = setting(
        None, "one start pose per robot; unset: the start area's cells", kind=tuple)
    beacons: bool = setting(False, "LIDAR beacons in the team areas")
    camera: bool = setting(True, "render the robot's camera")
    lidar: bool = setting(True, "cast the 2D LIDAR")
    lidar_noise: bool = setting(True, "SimTwo's range noise a exp(b d), seeded")
    competition: bool = setting(True, "the round's parts, machines and referee")
    round_no: int = setting(1, "the competition round", choices=(1, 2, 3))
    parts: str | None = setting(None, "incoming warehouse layout, slot 1 first (R, G, B or X for empty); unset: "
                                      "the round's draw", kind=str)
    processing_delay: float = setting(10.0, "s of simulation time a machine processes a part", lo=0.0)
    start_after: float = setting(0.0, "s of simulation time before the run may start (the server says STOP)",
                                 lo=0.0)
    round_duration: float = setting(600.0, "s of simulation time a round lasts", lo=0.0, lo_open=True)
    extra_parts: tuple[PartPlacement, ...] = field(default_factory=tuple)  # by hand (tests), not a setting
    camera_timing: str = setting("simtwo", "when camera frames are rendered: simtwo (as SimTwo's GUI loop: the "
                                           "ends of 17 ms physics chunks on a seeded wall clock, every 4th "
                                           "render published) or grid (the idealisation k/15 s)",
                                 choices=CAMERA_TIMINGS)
    camera_every: int = setting(1, "publish one of every this many of the camera frames camera_timing gives, "
                                   "the others dropped unrendered (1: all, SimTwo on a PC that keeps up; SimTwo's "
                                   "software camera on this project's 2-core host beside the whole stack varies by "
                                   "session: 12 about its 1.0-1.4 frames a second of stop 46, 6 the 2.1-2.5 fixes "
                                   "a second of stop 47, docs/simtwo.md)", lo=1, hi=10 ** 4)
    reply_timing: str = setting("simtwo", "free-running: simtwo (SimTwo's script reads UDP only when its GUI loop "
                                          "handled messages since its previous call, and of several replies "
                                          "applies the first) or every_cycle (the newest reply before every "
                                          "cycle, the idealisation)", choices=REPLY_TIMINGS)
    report_parts: bool = setting(True, "the SensorFrame's optional Parts labels (the parts' ground truth, as "
                                       "simtwo/control.pas sends them)")
    lidar_update: str = setting("sweep", "sweep (SimTwo: all rays replaced once per period, 0 before the first) "
                                         "or per_ray (each ray as soon as measured, the idealisation)",
                                choices=LIDAR_UPDATES)
    lidar_self_hits: bool = setting(True, "rays hit the robot's own wheels as SimTwo's ODE rays do (false: "
                                          "they pass through, the idealisation)")
    speed_control: str = setting("simtwo", "simtwo (SimTwo's CalcPID set once), simtwo_per_cycle (its integral "
                                           "reset every cycle) or ideal_pi (the stand-in's own 1 ms PI)",
                                 choices=SPEED_CONTROLS)
    simtwo_pid_timing: str = setting("script_enabled", "when SimTwo's PID runs against the script calls: "
                                                       "script_enabled (0 V for 9 ms after each call), "
                                                       "scene_enabled or script_holds_voltage (no gap)",
                                     choices=PID_TIMINGS)
    magnet: str = setting("force", "force (SimTwo's electromagnet: a 5 N pull along one ray; a part can hang "
                                   "askew, slip off or be lost) or weld (the idealisation: never lost)",
                          choices=MAGNETS)
    perturb: Perturb = section(Perturb, "a world that is not the map (issue 20; sim/perturb.py): the field's "
                                        "fixtures, the parts, the start pose and the rendering camera drawn off "
                                        "their nominal values, seeded per round and seed; all 0 (off) by default")

    def __post_init__(self):
        if self.start_pose is not None:
            if len(self.start_pose) != 3 or not all(math.isfinite(float(v)) for v in self.start_pose):
                raise ConfigError(f"start pose {self.start_pose!r}: expected three finite numbers x,y,theta")
        if not isinstance(self.robots, int) or not 1 <= self.robots <= MAX_ROBOTS:
            raise ConfigError(f"--robots {self.robots!r}: must be an integer 1..{MAX_ROBOTS}")
        if self.start_poses is not None:
            if len(self.start_poses) != self.robots:
                raise ConfigError(f"{len(self.start_poses)} start poses for {self.robots} robots: give one per robot")
            for p in self.start_poses:
                if len(p) != 3 or not all(math.isfinite(float(v)) for v in p):
                    raise ConfigError(f"start pose {p!r}: expected three finite numbers x,y,theta")
            if self.start_pose is not None:
                raise ConfigError("give either start_pose or start_poses, not both")
        if self.start_after < 0 or not math.isfinite(self.start_after):
            raise ConfigError(f"--start-after {self.start_after}: must be >= 0 seconds")
        if not isinstance(self.seed, int) or self.seed < 0:
            raise ConfigError(f"seed {self.seed!r}: must be a non-negative integer")
        for name, allowed in (("lidar_update", LIDAR_UPDATES), ("speed_control", SPEED_CONTROLS),
                              ("reply_timing", REPLY_TIMINGS), ("camera_timing", CAMERA_TIMINGS),
                              ("simtwo_pid_timing", PID_TIMINGS), ("magnet", MAGNETS)):
            if getattr(self, name) not in allowed:
                raise ConfigError(f"{name} {getattr(self, name)!r}: expected one of {', '.join(allowed)}")


def parse_pose(text: str) -> tuple[float, float, float]:
    """``"x,y,theta"`` (metres, radians) to a tuple; raises ConfigError with the reason."""
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise ConfigError(f"pose {text!r}: expected x,y,theta as three numbers (m, m, rad)") from None
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise ConfigError(f"pose {text!r}: expected x,y,theta as three finite numbers (m, m, rad)")
    return vals  # type: ignore[return-value]


def sim_config(values: dict | None = None) -> SimConfig:
    """:class:`SimConfig` from a nested mapping (``raf sim --config/--set``, an experiment's ``--sim``): every
    value checked against its setting (kind, range, choices; robotatfactory.settings.build)."""
    from ..settings import build

    return build(SimConfig, values)
