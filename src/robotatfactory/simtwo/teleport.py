"""Teleports for SimTwo: optional labels of the Command datagram that simtwo/control.pas applies with SimTwo's
``SetRobotPos`` (the robot, or a part: in SimTwo's RobotAtFactory scenes the parts are robots ``Part1`` ..
``Part4``). docs/protocol.md ("Teleport labels") is the reference::

    TpId      integer > 0: the request; the script applies each TpId once (a repeat is ignored)
    TpTarget  the scene robot's ID (e.g. AGV, Part3); absent: the script's own robot
    TpX, TpY  metres, field frame: where SetRobotPos puts the robot's origin
    TpZ       metres (absent: 0)
    TpTh      radians: the heading

The bridge adds them to its next ``repeats`` replies (a lost datagram does not lose the teleport); a script
without this support, and raf sim, ignore labels they do not know, and a bridge without it never sends them.
No ROS here.
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass

from .errors import ProtocolError
from .labels import LabelledValues, encode_labels, format_int, format_real

TELEPORT_LABELS = ("TpId", "TpTarget", "TpX", "TpY", "TpZ", "TpTh")
DEFAULT_REPEATS = 5
# SimTwo's RobotAtFactory scenes (RobotFactoryPro2022): the parts are robots Part1..Part4 (scene.xml) standing at
# z = part_pos_z = 0.0021 m; their plate is on the part's -y side (PartBlue.xml 'Plate', y = -part_depth/2)
SIMTWO_PART_Z = 0.0021
SIMTWO_PART_PREFIX = "Part"
#: where a scene's parts that a round does not use stand (off the field, 0.2 m apart in x): raf simtwo run's
#: scene copy puts SimTwo's spare robots PartN there, and the stand-in reports its absent parts there
SPARE_PART_XY = (1.5, 1.2)


def spare_part_xy(k: int) -> tuple[float, float]:
    """Where the k-th spare part (0, 1, ...) stands."""
    return SPARE_PART_XY[0] + 0.2 * k, SPARE_PART_XY[1]


def part_heading(facing: float) -> float:
    """SimTwo's heading of a part (``SetRobotPos``, the scene's ``rot_deg z``) whose plate faces ``facing``
    (rad, a field slot's convention): the plate is on the part's -y side, so the plate's heading + pi/2."""
    return math.remainder(facing + math.pi / 2, 2 * math.pi)


def plate_facing(heading: float) -> float:
    """The inverse of :func:`part_heading`: the plate's heading of a part whose SimTwo heading is ``heading``."""
    return math.remainder(heading - math.pi / 2, 2 * math.pi)


@dataclass(frozen=True)
class Teleport:
    id: int
    x: float
    y: float
    theta: float
    z: float = 0.0
    target: str = ""  # "": the script's robot

    def labels(self) -> bytes:
        items = [("TpId", format_int(self.id))]
        if self.target:
            items.append(("TpTarget", self.target))
        items += [("TpX", format_real(self.x)), ("TpY", format_real(self.y)), ("TpZ", format_real(self.z)),
                  ("TpTh", format_real(self.theta))]
        return encode_labels(items)

    @classmethod
    def from_datagram(cls, data: bytes | str) -> "Teleport | None":
        """The teleport a Command datagram carries, None without TpId; ProtocolError when malformed."""
        v = LabelledValues(data)
        if "TpId" not in v:
            return None
        tid = v.get_int("TpId")
        if tid <= 0:
            raise ProtocolError(f"TpId {tid}: must be > 0")
        x, y, th = v.get_real("TpX"), v.get_real("TpY"), v.get_real("TpTh")
        z = v.get_real("TpZ") if "TpZ" in v else 0.0
        if not all(math.isfinite(a) for a in (x, y, z, th)):
            raise ProtocolError("teleport with a non-finite value")
        return cls(tid, x, y, th, z, v.raw("TpTarget").strip() if "TpTarget" in v else "")


class TeleportSender:
    """The teleport the bridge's next replies carry (one at a time; thread-safe).

    ``request`` queues one and returns it; ``labels()`` (called for each reply) returns its labels for
    ``repeats`` replies, then nothing; ``delivered(t)`` says whether ``t`` has been sent that often.
    """

    def __init__(self, repeats: int = DEFAULT_REPEATS):
        if repeats < 1:
            raise ValueError("repeats must be >= 1")
        self.repeats = repeats
        self._lock = threading.Lock()
        self._next_id = 1
        self._pending: Teleport | None = None
        self._bytes = b""
        self._left = 0
        self.sent = 0  # replies that carried a teleport

    def request(self, x: float, y: float, theta: float, z: float = 0.0, target: str = "") -> Teleport:
        if not all(math.isfinite(a) for a in (x, y, z, theta)):
            raise ValueError("teleport pose must be finite")
        if any(c in target for c in "\r\n"):
            raise ValueError("target must be one line")
        with self._lock:
            t = Teleport(self._next_id, float(x), float(y), float(theta), float(z), target)
            self._next_id += 1
            self._pending, self._bytes, self._left = t, t.labels(), self.repeats
            return t

    def labels(self) -> bytes:
        with self._lock:
            if self._left <= 0:
                return b""
            self._left -= 1
            self.sent += 1
            return self._bytes

    def delivered(self, t: Teleport) -> bool:
        with self._lock:
            return self._pending is not t or self._left <= 0
