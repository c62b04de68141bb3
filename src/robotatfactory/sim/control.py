"""The stand-in's control channel: reset, pause, resume, step, teleport, place/remove parts, read the state.

A small request/reply protocol on its own loopback UDP port (``raf sim --control-port``, default the
command port + :data:`CONTROL_PORT_OFFSET`): one JSON object per datagram, one JSON reply per request to
the request's source address. docs/protocol.md ("Control channel") is the reference; in short::

    {"op": "pause", "id": 7}                       -> {"ok": true, "op": "pause", "id": 7, "paused": true, ...}
    {"op": "step", "cycles": 5}                    -> (after 5 control cycles) {"ok": true, "seq": ..., ...}
    {"op": "set_robot_pose", "x": 0.1, "y": 0.2, "theta": 1.57}
    {"op": "place_part", "part": 1, "slot": "outgoing_2"}   or   "x": .., "y": .., "facing": ..
    {"op": "remove_part", "part": 1}
    {"op": "reset", "seed": 3, "round": 2, "parts": "RGBX", "start_pose": [x, y, theta]}  (all optional)
    {"op": "get_state"}
    {"op": "nonsense"} -> {"ok": false, "error": "unknown_op", "message": "...", "id": null}

Requests are applied by :class:`SimRunner` between control cycles (never during one), so a request can not
corrupt a cycle in progress; a request that fails is rejected whole (the scene is left as it was). A reset
builds a fresh :class:`~robotatfactory.sim.Simulator` from the same field, robot and configuration (with the
request's changes): its frames are those of a fresh start, byte for byte (Seq from 0, Tms from 40).

No I/O and no ROS here: :class:`SimControl` turns request bytes into replies and acts on the runner.
Units: metres, radians, seconds; poses in the field frame.
"""
from __future__ import annotations

import dataclasses
import json
import logging
import math

log = logging.getLogger(__name__)

CONTROL_PORT_OFFSET = 4  # default control port = command port + 4 (control_port_for)
MAX_REQUEST = 4096  # bytes
MAX_STEP_CYCLES = 100_000  # cycles one step request may ask for (~67 simulated minutes)
OPS = ("reset", "pause", "resume", "step", "set_robot_pose", "place_part", "remove_part", "get_state")
PARK_DISTANCE = 20.0  # m beyond the field's floor where removed parts rest (outside every sensor's reach)

ERRORS = {  # error code -> meaning (docs/protocol.md lists them)
    "bad_request": "not a JSON object of at most 4096 bytes",
    "unknown_op": "op is missing or not one of OPS",
    "bad_argument": "a field is missing, of the wrong type, not finite or out of range",
    "not_paused": "step needs a paused simulation",
    "busy": "a step is still running",
    "unknown_part": "no part with this id in the scene",
    "unknown_slot": "no slot of that name on the field",
    "out_of_field": "the pose is not on the field's floor",
    "reset_failed": "the new scene could not be built (the old one keeps running)",
}


class ControlError(Exception):
    """A request that cannot be applied: ``code`` is one of :data:`ERRORS`."""

    def __init__(self, code: str, message: str):
        super().__init__(message)
        self.code = code


def control_port_for(command_port: int) -> int:
    """The default control port of a simulator whose command port is ``command_port`` (0 stays 0: any)."""
    return command_port + CONTROL_PORT_OFFSET if command_port else 0


def parse_request(data: bytes) -> dict:
    """One datagram to a request dict with an ``op``; ControlError otherwise."""
    if len(data) > MAX_REQUEST:
        raise ControlError("bad_request", f"request of {len(data)} bytes (at most {MAX_REQUEST})")
    try:
        req = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as e:
        raise ControlError("bad_request", f"not JSON: {e}") from None
    if not isinstance(req, dict):
        raise ControlError("bad_request", "a request is a JSON object, e.g. {\"op\": \"get_state\"}")
    op = req.get("op")
    if op not in OPS:
        raise ControlError("unknown_op", f"op {op!r}: expected one of {', '.join(OPS)}")
    return req


def _number(req: dict, key: str, default=None) -> float:
    v = req.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ControlError("bad_argument", f"{key!r} must be a finite number, got {v!r}")
    return float(v)


def _int(req: dict, key: str, lo: int, hi: int, default=None) -> int:
    v = req.get(key, default)
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise ControlError("bad_argument", f"{key!r} must be an integer {lo}..{hi}, got {v!r}")
    return v


def encode_reply(reply: dict) -> bytes:
    return json.dumps(reply, separators=(",", ":"), allow_nan=False).encode("utf-8")


def error_reply(req_id, op, code: str, message: str) -> dict:
    return {"ok": False, "id": req_id, "op": op, "error": code, "message": message}


class SimControl:
    """Pause/step state and the requests' effects on a runner's simulator.

    ``runner`` provides ``sim`` (the :class:`Simulator`) and ``replace_sim(new_sim)`` (used by reset).
    """

    def __init__(self, runner):
        self.runner = runner
        self.paused = False
        self.steps_left = 0  # cycles the present step request still runs
        self.pending = None  # (reply dict, address) of the step request in progress
        self.removed: set[int] = set()
        self.resets = 0
        self.requests = 0
        self.errors = 0

    # ------------------------------------------------------------------------------------------ the loop
    @property
    def may_run(self) -> bool:
        """True when the runner may run the next control cycle (not paused, or a step is in progress)."""
        return not self.paused or self.steps_left > 0

    def cycle_done(self):
        """Call after each control cycle; returns (reply, address) when a step request has just finished."""
        if self.steps_left <= 0:
            return None
        self.steps_left -= 1
        if self.steps_left == 0 and self.pending is not None:
            reply, addr = self.pending
            self.pending = None
            reply.update(self.summary())
            return reply, addr
        return None

    def handle(self, data: bytes, addr=None) -> dict | None:
        """Apply one request; its reply, or None when the reply comes later (a step: see :meth:`cycle_done`)."""
        self.requests += 1
        req_id = op = None
        try:
            req = parse_request(data)
            req_id, op = req.get("id"), req["op"]
            if not (req_id is None or isinstance(req_id, (int, str))):
                raise ControlError("bad_argument", f"'id' must be an integer or a string, got {req_id!r}")
            out = getattr(self, f"_op_{op}")(req)
            if out is None:  # deferred (step)
                self.pending = ({"ok": True, "id": req_id, "op": op}, addr)
                return None
            return {"ok": True, "id": req_id, "op": op, **out}
        except ControlError as e:
            self.errors += 1
            return error_reply(req_id, op, e.code, str(e))

    # ------------------------------------------------------------------------------------------ requests
    def _op_pause(self, req):
        self.paused = True
        return self.summary()

    def _op_resume(self, req):
        if self.steps_left > 0:
            raise ControlError("busy", f"a step request has {self.steps_left} cycles to run")
        self.paused = False
        self.runner.on_resume()
        return self.summary()

    def _op_step(self, req):
        n = _int(req, "cycles", 1, MAX_STEP_CYCLES, default=1)
        if not self.paused:
            raise ControlError("not_paused", "step runs control cycles of a paused simulation: pause first")
        if self.steps_left > 0:
            raise ControlError("busy", f"a step request has {self.steps_left} cycles to run")
        self.steps_left = n
        return None

    def _op_get_state(self, req):
        return self.state()

    def _op_set_robot_pose(self, req):
        x, y, th = _number(req, "x"), _number(req, "y"), _number(req, "theta", 0.0)
        sim = self.runner.sim
        if not sim.field.floor.contains(x, y):
            raise ControlError("out_of_field", f"({x:g}, {y:g}) is not on the floor of field {sim.field.name!r}")
        sim.set_pose(x, y, math.remainder(th, 2 * math.pi))
        return self.summary()

    def _part(self, req) -> int:
        sim = self.runner.sim
        pid = req.get("part")
        if isinstance(pid, bool) or not isinstance(pid, int) or pid not in sim.parts.qadr:
            raise ControlError("unknown_part", f"part {pid!r}: the scene's parts are {sorted(sim.parts.qadr)}")
        return pid

    def _op_place_part(self, req):
        sim = self.runner.sim
        pid = self._part(req)
        if "slot" in req:
            name = req["slot"]
            slots = {s.name: s for s in sim.field.slots}
            if not isinstance(name, str) or name not in slots:
                raise ControlError("unknown_slot", f"slot {name!r}: expected one of {', '.join(sorted(slots))}")
            s = slots[name]
            x, y, facing = s.xy[0], s.xy[1], s.facing
        else:
            x, y, facing = _number(req, "x"), _number(req, "y"), _number(req, "facing", 0.0)
            if not sim.field.floor.contains(x, y):
                raise ControlError("out_of_field", f"({x:g}, {y:g}) is not on the floor of field {sim.field.name!r}")
        letter = req.get("type")
        if letter is not None and letter not in ("R", "G", "B"):
            raise ControlError("bad_argument", f"'type' {letter!r}: expected R, G or B")
        sim.place_part(pid, x, y, facing)
        if letter is not None:
            sim.parts.set_letter(pid, letter)
        self.removed.discard(pid)
        return {**self.summary(), "part": pid, "part_pose": list(sim.part_pose(pid))}

    def _op_remove_part(self, req):
        sim = self.runner.sim
        pid = self._part(req)
        x = sim.field.floor.x[1] + PARK_DISTANCE + 0.5 * sim.parts.ids.index(pid)
        sim.place_part(pid, x, sim.field.floor.y[0], 0.0)
        self.removed.add(pid)
        return {"part": pid, **self.summary()}

    def _op_reset(self, req):
        sim = self.runner.sim
        if self.steps_left > 0:
            raise ControlError("busy", f"a step request has {self.steps_left} cycles to run")
        changes = {}
        if "seed" in req:
            changes["seed"] = _int(req, "seed", 0, 2**31 - 1)
        if "round" in req:
            changes["round_no"] = _int(req, "round", 1, 3)
        if "parts" in req:
            p = req["parts"]
            if p is not None and (not isinstance(p, str) or not p or any(c not in "RGBX" for c in p)):
                raise ControlError("bad_argument", f"'parts' {p!r}: a layout such as 'RGBX' (R, G, B, X) or null")
            changes["parts"] = p
        if "start_pose" in req:
            sp = req["start_pose"]
            if sp is not None:
                if not isinstance(sp, list) or len(sp) != 3:
                    raise ControlError("bad_argument", f"'start_pose' {sp!r}: [x, y, theta] or null")
                sp = tuple(_number({"v": v}, "v") for v in sp)
                if not sim.field.floor.contains(sp[0], sp[1]):
                    raise ControlError("out_of_field", f"start pose {sp!r} is not on the field's floor")
            changes["start_pose"] = sp
        from ..errors import ConfigError
        from .simulator import Simulator

        try:
            config = dataclasses.replace(sim.config, **changes)
            # the nominal map and robot: the new simulator draws its own world from them (sim/perturb.py)
            new = Simulator(sim.nominal_field, sim.nominal_robot, config, reference_drive=sim.reference_drive)
        except (ConfigError, ValueError, KeyError) as e:
            raise ControlError("reset_failed", f"{e}") from None
        self.runner.replace_sim(new)
        self.removed.clear()
        self.resets += 1
        return self.state()

    # ------------------------------------------------------------------------------------------ state
    def summary(self) -> dict:
        sim = self.runner.sim
        return {"paused": self.paused, "seq": sim.seq, "time": round(sim.time, 6), "pose": list(sim.pose)}

    def state(self) -> dict:
        """The simulation's state as JSON-able values (see docs/protocol.md)."""
        sim = self.runner.sim
        c = sim.config
        parts = [{"id": pid, "type": sim.part_letter(pid), "pose": list(sim.part_pose(pid)),
                  "removed": pid in self.removed} for pid in sim.parts.ids]
        v, w = sim.body_velocity
        out = {**self.summary(), "velocity": [v, w], "held": sim.held, "magnet": sim.magnet_on,
               "contact": sim.contact, "seed": c.seed, "round": c.round_no, "layout": c.parts,
               "field": sim.field.name, "parts": parts, "resets": self.resets, "ops": list(OPS)}
        if sim.referee is not None:
            out["score"] = sim.referee.report(sim.time).short()
        return out


class ControlClient:
    """Client of the control channel (the bridge's services use it). ``request`` sends one request and
    returns the reply dict; ``ConnectionError`` when nothing answers within ``timeout`` wall seconds (a step
    request waits ``step_timeout`` per 100 cycles more). Thread-safe (one socket per request)."""

    def __init__(self, address: tuple[str, int], timeout: float = 1.0, step_timeout: float = 5.0):
        self.address = (address[0], int(address[1]))
        self.timeout = timeout
        self.step_timeout = step_timeout
        self._ids = iter(range(1, 2**62))

    def request(self, op: str, timeout: float | None = None, **fields) -> dict:
        import socket

        rid = next(self._ids)
        req = {"op": op, "id": rid, **fields}
        if timeout is None:
            timeout = self.timeout
            if op == "step":
                timeout += self.step_timeout * (1 + int(fields.get("cycles", 1)) // 100)
            elif op == "reset":
                timeout += 10.0  # a new scene is compiled
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            s.settimeout(timeout)
            s.sendto(encode_reply(req), self.address)
            while True:
                data, _ = s.recvfrom(65535)
                reply = json.loads(data)
                if reply.get("id") == rid:
                    return reply
        except (OSError, ValueError) as e:  # timeout, port unreachable (ICMP), garbage
            raise ConnectionError(f"no answer from the control channel at {self.address[0]}:{self.address[1]} "
                                  f"({e.__class__.__name__}: {e})") from None
        finally:
            s.close()
