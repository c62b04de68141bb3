"""The stand-in simulator's core: MuJoCo physics, SimTwo's motor model, sensors and the competition.

Deterministic and free of I/O: :meth:`Simulator.step_cycle` takes the :class:`~robotatfactory.simtwo.Command`
to apply and returns the :class:`~robotatfactory.simtwo.SensorFrame` measured at the end of the control
period (40 ms of 1 ms physics steps). Camera frames due in that period are rendered at the physics step
they fall on and collected with :meth:`take_frames`: by default when SimTwo's GUI loop would render them
(``camera_timing="simtwo"``, :class:`~robotatfactory.sim.camera.RenderCadence`: ends of 17 ms physics
chunks picked by a seeded wall clock, every 4th render), or on the idealised grid k/15 s
(``"grid"``); a caller that publishes them before sending the returned frame honours the frame ordering rule
of ``docs/dev/interfaces.md``.

Units: metres, radians, seconds, volts, amperes, newton-metres. Poses are in the field frame.
"""
from __future__ import annotations

import dataclasses
import logging
import math
import os
import time
from collections import deque

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from ..field import Field  # noqa: E402
from ..robot import RobotSpec  # noqa: E402
from ..simtwo import Command, SensorFrame  # noqa: E402
from ..simtwo.teleport import part_heading, spare_part_xy  # noqa: E402
from . import scene as sc  # noqa: E402
from .camera import CameraFrame, RenderCadence, Renderer, ScheduledFrame, one_in  # noqa: E402
from .config import SimConfig  # noqa: E402
from .motor import DCMotor, MotorParams, SimTwoPID, SimTwoPIDParams, SpeedControllerParams, SpeedPI  # noqa: E402
from .magnet import MagnetForce, MagnetParams  # noqa: E402
from .parts import PartBodies  # noqa: E402
from .sensors import Encoder, Lidar  # noqa: E402

log = logging.getLogger(__name__)

SETTLE_STEPS = 300  # physics steps run before t = 0 so that wheels and parts rest on the floor
MAGNET_CHECK_STEPS = 10  # while on and empty, the magnet looks for a plate every 10 ms
MAGNET_GAP = 0.0005  # m left between the magnet's face and a held plate
UNIT_SEED_STRIDE = 1_000_003  # robot k's LIDAR noise seed: seed + stride * (k - 1) (robot 1: the seed itself)
BEAM_BACKOFF = 0.005  # m: beams start this far behind their origin (a ray starting inside a touching
#                       surface would miss it); hits are measured from the nominal origin


class Simulator:
    """One robot on the RobotAtFactory 4.0 field. See the module docstring.

    Attributes worth reading: ``time`` (s), ``pose`` (x, y, theta), ``seq`` (cycles done), ``held`` (the
    part id on the magnet or None), ``factory`` and ``referee`` (None without the competition),
    ``wheel_speeds`` (rad/s), ``motor_voltages`` (V), ``motor_currents`` (A).
    """

    def __init__(self, field: Field, robot: RobotSpec, config: SimConfig | None = None, *,
                 offscreen: tuple[int, int] | None = None, reference_drive: bool = False):
        self.reference_drive = reference_drive  # True: the plain (slow) motor/controller loop, for tests
        self.config = config = config or SimConfig()
        # the map and the robot file as given; with config.perturb the simulated world departs from them
        # (sim/perturb.py): self.field and self.robot are then the world's (the factory and the referee too)
        self.nominal_field, self.nominal_robot = field, robot
        self.world = None
        scene_config = config
        if config.perturb.any:
            from .perturb import World

            self.world = World.draw(field, robot, config.perturb, config.round_no, config.seed, config.start_pose)
            field, robot = self.world.field, self.world.robot
            if self.world.start is not None and config.robots == 1:
                scene_config = dataclasses.replace(config, start_pose=self.world.start)
        self.field = field
        self.robot = robot
        self.factory = self.referee = self.setup = None
        parts = self._initial_parts()
        cam = robot.camera
        off = offscreen or (cam.width, cam.height)
        off = (max(off[0], cam.width), max(off[1], cam.height))
        spec, self.info = sc.build_spec(field, robot, scene_config, parts, offscreen=off)
        eq_names: list[dict[int, str]] = []  # per robot: part id -> its magnet's weld
        for names in self.info.robots:
            per = {}
            for pid in self.info.parts:
                name = f"{names.prefix}magnet_weld_{pid}"
                eq = spec.add_equality(name=name, type=mujoco.mjtEq.mjEQ_WELD, objtype=mujoco.mjtObj.mjOBJ_BODY,
                                       name1=names.robot_body, name2=self.info.parts[pid], active=False)
                eq.solref = [0.01, 1.0]
                per[pid] = name
            eq_names.append(per)
        self.spec = spec
        self.model = m = spec.compile()
        self.data = d = mujoco.MjData(m)
        self.dt = float(m.opt.timestep)
        self.steps_per_cycle = int(round(robot.control_period / self.dt))
        if abs(self.steps_per_cycle * self.dt - robot.control_period) > 1e-9:
            raise ValueError(f"control period {robot.control_period} s is not a multiple of the physics step {self.dt} s")

        name2id = mujoco.mj_name2id
        self.parts = PartBodies(m, self.info)
        if sc.PART_FOOT_FRICTION[0] < sc.PART_FOOT_FRICTIONLESS_BELOW:  # the feet's friction, per direction
            loss = sc.part_floor_frictionloss(field.part)
            for pid in self.info.parts:
                a = self.parts.vadr[pid]
                m.dof_frictionloss[a:a + 6] = loss
        self._plate_geoms = {name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"part_{pid}_plate"): pid for pid in self.info.parts}
        self._part_geoms = {name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"part_{pid}_body"): pid for pid in self.info.parts}
        for pid, letter, *_ in parts:
            self.parts.set_letter(pid, letter)

        # actuation: shared parameters
        mp = MotorParams.from_spec(robot.motor)
        self.motor_params = mp
        cp = SpeedControllerParams.from_spec(robot.speed_controller)
        self.controller_params = cp
        self._ctrl_every = max(1, int(round(cp.period / self.dt)))
        # the wheel speed controllers: SimTwo's CalcPID (default) or the stand-in's own PI (ideal_pi)
        self.speed_control = config.speed_control
        if config.speed_control == "ideal_pi":
            self.pid_params = None
        else:
            if not robot.simtwo_pid:
                from ..errors import ConfigError

                raise ConfigError(f"robot {robot.name!r} has no 'simtwo_pid' gains for speed control "
                                  f"{config.speed_control!r} (add them, or use --speed-control ideal_pi)")
            self.pid_params = SimTwoPIDParams.from_spec(robot.simtwo_pid, self.dt)
        self._ray_gid = np.zeros(1, dtype=np.int32)
        self._magnet_groups = np.asarray(sc.MAGNET_GROUPS, dtype=np.uint8)
        self._contact_groups = np.asarray(sc.CONTACT_GROUPS, dtype=np.uint8)

        # robot 1 is this object; robots 2..N are units sharing the model and data (see RobotUnit)
        self.index = 1
        self.units: list[Simulator] = [self]
        self._init_robot(self.info.robots[0], eq_names[0], 1)
        for k in range(2, len(self.info.robots) + 1):
            self.units.append(RobotUnit(self, self.info.robots[k - 1], eq_names[k - 1], k))

        # rest everything on the floor, then start the clock and the encoders at t = 0
        mujoco.mj_forward(m, d)
        for _ in range(SETTLE_STEPS):
            mujoco.mj_step(m, d)
        d.time = 0.0
        d.qvel[:] = 0.0
        mujoco.mj_forward(m, d)
        for u in self.units:
            u._start_robot()
        self._start_factory_if_due()

    def _init_robot(self, names: "sc.RobotNames", eq_names: dict[int, str], k: int) -> None:
        """Robot ``k``'s ids, motors, controllers, sensors and camera clock (the model is compiled)."""
        m, config, robot = self.model, self.config, self.robot
        multi = len(self.info.robots) > 1
        name2id = mujoco.mj_name2id
        self.names = names
        self._robot_body = name2id(m, mujoco.mjtObj.mjOBJ_BODY, names.robot_body)
        j = name2id(m, mujoco.mjtObj.mjOBJ_JOINT, names.robot_joint)
        self._qa = int(m.jnt_qposadr[j])
        self._va = int(m.jnt_dofadr[j])
        jl, jr = (name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in names.wheel_joints)
        self._wq = (int(m.jnt_qposadr[jl]), int(m.jnt_qposadr[jr]))
        self._wv = (int(m.jnt_dofadr[jl]), int(m.jnt_dofadr[jr]))
        self._act = tuple(name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in names.actuators)
        self._eq = {pid: name2id(m, mujoco.mjtObj.mjOBJ_EQUALITY, n) for pid, n in eq_names.items()}
        # several robots: this robot's own rays never hit its base body (the others' rays do)
        self._ray_exclude = self._robot_body if multi else -1

        mp, cp = self.motor_params, self.controller_params
        self.motors = (DCMotor(mp, self.dt), DCMotor(mp, self.dt))
        if self.pid_params is None:
            self.controllers = (SpeedPI(cp, mp.Vmax), SpeedPI(cp, mp.Vmax))
        else:
            pp = self.pid_params
            self.controllers = (SimTwoPID(pp), SimTwoPID(pp))
            for c in self.controllers:
                # enabled (and its gains set) once: by the script's first call, whose physics step is the
                # first of the first cycle, or by the scene XML, from SimTwo's first physics step, which
                # is one before the stand-in's first (see sensors.Lidar for the mapping of the clocks)
                c.set_state(True)
                c.ticks = -self.dt if config.simtwo_pid_timing == "scene_enabled" else 0.0
        self._wheel_refs = (0.0, 0.0)  # rad/s, the speed references of the command in force
        self.command = Command.stop()
        self.voltage_override: tuple[float, float] | None = None  # open-loop motor voltages (SetAxisVoltageRef)
        self.magnet_on = False
        self.held: int | None = None
        # SimTwo's electromagnet (magnet="force"): a force every physics step; None: the weld idealisation
        self._magnet = None
        self._mag_engaged = None
        if config.magnet == "force":
            self._magnet = MagnetForce(MagnetParams.from_spec(robot.electromagnet), m, self.data, mujoco,
                                       self._robot_body, sc.MAGNET_Z, self._plate_geoms, self._part_geoms,
                                       dict(self.parts.body), sc.MAGNET_FORCE_GROUPS, self.dt,
                                       bodyexclude=self._ray_exclude)

        # sensors (robot k >= 2: its own noise stream)
        seed = config.seed if k == 1 else config.seed + UNIT_SEED_STRIDE * (k - 1)
        self._lidar = Lidar(robot.lidar, self.dt, seed, config.lidar_noise,
                            sc.LIDAR_GROUPS, update=config.lidar_update,
                            self_groups=sc.LIDAR_SELF_GROUPS if config.lidar_self_hits else None) \
            if config.lidar else None
        if self._lidar is not None:
            self._lidar.bodyexclude = self._ray_exclude
        self.contact = False

        # camera clock: when frames are rendered (SimTwo's GUI cadence or the k/15 s grid), see sim/camera.py;
        # every robot's camera on the same clock (SimTwo's GUI loop renders all its cameras together)
        cam = robot.camera
        self._camera_name = names.robot_camera
        self._cadence = RenderCadence(config.camera_timing, self.dt, cam.render_fps, cam.decimation, config.seed)
        self._schedule = one_in(self._cadence.frames(), config.camera_every)
        # replies: the same GUI loop's turns (the same seed: the same turns as the camera's), see replies_readable
        self._turns = (RenderCadence("simtwo", self.dt, cam.render_fps, cam.decimation, config.seed).iterations()
                       if config.reply_timing == "simtwo" else None)
        self._turn = None  # the GUI turn of the latest script call: (index, last physics step)
        self._call_turn = -1
        self._next_frame: ScheduledFrame = next(self._schedule)
        self._frames: list[CameraFrame] = []
        self._renderer: Renderer | None = None
        self.render_times: deque[float] = deque(maxlen=10000)  # seconds per camera frame, latest last

    def _start_robot(self) -> None:
        """After the settling steps: the LIDAR's self hits, the clock and the encoders at t = 0."""
        m, d = self.model, self.data
        if self._lidar is not None:  # the robot's own wheels as the rays see them (robot frame)
            own = None
            if len(self.units) > 1:
                own = {int(g) for g in range(m.ngeom)
                       if int(m.geom_bodyid[g]) in {mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, b)
                                                   for b in self.names.wheel_bodies}}
            self._lidar.measure_self_hits(m, d, mujoco, d.xpos[self._robot_body], d.xmat[self._robot_body],
                                          own_geoms=own)
        self._step = 0
        self.seq = 0
        self.encoders = (Encoder(self.robot.ticks_per_rev, float(d.qpos[self._wq[0]])),
                         Encoder(self.robot.ticks_per_rev, float(d.qpos[self._wq[1]])))

    # ------------------------------------------------------------------------------------------ setup
    def _initial_parts(self) -> list[tuple[int, str, float, float, float]]:
        cfg = self.config
        parts = []
        if cfg.competition:
            from ..competition import Factory, Referee, RoundSetup

            self.setup = RoundSetup.make(cfg.round_no, seed=cfg.seed, parts=cfg.parts,
                                         processing_delay=cfg.processing_delay, duration=cfg.round_duration)
            self.factory = Factory(self.field, self.setup)
            self.referee = Referee(self.factory)
            p = cfg.perturb
            for pid, ptype, slot in self.factory.initial_parts():
                if p.parts_mm or p.parts_deg:  # put in by hand, off the slot's centre (sim/perturb.py)
                    from .perturb import part_pose

                    x, y, facing = part_pose(self.field, slot, int(pid), p, cfg.round_no, cfg.seed)
                else:
                    x, y, facing = slot.xy[0], slot.xy[1], slot.facing
                parts.append((int(pid), ptype.letter, x, y, facing))
        next_id = max([p[0] for p in parts], default=0) + 1
        for k, pp in enumerate(cfg.extra_parts):
            parts.append((next_id + k, pp.letter, pp.x, pp.y, pp.facing))
        return parts

    def _start_factory_if_due(self) -> None:
        f = self.factory
        if f is not None and not f.started and self.time >= self.config.start_after - 1e-9:
            f.start(self.time)

    # ------------------------------------------------------------------------------------------ state
    @property
    def time(self) -> float:
        """Simulation time (s): exact multiple of the physics step."""
        return self._step * self.dt

    @property
    def time_ms(self) -> int:
        return int(round(self._step * self.dt * 1000))

    @property
    def pose(self) -> tuple[float, float, float]:
        """Ground truth (x, y, theta) of base_link in the field frame (m, m, rad in (-pi, pi])."""
        q = self.data.qpos
        a = self._qa
        return float(q[a]), float(q[a + 1]), sc.quat_yaw(q[a + 3:a + 7])

    @property
    def wheel_speeds(self) -> tuple[float, float]:
        v = self.data.qvel
        return float(v[self._wv[0]]), float(v[self._wv[1]])

    @property
    def wheel_angles(self) -> tuple[float, float]:
        q = self.data.qpos
        return float(q[self._wq[0]]), float(q[self._wq[1]])

    @property
    def lidar_sweeps(self) -> int:
        """LIDAR sweeps published so far (sweep mode; per_ray mode: 0). See :class:`~.sensors.Lidar`."""
        return self._lidar.sweeps if self._lidar is not None else 0

    @property
    def motor_voltages(self) -> tuple[float, float]:
        return self.motors[0].voltage, self.motors[1].voltage

    @property
    def motor_currents(self) -> tuple[float, float]:
        return self.motors[0].current, self.motors[1].current

    @property
    def body_velocity(self) -> tuple[float, float]:
        """Ground-truth (v forward m/s, w rad/s) of the robot body."""
        v = self.data.qvel
        a = self._va
        _, _, th = self.pose
        return float(v[a] * math.cos(th) + v[a + 1] * math.sin(th)), float(v[a + 5])

    def set_pose(self, x: float, y: float, theta: float) -> None:
        """Put the robot at rest at (x, y, theta); releases a held part (a force pending from the magnet is
        dropped; a magnet still on pulls again what is in front of it). Encoders keep counting from here."""
        self._release()
        if self._magnet is not None:
            self._magnet.release()
        q = self.data.qpos
        a = self._qa
        q[a:a + 7] = (x, y, q[a + 2], math.cos(theta / 2), 0.0, 0.0, math.sin(theta / 2))
        self.data.qvel[self._va:self._va + 6] = 0.0
        for i in range(2):
            self.data.qvel[self._wv[i]] = 0.0
            self.motors[i].reset()
            self.controllers[i].reset()
        mujoco.mj_forward(self.model, self.data)

    def place_part(self, part_id: int, x: float, y: float, facing: float) -> None:
        """Teleport a part (at rest) to (x, y) with its plate towards ``facing``."""
        for u in self.units:
            if u.held == part_id:
                u._release()
            if u._magnet is not None and u._magnet.pulled == part_id:
                u._magnet.release()
        self.parts.place(self.data, part_id, x, y, facing)
        mujoco.mj_forward(self.model, self.data)

    def part_pose(self, part_id: int) -> tuple[float, float, float]:
        return self.parts.pose(self.data, part_id)

    def part_letter(self, part_id: int) -> str:
        return self.parts.letter[part_id]

    # ------------------------------------------------------------------------------------------ commands
    def apply(self, cmd: Command) -> None:
        """Make ``cmd`` the command in force: wheel speed references and the electromagnet."""
        v, w = float(cmd.v), float(cmd.w)
        if not (math.isfinite(v) and math.isfinite(w)):
            raise ValueError(f"command with non-finite V/W: {cmd}")
        self.command = cmd
        self.voltage_override = None
        wl, wr = self.robot.wheel_speeds(v, w)
        self._wheel_refs = (wl, wr)
        if self.pid_params is None:
            self.controllers[0].target = wl
            self.controllers[1].target = wr
        if self._magnet is not None:  # SimTwo: SetSensorVin(R, i, on * vin_on), the force follows every step
            self.magnet_on = bool(cmd.magnet)
            self._magnet.vin = self._magnet.p.vin_on if cmd.magnet else 0.0
        elif cmd.magnet and not self.magnet_on:
            self.magnet_on = True
        elif not cmd.magnet and self.magnet_on:
            self.magnet_on = False
            self._release()

    def drive_voltages(self, left: float, right: float) -> None:
        """Drive the motors open loop at these voltages (SimTwo's ``SetAxisVoltageRef`` with the speed
        controller off) until the next :meth:`apply`/:meth:`step_cycle` with a command. Volts, clamped to
        +-Vmax by the motor model."""
        if not (math.isfinite(left) and math.isfinite(right)):
            raise ValueError("motor voltages must be finite")
        self.voltage_override = (float(left), float(right))

    # ------------------------------------------------------------------------------------------ the cycle
    def step_cycle(self, cmd: Command | None = None) -> SensorFrame:
        """Apply ``cmd`` (None: keep the present one) and advance one control period (one robot; a scene of
        several robots steps with :meth:`step_all`)."""
        if len(self.units) > 1:
            raise RuntimeError("a scene of several robots advances with step_all(commands)")
        if cmd is not None:
            self.apply(cmd)
        self._start_factory_if_due()
        n = self.steps_per_cycle
        s0 = self._step
        self._steps((self,), (self._plan_cycle(s0, n),), s0, n)
        self._step = s0 + n
        return self._end_of_cycle()

    def step_all(self, commands) -> list[SensorFrame]:
        """Several robots: apply ``commands[k]`` to robot k + 1 (None: keep its present one), advance one
        control period for all of them together, return their frames (robot 1 first). The factory steps once
        with every robot's position and held part."""
        units = self.units
        if len(commands) != len(units):
            raise ValueError(f"{len(commands)} commands for {len(units)} robots")
        for u, c in zip(units, commands):
            if c is not None:
                u.apply(c)
        self._start_factory_if_due()
        n = self.steps_per_cycle
        s0 = self._step
        self._steps(units, [u._plan_cycle(s0, n) for u in units], s0, n)
        for u in units:
            u._step = s0 + n
            u._measure()
        poses = [u.pose for u in units]
        if self.factory is not None:
            held = {u.held for u in units if u.held is not None}
            self._apply_teleports(self.factory.step(self.time, self.parts.all_xy(self.data), [p[:2] for p in poses],
                                                    held))
        return [u._make_frame(*p) for u, p in zip(units, poses)]

    def _drive_step(self, s: int) -> None:
        """The motor voltages and torques of physics step ``s``, written plainly with :class:`DCMotor`,
        :class:`SpeedPI` and :class:`SimTwoPID` (``reference_drive``; the fast drives must match it)."""
        d = self.data
        qvel, ctrl = d.qvel, d.ctrl
        il, ir = self._wv
        (ml, mr), (pl, pr) = self.motors, self.controllers
        vo = self.voltage_override
        wl, wr = qvel[il], qvel[ir]
        if vo is not None:
            ul, ur = vo
            if self.pid_params is None:
                pl.output, pr.output = vo
        elif self.pid_params is not None:
            ul, ur = pl.tick(wl), pr.tick(wr)
        else:
            if s % self._ctrl_every == 0:
                pl.update(wl)
                pr.update(wr)
            ul, ur = pl.output, pr.output
        ctrl[self._act[0]] = ml.step(ul, wl)
        ctrl[self._act[1]] = mr.step(ur, wr)

    def _plan_cycle(self, s0: int, n: int) -> tuple[list[int], dict[int, list]]:
        """What happens after which physics step of the cycle from step ``s0`` (``n`` steps): the LIDAR's
        pose slots and the camera and magnet events (offset j: after step s0 + j + 1); frames due at the
        cycle's start are rendered now; SimTwo's script iteration of the speed controllers."""
        lidar_slot = [-1] * n
        if self._lidar is not None:
            for slot, j in enumerate(self._lidar.plan(s0, n)):
                lidar_slot[j] = slot
        events: dict[int, list] = {}
        if self.config.camera:
            while self._next_frame.step <= s0 + n:
                sf, self._next_frame = self._next_frame, next(self._schedule)
                if sf.step <= s0:  # due at the start of this cycle: render the state as it is now
                    self._render_frame(sf)
                else:
                    events.setdefault(sf.step - s0 - 1, []).append(("camera", sf))
        self._mag_engaged = None
        if self._magnet is not None:
            engaged, j = self._magnet.plan(s0, n)
            if engaged:
                self._mag_engaged = self._magnet
            elif j is not None:
                events.setdefault(j, []).append(("magnet_idle", 0))
        elif self.magnet_on and self.held is None:
            self._magnet_check()
            for j in range(MAGNET_CHECK_STEPS - 1, n, MAGNET_CHECK_STEPS):
                events.setdefault(j, []).append(("magnet", 0))
        if self.pid_params is not None and self.voltage_override is None:
            # SimTwo's control (script) iteration: ref.volts := 0, then the script sets the speed refs
            # (and, for "simtwo_per_cycle", calls SetMotorControllerState, which zeroes the integral)
            reset = self.speed_control == "simtwo_per_cycle"
            hold = self.config.simtwo_pid_timing == "script_holds_voltage"
            for c, ref in zip(self.controllers, self._wheel_refs):
                c.script_cycle(ref, reset_integral=reset, hold_voltage=hold)
        return lidar_slot, events

    def _on_events(self, step: int, ev: list) -> None:
        self._step = step
        for kind, arg in ev:
            if kind == "camera":
                self._render_frame(arg)
            elif kind == "magnet" and self.held is None:
                self._magnet_check()
            elif kind == "magnet_idle":
                self._magnet.idle_measure()

    def _steps(self, units, plans, s0: int, n: int) -> None:
        """The physics steps of one control cycle from step ``s0`` (``n`` steps), the one stepping loop: per
        step every robot's drive (:meth:`_drive`), the magnets' forces, MuJoCo's step, then each robot's LIDAR
        pose slots and camera and magnet events (``plans``: :meth:`_plan_cycle` per robot)."""
        m, d = self.model, self.data
        qpos = d.qpos
        step = mujoco.mj_step
        drives = [u._drive(s0) for u in units]
        steppers = [dr for dr, _ in drives]
        mags = [u._mag_engaged for u in units if u._mag_engaged is not None]
        logs = [(u._lidar.poses if u._lidar is not None else None, u._qa, slots, events, u)
                for u, (slots, events) in zip(units, plans)]
        for j in range(n):
            for drive in steppers:
                drive(j)
            if mags:
                for mg in mags:
                    mg.pre_step()
                step(m, d)
                for mg in mags:  # ODE cleared every accumulator in the step: all forces first, then the new ones
                    mg.clear()
                for mg in mags:
                    mg.post_step(s0 + j + 1, clear=False)
            else:
                step(m, d)
            for poses, qa, slots, events, u in logs:
                slot = slots[j]
                if slot >= 0:  # the LIDAR's pose after this step: the free joint's x, y, z, qw, qx, qy, qz
                    poses[slot] = qpos[qa:qa + 7].tolist()
                if events and j in events:
                    u._on_events(s0 + j + 1, events[j])
        for _, finish in drives:
            finish()

    def _drive(self, s0: int):
        """This robot's motors and speed controllers over one cycle from step ``s0``: ``(drive, finish)``;
        ``drive(j)`` sets the wheel torques of step s0 + j from the wheel speeds now, ``finish()`` writes back
        the state the drive kept in locals. With ``reference_drive`` the plain arithmetic (:meth:`_drive_step`);
        else the same inlined on local floats (the hot loop: Python's call overhead would cost more than
        MuJoCo's step). Tests check both give identical runs."""
        if self.reference_drive:
            return (lambda j: self._drive_step(s0 + j)), _nothing
        if self.pid_params is not None:
            return self._drive_fast_simtwo(s0)
        return self._drive_fast(s0)

    def _drive_fast(self, s0: int):
        """:meth:`_drive_step` with this project's speed PI (:class:`SpeedPI`) and the motors inlined."""
        d = self.data
        qvel, ctrl = d.qvel, d.ctrl
        il, ir = self._wv
        al, ar = self._act
        ml, mr = self.motors
        pl, pr = self.controllers
        mp, cp = self.motor_params, self.controller_params
        # motor constants
        a, b, ke, kt = ml.a, ml.b, ml.ke, ml.kt
        slew, imax, vmax = mp.slew_A_per_step, mp.Imax, mp.Vmax
        # controller constants
        kp, kf, kc = cp.kp, cp.kf, cp.kc
        kidt = pl._kidt
        dv = pl._dv
        every = self._ctrl_every
        vo = self.voltage_override
        if vo is not None:  # open loop: the controller does not run, its output is the voltage
            pl.output, pr.output = vo
            every = 0
        # state
        Il, Ir = ml.current, mr.current
        vl, vr = pl.output, pr.output
        intl, intr = pl.integral, pr.integral
        refl, refr = pl.ref, pr.ref
        tgl, tgr = pl.target, pr.target

        def drive(j: int) -> None:
            nonlocal Il, Ir, vl, vr, intl, intr, refl, refr
            wl = qvel[il]
            wr = qvel[ir]
            if every == 1 or (every and (s0 + j) % every == 0):
                # left speed PI (SpeedPI.update)
                if tgl - refl > dv:
                    refl += dv
                elif refl - tgl > dv:
                    refl -= dv
                else:
                    refl = tgl
                e = refl - wl
                ii = intl + kidt * e
                u = kf * refl + (kc if refl > 0.0 else (-kc if refl < 0.0 else 0.0)) + kp * e + ii
                if u > vmax:
                    if kidt * e > 0:
                        ii = intl
                    u = vmax
                elif u < -vmax:
                    if kidt * e < 0:
                        ii = intl
                    u = -vmax
                intl = ii
                vl = u
                # right
                if tgr - refr > dv:
                    refr += dv
                elif refr - tgr > dv:
                    refr -= dv
                else:
                    refr = tgr
                e = refr - wr
                ii = intr + kidt * e
                u = kf * refr + (kc if refr > 0.0 else (-kc if refr < 0.0 else 0.0)) + kp * e + ii
                if u > vmax:
                    if kidt * e > 0:
                        ii = intr
                    u = vmax
                elif u < -vmax:
                    if kidt * e < 0:
                        ii = intr
                    u = -vmax
                intr = ii
                vr = u
            # left motor (DCMotor.step)
            v = vmax if vl > vmax else (-vmax if vl < -vmax else vl)
            di = a * Il + b * (v - ke * wl) - Il
            di = slew if di > slew else (-slew if di < -slew else di)
            Il += di
            Il = imax if Il > imax else (-imax if Il < -imax else Il)
            ctrl[al] = kt * Il
            # right motor
            v = vmax if vr > vmax else (-vmax if vr < -vmax else vr)
            di = a * Ir + b * (v - ke * wr) - Ir
            di = slew if di > slew else (-slew if di < -slew else di)
            Ir += di
            Ir = imax if Ir > imax else (-imax if Ir < -imax else Ir)
            ctrl[ar] = kt * Ir

        def finish() -> None:  # the state back into the objects
            ml.current, mr.current = Il, Ir
            ml.voltage = vmax if vl > vmax else (-vmax if vl < -vmax else vl)
            mr.voltage = vmax if vr > vmax else (-vmax if vr < -vmax else vr)
            pl.output, pr.output = vl, vr
            pl.integral, pr.integral = intl, intr
            pl.ref, pr.ref = refl, refr

        return drive, finish

    def _drive_fast_simtwo(self, s0: int):
        """:meth:`_drive_step` with SimTwo's controller: the controller's clock and the motors inlined,
        ``CalcPID`` itself called (every 10 ms) on the :class:`SimTwoPID` objects."""
        d = self.data
        qvel, ctrl = d.qvel, d.ctrl
        il, ir = self._wv
        al, ar = self._act
        ml, mr = self.motors
        pl, pr = self.controllers
        mp, pp = self.motor_params, self.pid_params
        a, b, ke, kt = ml.a, ml.b, ml.ke, ml.kt
        slew, imax, vmax = mp.slew_A_per_step, mp.Imax, mp.Vmax
        odt, per = pp.ode_dt, pp.period
        vo = self.voltage_override
        run = vo is None and pl.active
        if vo is not None:
            vl, vr = vo
        else:
            vl, vr = pl.ref_volts, pr.ref_volts
        tl, tr = pl.ticks, pr.ticks
        refl, refr = pl.ref_w, pr.ref_w
        Il, Ir = ml.current, mr.current

        def drive(j: int) -> None:
            nonlocal Il, Ir, vl, vr, tl, tr
            wl = qvel[il]
            wr = qvel[ir]
            if run:
                tl = tl + odt
                if tl >= per:
                    tl = tl - per
                    vl = pl.calc(refl, refl - wl)
                    pl.runs += 1
                tr = tr + odt
                if tr >= per:
                    tr = tr - per
                    vr = pr.calc(refr, refr - wr)
                    pr.runs += 1
            # left motor (DCMotor.step)
            v = vmax if vl > vmax else (-vmax if vl < -vmax else vl)
            di = a * Il + b * (v - ke * wl) - Il
            di = slew if di > slew else (-slew if di < -slew else di)
            Il += di
            Il = imax if Il > imax else (-imax if Il < -imax else Il)
            ctrl[al] = kt * Il
            # right motor
            v = vmax if vr > vmax else (-vmax if vr < -vmax else vr)
            di = a * Ir + b * (v - ke * wr) - Ir
            di = slew if di > slew else (-slew if di < -slew else di)
            Ir += di
            Ir = imax if Ir > imax else (-imax if Ir < -imax else Ir)
            ctrl[ar] = kt * Ir

        def finish() -> None:  # the state back into the objects
            ml.current, mr.current = Il, Ir
            ml.voltage = vmax if vl > vmax else (-vmax if vl < -vmax else vl)
            mr.voltage = vmax if vr > vmax else (-vmax if vr < -vmax else vr)
            if vo is None:
                pl.ref_volts, pr.ref_volts = vl, vr
                pl.ticks, pr.ticks = tl, tr

        return drive, finish

    def _end_of_cycle(self) -> SensorFrame:
        d = self.data
        self._measure()
        x, y, th = self.pose
        if self.factory is not None:
            held = {self.held} if self.held is not None else set()
            self._apply_teleports(self.factory.step(self.time, self.parts.all_xy(d), (x, y), held))
        return self._make_frame(x, y, th)

    def _measure(self) -> None:
        """The end of a cycle's sensor readings: encoders, the LIDAR's rays, the contact switch."""
        m, d = self.model, self.data
        el, er = self.encoders
        el.update(float(d.qpos[self._wq[0]]))
        er.update(float(d.qpos[self._wq[1]]))
        if self._lidar is not None:
            self._lidar.cast(m, d, mujoco)
        self.contact = self._contact_pressed()
        if self._magnet is not None:  # the part the magnet pulls (what the factory counts as held)
            self.held = self._magnet.pulled

    def _apply_teleports(self, teleports) -> None:
        if teleports:
            for tp in teleports:
                self._teleport(tp)
            mujoco.mj_forward(self.model, self.data)

    def _make_frame(self, x: float, y: float, th: float) -> SensorFrame:
        el, er = self.encoders
        frame = SensorFrame(
            seq=self.seq, time_ms=self.time_ms, enc_delta=(el.delta, er.delta), enc_total=(el.total, er.total),
            x=x, y=y, theta=th, contact=self.contact, magnet=self.magnet_on,
            ranges=self._lidar.ranges.copy() if self._lidar is not None else np.empty(0),
            parts=self._parts_truth() if self.config.report_parts else ())
        self.seq += 1
        return frame

    def _parts_truth(self) -> tuple:
        """The SensorFrame's optional ``Parts``, as simtwo/control.pas reports SimTwo's ``Part1..PartN``: part k
        at index k - 1, SimTwo's heading (the plate's + pi/2); ids up to the highest, the absent ones (an
        empty incoming slot) where SimTwo's scene keeps its spare parts, off the field."""
        ids = self.parts.ids
        if not ids:
            return ()
        out, spare = [], 0
        for pid in range(1, max(ids) + 1):
            if pid in self.parts.qadr:
                x, y, facing = self.parts.pose(self.data, pid)
                out.append((x, y, part_heading(facing)))
            else:
                out.append((*spare_part_xy(spare), 0.0))
                spare += 1
        return tuple(out)

    def _teleport(self, tp) -> None:
        pid = int(tp.part_id)
        if pid not in self.parts.qadr:
            log.warning("factory asked to teleport unknown part %r", pid)
            return
        for u in self.units:
            if u.held == pid:
                u._release()
            if u._magnet is not None and u._magnet.pulled == pid:
                u._magnet.release()
        x, y = tp.slot.xy
        self.parts.place(self.data, pid, x, y, tp.slot.facing)
        self.parts.set_letter(pid, tp.new_type.letter)

    # ------------------------------------------------------------------------------------------ sensors
    def _robot_frame(self):
        d = self.data
        return d.xpos[self._robot_body], d.xmat[self._robot_body].reshape(3, 3)

    def _contact_pressed(self) -> bool:
        c = self.robot.contact
        p, R = self._robot_frame()
        origin = p + R @ (np.asarray(c["xyz"], dtype=np.float64) - (BEAM_BACKOFF, 0.0, 0.0))
        direction = np.ascontiguousarray(R[:, 0])
        dist = mujoco.mj_ray(self.model, self.data, origin, direction, self._contact_groups, 1, self._ray_exclude,
                             self._ray_gid)
        return bool(self._ray_gid[0] >= 0 and 0.0 <= dist <= float(c["beam"]) + BEAM_BACKOFF)

    def _magnet_check(self) -> None:
        """Attach a part whose plate is within the electromagnet's beam and faces it."""
        em = self.robot.electromagnet
        p, R = self._robot_frame()
        origin = p + R @ np.array([float(em["x"]) - BEAM_BACKOFF, 0.0, sc.MAGNET_Z])
        direction = np.ascontiguousarray(R[:, 0])
        dist = mujoco.mj_ray(self.model, self.data, origin, direction, self._magnet_groups, 1, self._ray_exclude,
                             self._ray_gid)
        gid = int(self._ray_gid[0])
        if gid < 0 or not 0.0 <= dist <= float(em["beam"]) + BEAM_BACKOFF:
            return
        pid = self._plate_geoms.get(gid)
        if pid is None:
            return
        if len(self.units) > 1 and any(u.held == pid for u in self.units):
            return  # another robot's magnet holds it
        d = self.data
        part_R = d.xmat[self.parts.body[pid]].reshape(3, 3)
        if float(part_R[:, 0] @ R[:, 0]) > -math.cos(math.radians(45)):
            return  # the plate does not face the magnet
        self._attach(pid)

    def _attach(self, pid: int) -> None:
        """Weld the part to the robot with its plate flat against the magnet (pulled in from the beam)."""
        m, d = self.model, self.data
        p, R = self._robot_frame()
        part_p = d.xpos[self.parts.body[pid]]
        rel = R.T @ (part_p - p)
        fp = self.field.part
        x_rel = float(self.robot.electromagnet["x"]) + MAGNET_GAP + sc.PLATE_THICKNESS + fp.depth / 2
        y_lim = fp.plate[0] / 2
        y_rel = float(np.clip(rel[1], -y_lim, y_lim))
        eq = self._eq[pid]
        # weld data: anchor (3), relpose of body1 (robot) in body2 (part) frame: pos (3), quat (4), torquescale
        # the part frame is the robot frame turned by pi about z and shifted by (x_rel, y_rel, rel_z)
        # robot origin in the part frame: R_z(pi)^T @ (-(x_rel, y_rel, z)) = (x_rel, y_rel, -z)
        m.eq_data[eq, 0:3] = 0.0
        m.eq_data[eq, 3:6] = (x_rel, y_rel, -float(rel[2]))
        m.eq_data[eq, 6:10] = (0.0, 0.0, 0.0, 1.0)
        m.eq_data[eq, 10] = 1.0
        d.eq_active[eq] = 1
        self.held = pid

    def _release(self) -> None:
        if self.held is not None:
            self.data.eq_active[self._eq[self.held]] = 0
            self.held = None

    # ------------------------------------------------------------------------------------------ camera
    def _get_renderer(self) -> Renderer:
        if self._renderer is None:
            c = self.robot.camera
            self._renderer = Renderer(self.model, self._camera_name, c.width, c.height)
        return self._renderer

    def _render_frame(self, sf: ScheduledFrame) -> None:
        t0 = time.perf_counter()
        rgb = self._get_renderer().render(self.data).copy()
        self.render_times.append(time.perf_counter() - t0)
        self._frames.append(CameraFrame(index=sf.index, tick=sf.tick, tick_time=sf.tick_time, time=self.time,
                                        rgb_bottom_up=rgb, wall=sf.wall))

    def replies_readable(self) -> bool:
        """Whether the script call before the next cycle can read the replies that came since the previous
        call (``reply_timing="simtwo"``): SimTwo's script reads UDP from its GUI thread's message handling, so
        only when a GUI turn ended between the two calls; the later calls of one catch-up turn read nothing
        (docs/simtwo.md). The call before physics step ``b + 1`` runs in the turn with ``first_step <= b <
        first_step + steps`` (:class:`~.camera.GuiIteration`). Always True for ``"every_cycle"``. Call once
        per cycle, before :meth:`step_cycle`."""
        if self._turns is None:
            return True
        step = self._step
        while self._turn is None or self._turn[1] <= step:
            it = next(self._turns)
            self._turn = ((self._turn[0] + 1) if self._turn is not None else 0, it.first_step + it.steps)
        readable = self._turn[0] != self._call_turn
        self._call_turn = self._turn[0]
        return readable

    def take_frames(self) -> list[CameraFrame]:
        """Camera frames rendered since the last call, oldest first (publish them before the next frame)."""
        out, self._frames = self._frames, []
        return out

    def render_camera(self) -> np.ndarray:
        """The robot camera's view of the present state: H x W x 3 uint8 BGR, top row first."""
        return self._get_renderer().render_bgr(self.data)

    def camera_pose(self) -> np.ndarray:
        """4x4 world <- camera_optical (OpenCV: x right, y down, z forward) from the simulated state."""
        m, d = self.model, self.data
        cid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, self._camera_name)
        T = np.eye(4)
        T[:3, :3] = d.cam_xmat[cid].reshape(3, 3) @ np.diag([1.0, -1.0, -1.0])
        T[:3, 3] = d.cam_xpos[cid]
        return T

    def snapshot(self, path=None, width: int = 1280, height: int = 960, camera: str = "overview") -> np.ndarray:
        """An overview render (BGR, top row first) of the scene; written as PNG when ``path`` is given.
        The model must have been built with ``offscreen`` at least (width, height)."""
        import cv2

        r = Renderer(self.model, camera, width, height)
        try:
            img = r.render_bgr(self.data)
        finally:
            r.close()
        if path is not None:
            if not cv2.imwrite(str(path), img):
                raise OSError(f"cannot write {path}")
        return img

    def close(self) -> None:
        for u in getattr(self, "units", [self]):
            if u._renderer is not None:
                u._renderer.close()
                u._renderer = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown: nothing left to report to
            pass


class RobotUnit(Simulator):
    """Robot k >= 2 of a scene of several robots: its own motors, controllers, sensors, camera, magnet and
    frame counter, sharing the main :class:`Simulator`'s model, data, parts and competition. Read it as a
    Simulator (``pose``, ``held``, ``take_frames()``, ``render_camera()``...); the scene advances with the
    main simulator's :meth:`Simulator.step_all`."""

    _SHARED = ("reference_drive", "field", "robot", "nominal_field", "nominal_robot", "world", "config", "factory", "referee", "setup", "info", "spec",
               "model", "data", "dt", "steps_per_cycle", "parts", "_plate_geoms", "_part_geoms", "motor_params",
               "controller_params", "_ctrl_every", "speed_control", "pid_params", "_magnet_groups",
               "_contact_groups", "units")

    def __init__(self, main: Simulator, names, eq_names: dict[int, str], k: int):  # noqa: D107 - see the class
        self.main = main
        for a in self._SHARED:
            setattr(self, a, getattr(main, a))
        self._ray_gid = np.zeros(1, dtype=np.int32)
        self._renderer = None
        self.index = k
        self._init_robot(names, eq_names, k)

    def step_cycle(self, cmd: Command | None = None) -> SensorFrame:
        raise RuntimeError("a scene of several robots advances with the main simulator's step_all(commands)")

    def _start_factory_if_due(self) -> None:
        self.main._start_factory_if_due()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def _nothing() -> None:
    pass
