"""Bag files in one place: ROS 1 bags and rosbag2 recordings (MCAP or sqlite3), written and read with
``rosbags`` (pure Python; the same library on both middlewares, no ROS install needed to read a bag).

Reading (:func:`open_bag`): a ROS 1 ``.bag``, a rosbag2 directory (``metadata.yaml`` + storage files), or a
lone ``.mcap`` / ``.db3`` file. Messages come out as plain objects with the ROS field names of the bag's own
type definitions (``msg.header.stamp.sec`` / ``.nanosec`` in both formats: read stamps with
:func:`robotatfactory.ros.mw.base.stamp_ns`; ``Image.data`` is a numpy uint8 array)::

    with open_bag("run") as bag:
        print(bag.topics)                                  # {"/odom": TopicInfo("nav_msgs/msg/Odometry", 812)}
        for topic, stamp_ns, msg in bag.messages(["/odom"]):
            ...

Writing (:func:`open_writer`): the format follows the middleware: a rosbag2 (MCAP by default, ``version 9``
metadata as ROS 2 Jazzy writes it) with Jazzy's type definitions and RIHS01 type hashes (rosbags'
``Stores.ROS2_JAZZY``), or a ROS 1 bag with the message classes' own definitions and MD5 sums. Messages go
in serialized (:meth:`BagWriter.write_raw`, what ``raf record`` does) or as the middleware's message objects
(:meth:`BagWriter.write`). Type names are ROS 2's ``pkg/msg/Name`` everywhere here (ROS 1 bags store
``pkg/Name``; rosbags converts).
"""
from __future__ import annotations

import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from ..errors import ConfigError

FORMATS = ("mcap", "sqlite3", "bag")  # rosbag2 + MCAP, rosbag2 + sqlite3, ROS 1 bag


@dataclass(frozen=True)
class TopicInfo:
    msgtype: str  # pkg/msg/Name
    count: int


def normalize_type(name: str) -> str:
    """``nav_msgs/Odometry`` or ``nav_msgs/msg/Odometry`` -> ``nav_msgs/msg/Odometry``."""
    parts = name.strip("/").split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return "/".join(parts)


def msgtype_of(msg) -> str:
    """The ``pkg/msg/Name`` of a ROS 1 (``_type``) or ROS 2 (class module ``pkg.msg._name``) message object."""
    t = getattr(msg, "_type", None)
    if isinstance(t, str) and "/" in t:
        return normalize_type(t)
    cls = type(msg)
    pkg = cls.__module__.split(".")[0]
    return f"{pkg}/msg/{cls.__name__}"


def _typestore(ros: int):
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY if ros == 2 else Stores.ROS1_NOETIC)


# ---- reading ------------------------------------------------------------------------------------------

class BagReader:
    """An open bag of either format (:func:`open_bag`)."""

    def __init__(self, path: str | Path):
        from rosbags.highlevel import AnyReader, AnyReaderError

        self.path = Path(path)
        if not self.path.exists():
            raise ConfigError(f"bag {self.path}: no such file or rosbag2 directory")
        try:
            self._reader = AnyReader([self.path], default_typestore=_typestore(2 if self.path.suffix != ".bag" else 1))
            self._reader.open()
        except (AnyReaderError, FileNotFoundError, OSError, ValueError) as e:
            raise ConfigError(f"cannot read bag {self.path}: {e}") from None
        self.format = "rosbag2" if self._reader.is2 else "rosbag1"
        self._lock = threading.Lock()

    @property
    def topics(self) -> dict[str, TopicInfo]:
        out = {}
        for topic, info in self._reader.topics.items():
            out[topic] = TopicInfo(normalize_type(info.msgtype or "?"), int(info.msgcount))
        return out

    @property
    def start_ns(self) -> int:
        return int(self._reader.start_time)

    @property
    def end_ns(self) -> int:
        return int(self._reader.end_time)

    def messages(self, topics: list[str] | None = None, raw: bool = False) -> Iterator[tuple[str, int, object]]:
        """(topic, bag time ns, message) in time order; ``topics`` (exact names) limits them; ``raw``: the
        serialized bytes instead of the message. A message that does not deserialize is a ConfigError."""
        conns = [c for c in self._reader.connections if topics is None or c.topic in topics]
        for conn, t, data in self._reader.messages(connections=conns):
            if raw:
                yield conn.topic, int(t), bytes(data)
                continue
            try:
                msg = self._reader.deserialize(data, conn.msgtype)
            except Exception as e:  # noqa: BLE001 - rosbags raises several kinds for a corrupt message
                raise ConfigError(f"bag {self.path}: a message on {conn.topic} ({conn.msgtype}) does not read: "
                                  f"{e}") from None
            yield conn.topic, int(t), msg

    def close(self) -> None:
        self._reader.close()

    def __enter__(self) -> "BagReader":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_bag(path: str | Path) -> BagReader:
    """A ROS 1 ``.bag``, a rosbag2 directory, or a ``.mcap`` / ``.db3`` file, open for reading."""
    return BagReader(path)


def find_topic(topics: dict[str, TopicInfo], wanted: str) -> list[str]:
    """The bag's topics named ``wanted`` exactly, or ending in ``/wanted`` (``camera/image_raw`` finds
    ``/robot1/camera/image_raw``)."""
    w = wanted.strip("/")
    return [t for t in topics if t.strip("/") == w or t.strip("/").endswith("/" + w)]


# ---- writing ------------------------------------------------------------------------------------------

class BagWriter:
    """A new bag: ``fmt`` ``mcap`` / ``sqlite3`` (rosbag2 directory ``path``) or ``bag`` (ROS 1 file ``path``).

    Thread-safe: the recorder's callbacks write from several threads."""

    def __init__(self, path: str | Path, fmt: str, custom: dict[str, str] | None = None):
        """``custom``: rosbag2's ``custom_data`` entries of metadata.yaml (ignored in a ROS 1 bag)."""
        if fmt not in FORMATS:
            raise ConfigError(f"bag format {fmt!r}: use one of {', '.join(FORMATS)}")
        self.path = Path(path)
        self.fmt = fmt
        if self.path.exists():
            raise ConfigError(f"{self.path} exists already: give a new name (a bag is never overwritten)")
        self.ros = 1 if fmt == "bag" else 2
        self.typestore = _typestore(self.ros)
        if self.ros == 2:
            from rosbags.rosbag2 import StoragePlugin, Writer

            plugin = StoragePlugin.MCAP if fmt == "mcap" else StoragePlugin.SQLITE3
            self._w = Writer(self.path, version=Writer.VERSION_LATEST, storage_plugin=plugin)
            for k, v in (custom or {}).items():
                self._w.set_custom_data(str(k), str(v))
        else:
            from rosbags.rosbag1 import Writer

            self._w = Writer(self.path)
        self._w.open()
        self._conns: dict[str, object] = {}
        self.counts: dict[str, int] = {}
        self._lock = threading.Lock()
        self._closed = False

    def has_topic(self, topic: str) -> bool:
        return topic in self._conns

    def add_topic(self, topic: str, msgtype: str, *, msgdef: str | None = None, digest: str | None = None,
                  qos: list | None = None, latched: bool = False) -> None:
        """Declare a topic before its first message. ``msgdef``/``digest``: the definition and MD5 (ROS 1) or
        RIHS01 hash (ROS 2) when known (else rosbags' Jazzy / Noetic type store gives them); ``qos``: the
        publishers' offered QoS (rosbags ``Qos``; rosbag2 only: ``ros2 bag play`` republishes with it);
        ``latched`` (ROS 1 only)."""
        msgtype = normalize_type(msgtype)
        with self._lock:
            if topic in self._conns:
                return
            try:
                if self.ros == 2:
                    c = self._w.add_connection(topic, msgtype, typestore=self.typestore, msgdef=msgdef,
                                               rihs01=digest, offered_qos_profiles=list(qos or []))
                else:
                    c = self._w.add_connection(topic, msgtype, typestore=self.typestore if msgdef is None else None,
                                               msgdef=msgdef, md5sum=digest, latching=1 if latched else None)
            except KeyError:
                raise ConfigError(f"topic {topic}: type {msgtype} is not in rosbags' "
                                  f"{'Jazzy' if self.ros == 2 else 'Noetic'} type store") from None
            self._conns[topic] = c
            self.counts[topic] = 0

    def write_raw(self, topic: str, data: bytes, stamp_ns: int) -> None:
        """One serialized message (CDR on rosbag2, ROS 1 serialization in a ROS 1 bag) at ``stamp_ns``."""
        with self._lock:
            if self._closed:
                return
            self._w.write(self._conns[topic], int(stamp_ns), data)
            self.counts[topic] += 1

    def write(self, topic: str, msg, stamp_ns: int) -> None:
        """One message object of this process's middleware (rclpy's or rospy's class)."""
        if topic not in self._conns:
            if self.ros == 1:
                self.add_topic(topic, msgtype_of(msg), msgdef=msg._full_text, digest=msg._md5sum)
            else:
                self.add_topic(topic, msgtype_of(msg))
        self.write_raw(topic, serialize(msg, self.ros), stamp_ns)

    def close(self) -> None:
        with self._lock:
            if not self._closed:
                self._closed = True
                self._w.close()

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def serialize(msg, ros: int) -> bytes:
    """A middleware message object serialized as its middleware does (ROS 2: CDR, little endian): a message of
    ROS ``ros`` (1 or 2), by that middleware's :mod:`.mw` module (only its own interpreter has it)."""
    from .mw import module

    return module(f"ros{ros}").serialize(msg)


def default_format(middleware: str | None = None) -> str:
    """The bag format ``middleware`` (default: this process's) records (:func:`.mw.bag_format`)."""
    from .mw import bag_format

    return bag_format(middleware)


def open_writer(path: str | Path, fmt: str | None = None, custom: dict[str, str] | None = None) -> BagWriter:
    """A new bag for this process's middleware (rosbag2 + MCAP on ROS 2, a ROS 1 bag on ROS 1) unless ``fmt``
    says otherwise; a ``.bag`` path is always a ROS 1 bag."""
    if fmt is None:
        fmt = "bag" if str(path).endswith(".bag") else default_format()
    return BagWriter(path, fmt, custom)
