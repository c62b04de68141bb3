"""The bridge's simulation services (``sim/reset``, ``sim/pause``, ... ``sim/get_state``), after ROS 2's
``simulation_interfaces`` (ResetSimulation, SetSimulationState, StepSimulation, SetEntityState,
GetSimulationState) in ROS 1 form: the package's own .srv types (srv/*.srv, classes generated into
``robotatfactory.srv``), callable with ``rosservice call``. docs/bridge.md describes them.

Two simulators:

* **the stand-in** (``raf sim``): every service, through its control channel (:mod:`robotatfactory.sim.control`,
  ``~simulator/control``, default the simulator's command port + 4);
* **SimTwo** (no control channel answers): ``set_robot_pose``, ``place_part`` and a robot-only ``reset``
  through the Command datagram's teleport labels (:mod:`robotatfactory.simtwo.teleport`, applied by
  simtwo/control.pas with SimTwo's ``SetRobotPos``), ``get_state`` from the last SensorFrame; ``pause``,
  ``resume`` and ``step`` answer ``success: false`` (SimTwo's script API has no call for them).

Which one is connected is probed at start and again at every call (the simulator may start after the
bridge); ``sim/get_state`` and the start-up log say which and what it supports.
"""
from __future__ import annotations

import json
import math
import threading
import time

from ..sim import standard
from ..sim.control import ControlClient
from ..simtwo.teleport import (SIMTWO_PART_PREFIX, SIMTWO_PART_Z, TeleportSender, part_heading, plate_facing,
                               spare_part_xy)
from .mw import api

SERVICES = ("reset", "pause", "resume", "step", "set_robot_pose", "place_part", "get_state")
SIMTWO_SERVICES = ("reset", "set_robot_pose", "place_part", "get_state")
STANDIN, SIMTWO = "stand-in", "simtwo"
TELEPORT_WAIT = 3.0  # wall s a SimTwo teleport may take to be delivered and seen in the ground truth
PROBE_REUSE = 1.0  # wall s: backend() reuses a probe this young
POSE_TOLERANCE = 0.02  # m: the ground truth confirms a SimTwo teleport of the robot


class SimServices:
    """The ``sim/*`` services of one bridge. ``bridge`` is the :class:`~.bridge_node.Bridge`."""

    def __init__(self, bridge, control: tuple[str, int] | None, namespace: str = "sim", repeats: int = 5):
        self.bridge = bridge
        self.client = ControlClient(control, timeout=0.5) if control else None
        self.namespace = namespace.rstrip("/")
        self.teleports = TeleportSender(repeats)
        self.kind: str | None = None
        self.services: list = []
        self.standin = standard.StandInBackend(self.client, self._standin_backend_reset) if self.client else None
        self.simtwo = SimTwoBackend(self)
        self._probed = -1e9  # monotonic time of backend()'s last probe

    def backend(self):
        """The connected simulator as :mod:`robotatfactory.sim.standard` sees it: probed again when the last
        probe is older than :data:`PROBE_REUSE` (one standard call asks several times; SimTwo's probe costs its
        timeout, 0.3 s)."""
        now = time.monotonic()
        if self.kind is None or now - self._probed > PROBE_REUSE:
            self.probe()
            self._probed = now
        return self.standin if self.kind == STANDIN else self.simtwo

    def _standin_reset(self, **fields) -> tuple[bool, str]:
        """A stand-in reset: the bridge expects the new stream, then waits for its first frame unless the
        simulation stays paused. (ok, message)."""
        self.bridge.expect_restart()
        err, r = self.standin.call("reset", **fields)
        if err:
            self.bridge.expect_restart(False)
            return False, err
        self.bridge._reset_commands()
        if r.get("paused"):
            return True, "reset (paused: the new stream starts at the next step or resume)"
        if self.bridge.wait_restarted(3.0):
            return True, "reset: the new stream is published"
        return False, "reset done, but no frame of the new stream within 3 s"

    def _standin_backend_reset(self) -> str:
        ok, msg = self._standin_reset()
        return "" if ok else msg

    # ------------------------------------------------------------------------------------------ setup
    def start(self) -> "SimServices":
        ns, srv, node = self.namespace, api().srv_types(), self.bridge.node
        for name, typ, fn in (("reset", srv.ResetSimulation, self._reset), ("pause", srv.Trigger, self._pause),
                              ("resume", srv.Trigger, self._resume), ("step", srv.StepSimulation, self._step),
                              ("set_robot_pose", srv.SetRobotPose, self._set_robot_pose),
                              ("place_part", srv.PlacePart, self._place_part),
                              ("get_state", srv.GetSimulationState, self._get_state)):
            self.services.append(node.service(f"{ns}/{name}", typ, fn))
        # the first probe in the background: the node's start-up does not wait for a simulator's answer
        threading.Thread(target=self.probe, kwargs={"log": True}, name="raf-sim-services-probe", daemon=True).start()
        return self

    def shutdown(self) -> None:
        """Stop serving: the services leave the graph (on ROS 1 a call already being answered still gets its
        answer; on ROS 2 the closed service cannot send one, and the caller's wait ends in its timeout)."""
        for s in self.services:
            self.bridge.node.close(s)
        self.services.clear()

    def probe(self, log: bool = False) -> str:
        """Which simulator is connected: the stand-in when its control channel answers, else SimTwo."""
        kind = SIMTWO
        if self.client is not None:
            try:
                if self.client.request("get_state", timeout=0.3).get("ok"):
                    kind = STANDIN
            except ConnectionError:
                pass
        if log or kind != self.kind:
            where = (f"control channel udp {self.client.address[0]}:{self.client.address[1]}"
                     if self.client else "no control channel configured")
            if kind == STANDIN:
                self.bridge.node.info(f"bridge: simulation services {self.namespace}/*: the stand-in ({where}) "
                                      f"supports all: {', '.join(SERVICES)}")
            else:
                self.bridge.node.info(f"bridge: simulation services {self.namespace}/*: SimTwo assumed ({where}: no "
                              f"answer): supported {', '.join(SIMTWO_SERVICES)} (reset: the robot only) through "
                              f"the Command datagram's teleport labels (simtwo/control.pas); pause, resume, step: "
                              "not supported")
        self.kind = kind
        return kind

    def supported(self) -> list[str]:
        return list(SERVICES if self.kind == STANDIN else SIMTWO_SERVICES)

    # ------------------------------------------------------------------------------------------ helpers
    def _call(self, op: str, **fields) -> tuple[bool, str, dict]:
        """A stand-in request: (success, message, reply)."""
        err, r = self.standin.call(op, **fields)
        return not err, err, r

    def _unsupported(self, what: str) -> str:
        return (f"{what} is not supported by SimTwo (its script API has no call for it); supported: "
                f"{', '.join(SIMTWO_SERVICES)}")

    def _teleport(self, x, y, theta, z=0.0, target="") -> tuple[bool, str]:
        """SimTwo: send a teleport in the next replies; for the robot, wait until the ground truth shows it."""
        if self.bridge.gate.bound is None:
            return False, "no SensorFrame stream bound yet: nothing to send the teleport to"
        t = self.teleports.request(x, y, theta, z, target)
        end = time.monotonic() + TELEPORT_WAIT
        while not self.teleports.delivered(t):
            if time.monotonic() > end:
                return False, f"teleport {t.id} not delivered in {TELEPORT_WAIT} s (is SimTwo streaming?)"
            time.sleep(0.01)
        if target:
            return True, f"teleport {t.id} of {target} sent {self.teleports.repeats} times"
        while True:
            gt = self.bridge.ground_truth()
            if gt is not None and math.hypot(gt[1] - x, gt[2] - y) < POSE_TOLERANCE:
                return True, f"robot at ({gt[1]:.3f}, {gt[2]:.3f}, {gt[3]:.3f}) (teleport {t.id})"
            if time.monotonic() > end:
                return False, (f"teleport {t.id} sent, but the ground truth does not show it (SimTwo's script "
                               "without teleport support? see docs/simtwo.md)")
            time.sleep(0.01)

    # ------------------------------------------------------------------------------------------ services
    def _reset(self, req, resp):
        kind = self.probe()
        if kind == STANDIN:
            fields = {}
            if req.round:
                fields["round"] = int(req.round)
            if req.set_seed:
                fields["seed"] = int(req.seed)
            if req.parts:
                fields["parts"] = req.parts
            if req.set_start_pose:
                fields["start_pose"] = [req.x, req.y, req.theta]
            return _answer(resp, *self._standin_reset(**fields))
        if req.round or req.set_seed or req.parts:
            return _answer(resp, False, "SimTwo resets the robot only (round, seed and parts: restart "
                                                  "the scene in SimTwo)")
        sp = self.bridge.field.start_pose
        x, y, th = (req.x, req.y, req.theta) if req.set_start_pose else (sp.x, sp.y, sp.theta)
        self.bridge._reset_commands()
        ok, msg = self._teleport(x, y, th)
        if ok:
            self.bridge.expect_restart(True, odometry_only=True)
            ok = self.bridge.wait_restarted(2.0)
            msg = "robot reset, odometry restarted: " + msg if ok else "robot moved, but no frame since"
        return _answer(resp, ok, msg)

    def _pause(self, req, resp):
        if self.probe() != STANDIN:
            return _answer(resp, False, self._unsupported("pause"))
        ok, msg, r = self._call("pause")
        return _answer(resp, ok, msg or f"paused at t = {r['time']:.3f} s")

    def _resume(self, req, resp):
        if self.probe() != STANDIN:
            return _answer(resp, False, self._unsupported("resume"))
        ok, msg, r = self._call("resume")
        return _answer(resp, ok, msg or f"running from t = {r['time']:.3f} s")

    def _step(self, req, resp):
        if self.probe() != STANDIN:
            return _answer(resp, False, self._unsupported("step"))
        ok, msg, r = self._call("step", cycles=int(req.steps))
        return _answer(resp, ok, msg or f"stepped to Seq {r['seq']}, t = {r['time']:.3f} s")

    def _set_robot_pose(self, req, resp):
        if self.probe() == STANDIN:
            ok, msg, r = self._call("set_robot_pose", x=req.x, y=req.y, theta=req.theta)
            return _answer(resp, ok, msg or "robot at ({:.3f}, {:.3f}, {:.3f})".format(*r["pose"]))
        if not self.bridge.field.floor.contains(req.x, req.y):
            return _answer(resp, False, f"out_of_field: ({req.x:g}, {req.y:g}) is not on the floor")
        return _answer(resp, *self._teleport(req.x, req.y, req.theta))

    def _place_part(self, req, resp):
        if self.probe() == STANDIN:
            if req.remove:
                ok, msg, r = self._call("remove_part", part=int(req.part))
                return _answer(resp, ok, msg or f"part {req.part} removed")
            fields = {"part": int(req.part)}
            if req.slot:
                fields["slot"] = req.slot
            else:
                fields.update(x=req.x, y=req.y, facing=req.facing)
            if req.type:
                fields["type"] = req.type
            ok, msg, r = self._call("place_part", **fields)
            return _answer(resp, ok, msg or "part {} at ({:.3f}, {:.3f}, {:.3f})".format(req.part, *r["part_pose"]))
        if req.type:
            return _answer(resp, False, "SimTwo cannot recolour a part (type must be empty)")
        if req.part < 1:
            return _answer(resp, False, f"unknown_part: {req.part} (SimTwo's parts are Part1..Part4)")
        field = self.bridge.field
        if req.remove:
            (x, y), facing = parking(int(req.part)), 0.0
        elif req.slot:
            slots = {s.name: s for s in field.slots}
            if req.slot not in slots:
                return _answer(resp, False, f"unknown_slot: {req.slot!r}")
            s = slots[req.slot]
            x, y, facing = s.xy[0], s.xy[1], s.facing
        else:
            if not field.floor.contains(req.x, req.y):
                return _answer(resp, False, f"out_of_field: ({req.x:g}, {req.y:g}) is not on the floor")
            x, y, facing = req.x, req.y, req.facing
        return _answer(resp, *self._teleport(x, y, part_heading(facing), SIMTWO_PART_Z,
                                                 f"{SIMTWO_PART_PREFIX}{int(req.part)}"))

    def _get_state(self, req, resp):
        kind = self.probe()
        out = resp
        out.success, out.simulator, out.supported = True, kind, self.supported()
        if kind == STANDIN:
            ok, msg, r = self._call("get_state")
            if not ok:
                out.success, out.message = False, msg
                return out
            out.paused, out.time, out.seq = bool(r["paused"]), float(r["time"]), int(r["seq"])
            out.x, out.y, out.theta = (float(v) for v in r["pose"])
            out.state_json = json.dumps(r)
            out.message = "stand-in: " + ("paused" if out.paused else "running")
            return out
        gt = self.bridge.ground_truth()
        tr = self.bridge.tracker
        if gt is None:
            out.message = "SimTwo: no SensorFrame yet"
            return out
        out.time, out.x, out.y, out.theta = (float(v) for v in gt)
        out.seq = tr.last_seq if tr.last_seq is not None else 0
        out.message = "SimTwo: from the last SensorFrame (pause state unknown)"
        return out


class SimTwoBackend:
    """SimTwo for :mod:`robotatfactory.sim.standard`: the ground truth of the last SensorFrame (the robot, and
    the parts when the script sends ``Parts``), teleports through the Command datagram's labels. No pause, no
    step, no reset (SimTwo's script API has no call for them): its features say so."""

    name = "simtwo"
    features = standard.SIMTWO_FEATURES

    def __init__(self, services: SimServices):
        self.s = services

    def snapshot(self):
        b = self.s.bridge
        gt = b.ground_truth()
        if gt is None:
            return "no SensorFrame from SimTwo yet"
        _, parts = b.parts_truth()
        floor = b.field.floor
        out = tuple(standard.PartTruth(k + 1, "", x, y, plate_facing(h), floor.contains(x, y))
                    for k, (x, y, h) in enumerate(parts))
        return standard.Snapshot(float(gt[0]), tuple(gt[1:]), b.ground_truth_velocity(), out, None)

    def set_robot_pose(self, x, y, yaw) -> str:
        ok, msg = self.s._teleport(x, y, yaw)
        return "" if ok else msg

    def place_part(self, pid, x, y, facing, letter) -> str:
        if letter:
            return "SimTwo cannot recolour a part: use uri 'raf://part'"
        ok, msg = self.s._teleport(x, y, part_heading(facing), SIMTWO_PART_Z, f"{SIMTWO_PART_PREFIX}{pid}")
        if not ok:
            return msg
        return self._seen(pid, x, y)

    def remove_part(self, pid) -> str:
        x, y = parking(pid)
        ok, msg = self.s._teleport(x, y, 0.0, SIMTWO_PART_Z, f"{SIMTWO_PART_PREFIX}{pid}")
        return self._seen(pid, x, y) if ok else msg

    def _seen(self, pid: int, x: float, y: float) -> str:
        """Wait until the frames' ``Parts`` show part ``pid`` at (x, y) (nothing to wait for without them)."""
        end = time.monotonic() + TELEPORT_WAIT
        while True:
            _, parts = self.s.bridge.parts_truth()
            if len(parts) < pid:
                return ""
            px, py, _ = parts[pid - 1]
            if math.hypot(px - x, py - y) < POSE_TOLERANCE:
                return ""
            if time.monotonic() > end:
                return f"part {pid} teleported, but SimTwo's ground truth shows it at ({px:.3f}, {py:.3f})"
            time.sleep(0.01)

    def pause(self, *_args) -> str:
        return "SimTwo's script API has no pause, step or reset"

    resume = step = reset = pause


def parking(pid: int) -> tuple[float, float]:
    """Where SimTwo's part ``pid`` goes when it is removed: beside the scene's spare parts (off the field, on
    SimTwo's ground: 20 m away there is none, and a part put there falls and drifts)."""
    return spare_part_xy(3 + pid)


def _answer(resp, success: bool, message: str):
    """Fill a response with ``success`` and ``message`` fields."""
    resp.success, resp.message = bool(success), str(message)
    return resp
