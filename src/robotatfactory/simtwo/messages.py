"""The RobotAtFactory datagrams between SimTwo (or the stand-in simulator) and ROS, version 1.

See ``docs/protocol.md`` for the definition. Both messages are SimTwo labelled strings
(:mod:`.labels`); the first label ``RAF`` carries the protocol version.

* :class:`SensorFrame`, simulator -> ROS, once per control cycle.
* :class:`Command`, ROS -> simulator, exactly one reply per received frame.

Losing nothing: ``Enc1``/``Enc2`` are SimTwo's per-cycle deltas (``GetAxisOdo``) and
``Odo1``/``Odo2`` the script's running totals, so a receiver that differences totals loses no tick when
a datagram is lost; ``Seq`` counts cycles, so a gap, a duplicate or a reordering is detected.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .errors import ProtocolError
from .labels import LabelledValues, encode_labels, format_int, format_real

PROTOCOL_VERSION = 1
VERSION_LABEL = "RAF"
LIDAR_SEPARATOR = ";"
NO_RETURN = -1.0


def _check_version(v: LabelledValues, what: str) -> None:
    if VERSION_LABEL not in v:
        raise ProtocolError(f"not a RobotAtFactory {what}: the first label must be {VERSION_LABEL!r} "
                            f"(protocol version), got {v.lines[0][:40]!r}" if v.lines else
                            f"not a RobotAtFactory {what}: empty datagram")
    ver = v.get_int(VERSION_LABEL)
    if ver != PROTOCOL_VERSION:
        raise ProtocolError(f"{what} has protocol version {ver}; this side speaks version {PROTOCOL_VERSION}")


def encode_ranges(ranges: np.ndarray | list[float]) -> str:
    """LIDAR ranges to one value line: ``%.6g`` values separated by ';', -1 for no return."""
    out = []
    for r in ranges:
        r = float(r)
        if not math.isfinite(r) or r < 0:
            out.append("-1")
        else:
            out.append("%.6g" % r)
    return LIDAR_SEPARATOR.join(out)


def decode_ranges(s: str, label: str = "Lidar") -> np.ndarray:
    """One value line of ranges back to float64 metres (-1 kept for no return)."""
    s = s.strip()
    if not s:
        return np.empty(0)
    parts = s.split(LIDAR_SEPARATOR)
    try:
        arr = np.array(parts, dtype=np.float64)
    except ValueError:
        for i, p in enumerate(parts):
            try:
                float(p)
            except ValueError:
                raise ProtocolError(f"label {label!r}: ray {i} is {p[:20]!r}, expected a real number") from None
        raise
    if not np.isfinite(arr).all():
        i = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise ProtocolError(f"label {label!r}: ray {i} is {parts[i]!r}, not a finite number")
    bad = (arr < 0) & (arr != NO_RETURN)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ProtocolError(f"label {label!r}: ray {i} is {parts[i]!r}; a range is >= 0, or -1 for no return")
    return arr


def encode_parts(parts) -> str:
    """Part poses to one value line: ``x;y;theta`` of each part in turn, ``%.6g`` each."""
    return LIDAR_SEPARATOR.join("%.6g" % float(v) for pose in parts for v in pose)


def _decode_camera_frames(v: LabelledValues) -> int | None:
    """The optional ``CamN`` label (camera frames published before this frame): None when absent."""
    if "CamN" not in v:
        return None
    n = v.get_int("CamN")
    if n < 0:
        raise ProtocolError(f"label 'CamN' (line {v.line_of('CamN')}): {n} camera frames")
    return n


def _decode_parts(v: LabelledValues) -> tuple[tuple[float, float, float], ...]:
    """The optional ``PartsN``/``Parts`` labels: () when the frame has none."""
    if "PartsN" not in v:
        return ()
    n = v.get_int("PartsN")
    if n < 0:
        raise ProtocolError(f"label 'PartsN' (line {v.line_of('PartsN')}): {n} parts")
    if n == 0:
        return ()
    raw = v.raw("Parts").strip()
    vals = raw.split(LIDAR_SEPARATOR) if raw else []
    if len(vals) != 3 * n:
        raise ProtocolError(f"label 'Parts' (line {v.line_of('Parts')}): {len(vals)} values, but PartsN {n} "
                            f"needs {3 * n} (x;y;theta per part)")
    out = []
    for i, s in enumerate(vals):
        try:
            x = float(s)
        except ValueError:
            raise ProtocolError(f"label 'Parts': value {i} is {s[:20]!r}, expected a real number") from None
        if not math.isfinite(x):
            raise ProtocolError(f"label 'Parts': value {i} is {s!r}, not a finite number")
        out.append(x)
    return tuple((out[k], out[k + 1], out[k + 2]) for k in range(0, len(out), 3))


@dataclass
class SensorFrame:
    """What the simulator measured in one control cycle (simulator -> ROS)."""

    seq: int  # control cycle counter, +1 per cycle, from 0
    time_ms: int  # simulation time at the end of the cycle, integer milliseconds
    enc_delta: tuple[int, int]  # ticks since the previous cycle, (left axis 0, right axis 1)
    enc_total: tuple[int, int]  # ticks since the start, (left, right)
    x: float  # ground truth, map frame, metres
    y: float
    theta: float  # ground-truth heading, radians
    contact: bool  # micro switch pressed
    magnet: bool  # electromagnet state as applied
    ranges: np.ndarray = field(default_factory=lambda: np.empty(0))  # metres, -1 = no return
    #: ground truth of the scene's parts, (x, y, theta) of part 1..N (SimTwo: robots Part1..PartN; theta is the
    #: simulator's heading of the part body); optional labels ``PartsN``/``Parts``, empty when not sent
    parts: tuple[tuple[float, float, float], ...] = ()
    #: camera frames the simulator has published before this frame, since it started (optional label ``CamN``:
    #: ``raf sim --paced`` sends it, so the bridge's camera side knows which frames to wait for; None: not sent)
    camera_frames: int | None = None

    @property
    def time(self) -> float:
        return self.time_ms / 1000.0

    def encode(self) -> bytes:
        items = [
            (VERSION_LABEL, format_int(PROTOCOL_VERSION)),
            ("Seq", format_int(self.seq)),
            ("Tms", format_int(self.time_ms)),
            ("Enc1", format_int(self.enc_delta[0])),
            ("Enc2", format_int(self.enc_delta[1])),
            ("Odo1", format_int(self.enc_total[0])),
            ("Odo2", format_int(self.enc_total[1])),
            ("X", format_real(self.x)),
            ("Y", format_real(self.y)),
            ("Theta", format_real(self.theta)),
            ("Contact", format_int(int(self.contact))),
            ("Magnet", format_int(int(self.magnet))),
            ("LidarN", format_int(len(self.ranges))),
            ("Lidar", encode_ranges(self.ranges)),
        ]
        if self.parts:
            items += [("PartsN", format_int(len(self.parts))), ("Parts", encode_parts(self.parts))]
        if self.camera_frames is not None:
            items.append(("CamN", format_int(self.camera_frames)))
        return encode_labels(items)

    @classmethod
    def decode(cls, data: bytes | str) -> "SensorFrame":
        v = LabelledValues(data)
        _check_version(v, "sensor frame")
        seq = v.get_int("Seq")
        if seq < 0:
            raise ProtocolError(f"label 'Seq' (line {v.line_of('Seq')}): sequence number {seq} is negative")
        n = v.get_int("LidarN")
        ranges = decode_ranges(v.raw("Lidar"))
        if len(ranges) != n:
            raise ProtocolError(f"label 'Lidar' (line {v.line_of('Lidar')}): {len(ranges)} rays, but LidarN says {n}")
        return cls(
            seq=seq, time_ms=v.get_int("Tms"),
            enc_delta=(v.get_int("Enc1"), v.get_int("Enc2")),
            enc_total=(v.get_int("Odo1"), v.get_int("Odo2")),
            x=v.get_real("X"), y=v.get_real("Y"), theta=v.get_real("Theta"),
            contact=v.get_bool("Contact"), magnet=v.get_bool("Magnet"),
            ranges=ranges, parts=_decode_parts(v), camera_frames=_decode_camera_frames(v),
        )

    def __eq__(self, other):  # ndarray field: compare explicitly
        if not isinstance(other, SensorFrame):
            return NotImplemented
        return (self.seq, self.time_ms, self.enc_delta, self.enc_total, self.x, self.y, self.theta,
                self.contact, self.magnet) == (other.seq, other.time_ms, other.enc_delta, other.enc_total,
                                               other.x, other.y, other.theta, other.contact, other.magnet) \
            and np.array_equal(self.ranges, other.ranges) and tuple(self.parts) == tuple(other.parts) \
            and self.camera_frames == other.camera_frames


@dataclass(frozen=True)
class Command:
    """What ROS asks for (ROS -> simulator): body velocities and the electromagnet."""

    v: float  # linear speed, m/s (forward +)
    w: float  # angular speed, rad/s (counter-clockwise +)
    magnet: bool  # electromagnet on
    seq: int = -1  # Seq of the SensorFrame this answers (-1: unsolicited)

    def encode(self) -> bytes:
        return encode_labels([
            (VERSION_LABEL, format_int(PROTOCOL_VERSION)),
            ("Seq", format_int(self.seq)),
            ("V", format_real(self.v)),
            ("W", format_real(self.w)),
            ("S", format_int(int(self.magnet))),
        ])

    @classmethod
    def decode(cls, data: bytes | str) -> "Command":
        v = LabelledValues(data)
        _check_version(v, "command")
        return cls(v=v.get_real("V"), w=v.get_real("W"), magnet=v.get_bool("S"), seq=v.get_int("Seq"))

    @staticmethod
    def stop(seq: int = -1) -> "Command":
        return Command(0.0, 0.0, False, seq)


#: A lossy link's notice to a paced raf sim (not SimTwo's protocol): ``LINK_LOST`` + the Seq of a frame, or of
#: the reply to it, that the link lost or held back. A paced run waits for the reply to each frame; without the
#: notice a lost datagram would cost the whole reply timeout. The faults proxy sends it (``notify_lost``).
LINK_LOST = b"RAF-LINK-LOST "


def encode_link_lost(seq: int) -> bytes:
    """The notice that the frame ``seq``, or the reply to it, is lost on the link."""
    return LINK_LOST + str(int(seq)).encode()


def decode_link_lost(data: bytes) -> int | None:
    """The Seq a link-lost notice names; None if ``data`` is not one."""
    if not data.startswith(LINK_LOST):
        return None
    try:
        return int(data[len(LINK_LOST):])
    except ValueError:
        return None
