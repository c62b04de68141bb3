"""``raf record``: record a run into a bag: a rosbag2 (MCAP, or sqlite3) on ROS 2, a ROS 1 bag on ROS 1."""
from __future__ import annotations

import argparse

NAME = "record"
HELP = "record topics into a bag: rosbag2 (MCAP/sqlite3, readable by ROS 2 Jazzy) on ROS 2, a .bag on ROS 1"
ORDER = 38
DESCRIPTION = """\
Record the run's topics as they come off the wire into a bag, with the rosbags library (no rosbag2 or rosbag
install needed): on ROS 2 (raf --middleware ros2 record) a rosbag2 directory with MCAP storage (or
--format sqlite3), Jazzy's type definitions and type hashes, the publishers' QoS; on ROS 1 a .bag with the
publishers' own definitions. Topics are subscribed to as they appear (start it before or after the rest).
Bag time is the ROS clock (simulation time from the bridge's /clock; --no-sim-time: wall time); on
simulation time the recording starts at the first /clock, as rosbag record's does. Stops on Ctrl-C or after
--duration seconds of recording, then prints what it wrote. Read a bag back with
robotatfactory.ros.bags.open_bag, `raf calibrate --bag`, or ros2 bag / rosbag on a real install.

default topics: {topics}

examples:
  raf --middleware ros2 record -o run1                 # rosbag2 (MCAP) directory run1/
  raf record --roscore -o run1.bag --duration 60       # ROS 1
  raf --middleware ros2 record -o drive --topics camera/image_raw camera/camera_info odom /tf /tf_static
  raf --middleware ros2 record -o small --no-images --format sqlite3
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..ros.recorder import DEFAULT_TOPICS

    parser.description = DESCRIPTION.format(topics=" ".join(DEFAULT_TOPICS))
    parser.add_argument("-o", "--output", metavar="PATH",
                        help="the bag: a new directory (rosbag2) or FILE.bag (ROS 1); default raf_YYYYmmdd_HHMMSS")
    parser.add_argument("--format", choices=("mcap", "sqlite3", "bag"),
                        help="mcap or sqlite3 (ROS 2, default mcap), bag (ROS 1, its only format)")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC",
                        help="record these topics instead of the default set (relative names: in --ns)")
    parser.add_argument("--no-images", action="store_true", help="leave out the camera images (the bulk of a bag)")
    parser.add_argument("--duration", type=float, metavar="S",
                        help="stop after S seconds of wall time, counted from the recording's start")
    parser.add_argument("--ns", metavar="NS", default="", help="namespace the relative topic names resolve in")
    parser.add_argument("--name", default="raf_record", help="node name (default raf_record)")
    parser.add_argument("--no-sim-time", action="store_true", help="bag time from the wall clock, not /clock")
    parser.add_argument("--roscore", action="store_true", help="ROS 1: start a private roscore on a free port")


def run(args) -> int:
    ns = argparse.Namespace(ns=args.ns, name=args.name, no_sim_time=args.no_sim_time, roscore=args.roscore)
    return plan(args).run(ns)  # (which closes the bag, if the node never started or stopped)


def plan(args):
    """The node this command line makes (:class:`~robotatfactory.ros.cli.NodePlan`), not yet started: its bag
    is opened when the node starts; it closes it and prints what it wrote when it stops (``raf compose``: the
    robot's nodes' topics reach it in-process)."""
    import threading
    import time

    from ..errors import ConfigError
    from ..ros import mw
    from ..ros.cli import NodePlan
    from ..ros.recorder import DEFAULT_TOPICS, IMAGE_TOPICS

    middleware = mw.name()
    own = mw.bag_format(middleware)  # a middleware records its own generation's bags only
    fmt = args.format or own
    if own == "bag" and fmt != "bag":
        raise ConfigError(f"--format {fmt}: ROS 1 records a ROS 1 bag (--format bag); rosbag2 is ROS 2's "
                          "(raf --middleware ros2 record)")
    if own != "bag" and fmt == "bag":
        raise ConfigError("--format bag: ROS 2 records a rosbag2 (mcap or sqlite3); a ROS 1 bag is raf record on ROS 1")
    if args.duration is not None and not args.duration > 0:
        raise ConfigError(f"--duration must be > 0 s, got {args.duration}")
    out = args.output or time.strftime("raf_%Y%m%d_%H%M%S") + (".bag" if fmt == "bag" else "")
    topics = list(args.topics or DEFAULT_TOPICS)
    if args.no_images:
        topics = [t for t in topics if t.strip("/") not in IMAGE_TOPICS]
    if not topics:
        raise ConfigError("no topics to record")

    from ..ros.bags import BagWriter

    opened: list = []  # the bag, once the node starts

    class Recording:
        """The recorder, and what it wrote printed once it stops."""

        def __init__(self, rec):
            self.rec = rec

        def stop(self) -> None:
            self.rec.stop()  # (closes the bag)
            counts = opened[0].counts
            print(f"raf record: wrote {sum(counts.values())} messages on {len(counts)} topics to {out}", flush=True)
            for topic in sorted(counts):
                print(f"  {topic:<28} {counts[topic]}", flush=True)
            missing = [t for t in self.rec.topics if t not in counts]
            if missing:
                print(f"  not published during the recording: {' '.join(missing)}", flush=True)

    def make_node(node):
        from ..ros.recorder import Recorder

        writer = BagWriter(out, fmt, custom={"recorded_by": "raf record (robotatfactory)", "middleware": middleware})
        opened.append(writer)
        rec = Recorder(node, writer, topics, wall_time=args.no_sim_time).start()
        if args.duration is not None:
            def stop_later():
                while node.ok() and not rec.recording.wait(0.05):
                    pass
                end = time.monotonic() + args.duration
                while node.ok() and time.monotonic() < end:
                    time.sleep(0.05)
                node.shutdown("--duration reached")
            threading.Thread(target=stop_later, name="raf-record-duration", daemon=True).start()
        return Recording(rec)

    def started(r) -> str:
        return (f"recording {len(r.rec.topics)} topics into {out} ({fmt}); "
                + (f"{args.duration:g} s" if args.duration else "Ctrl-C stops"))

    def close() -> None:
        for w in opened:
            w.close()

    return NodePlan("record", args.name, {}, make_node, started, close=close)
