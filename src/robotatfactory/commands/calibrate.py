"""``raf calibrate``: the camera's intrinsics and mount from a recording (rosbag) or the live topics."""
from __future__ import annotations

import argparse

NAME = "calibrate"
HELP = "estimate the camera's fx, fy, cx, cy and mount (height, forward, pitch, roll) from the field's markers"
ORDER = 37
DESCRIPTION = """\
Estimate the camera calibration from frames of the robot moving on the field: every detected marker's
corners against the field map, one joint least-squares fit over all frames with the robot's poses unknown
(odometry, when recorded, ties consecutive poses). Writes a YAML file that `raf bridge --calibration FILE`
and `raf localize --calibration FILE` load. The data must contain wall markers (floor markers alone cannot
separate focal length, height and pitch, unless the principal point is held: --hold cx,cy on SimTwo) and
turns (for the forward offset); docs/calibration.md.

examples:
  raf calibrate --bag drive.bag --out calib.yaml
  raf --field simtwo2022 calibrate --bag drive.bag --image-topic /camera/image_raw --odom-topic /odom --out calib.yaml --json fit.json
  raf calibrate --live --duration 60 --out calib.yaml          # while the robot drives round the field
  raf --middleware ros2 calibrate --live --duration 60 --out calib.yaml   # the same on ROS 2
  raf --field simtwo2022 calibrate --bag drive.bag --hold cx,cy --aspect-sigma 0.0001 --out calib.yaml   # SimTwo
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..localization.calibration import CalibrationConfig

    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument("--bag", metavar="PATH", help="a recording with camera images (and odometry): a ROS 1 .bag, a "
                     "rosbag2 directory or a .mcap/.db3 file (raf record)")
    src.add_argument("--live", action="store_true", help="record the live topics (ROS 1: needs a ROS master; ROS 2: "
                     "raf --middleware ros2 calibrate --live, in the bridge's ROS_DOMAIN_ID)")
    parser.add_argument("--duration", type=float, default=60.0, metavar="S",
                        help="with --live: seconds to record (default 60)")
    parser.add_argument("--image-topic", default="camera/image_raw", help="sensor_msgs/Image topic (default camera/image_raw)")
    parser.add_argument("--odom-topic", default="odom",
                        help="nav_msgs/Odometry topic, the prior between frames ('' for none; default odom)")
    parser.add_argument("--out", required=True, metavar="FILE", help="calibration YAML to write")
    parser.add_argument("--json", metavar="FILE", help="also write the fit's results (flat JSON)")
    parser.add_argument("--robot", default="simtwo",
                        help="robot file whose camera is the starting point and prior (default simtwo)")
    parser.add_argument("--initial", metavar="FILE", help="start from this calibration YAML instead")
    parser.add_argument("--every", type=int, default=1, metavar="N", help="use every N-th image (default 1)")
    parser.add_argument("--max-frames", type=int, default=1500, metavar="N",
                        help="use at most N images (default 1500)")
    parser.add_argument("--fit-distortion", action="store_true", help="also estimate k1, k2 (SimTwo's camera has none)")
    parser.add_argument("--no-forward", action="store_true", help="hold the camera's forward offset")
    parser.add_argument("--hold", default="", metavar="P[,P...]",
                        help="camera parameters to hold at the robot file's (or --initial's) values, of "
                             "fx,fy,cx,cy,z,pitch_down_deg,roll_deg; on SimTwo: cx,cy (GLScene renders the principal "
                             "point at the image centre, and floor markers alone leave it degenerate with the pitch)")
    parser.add_argument("--aspect-sigma", type=float, default=CalibrationConfig.aspect_sigma, metavar="F",
                        help="prior on the pixels' aspect ratio fy/fx towards the initial camera's, relative 1 sigma "
                             f"(default {CalibrationConfig.aspect_sigma:g}: square pixels unless the data say "
                             "otherwise; 0: no prior; on SimTwo 0.0001: GLScene has one focal length)")
    parser.add_argument("--corner-refinement", default="apriltag", choices=("apriltag", "subpix", "contour", "none"),
                        help="ArUco corner refinement (default apriltag: 3-4x less corner scatter than subpix and no "
                             "shrinking of the markers on rendered frames; docs/calibration.md)")


def run(args) -> int:
    import json
    from dataclasses import replace
    from pathlib import Path

    from ..errors import ConfigError
    from ..field import load_field
    from ..localization.calibration import (DEFAULT_FREE, CalibrationConfig, calibrate, compare, load_calibration,
                                            write_calibration)
    from ..robot import load_robot

    if args.every < 1 or args.max_frames < 1:
        raise ConfigError("--every and --max-frames must be >= 1")
    hold = [p.strip() for p in args.hold.split(",") if p.strip()]
    bad = sorted(set(hold) - set(DEFAULT_FREE))
    if bad:
        raise ConfigError(f"--hold {','.join(bad)}: not a fitted camera parameter; of {','.join(DEFAULT_FREE)}")
    cfg = CalibrationConfig(free=tuple(p for p in DEFAULT_FREE if p not in hold), fit_distortion=args.fit_distortion,
                            fit_forward=not args.no_forward, aspect_sigma=args.aspect_sigma)
    cfg.check()
    fld = load_field(args.field)
    try:
        robot = load_robot(args.robot)
    except FileNotFoundError as e:
        raise ConfigError(f"--robot: {e}") from None
    if args.initial:
        robot = replace(robot, camera=load_calibration(args.initial).apply(robot.camera))
    odom_topic = args.odom_topic or None
    from ..localization.calibration import FrameData, interpolate_odometry
    from ..localization.detect import DetectorConfig, MarkerDetector

    det = MarkerDetector(DetectorConfig(dictionary=fld.dictionary, corner_refinement=args.corner_refinement))
    size = (robot.camera.height, robot.camera.width)
    kept: list[tuple[float, list]] = []
    wrong: dict[tuple[int, int], int] = {}

    def sink(stamp: float, img) -> None:  # detect as the images come: only the corners are kept
        if img.shape[:2] != size:
            wrong[img.shape[:2]] = wrong.get(img.shape[:2], 0) + 1
            return
        dets = [d for d in det.detect(img) if fld.has_marker(d.id)]
        if dets:
            kept.append((float(stamp), dets))

    if args.bag:
        if not Path(args.bag).exists():
            raise ConfigError(f"--bag {args.bag}: no such bag file or rosbag2 directory")
        from ..ros.calibration_source import read_bag

        n_images, odom = read_bag(args.bag, args.image_topic, odom_topic, sink, args.every, args.max_frames)
        source = f"bag {args.bag}"
    else:
        from ..ros.calibration_source import record_live

        n_images, odom = record_live(args.image_topic, odom_topic, args.duration, sink, args.every, args.max_frames)
        source = f"live topics, {args.duration:g} s"
    if wrong:
        sizes = ", ".join(f"{w}x{h} ({n})" for (h, w), n in sorted(wrong.items()))
        msg = f"images of another size than the camera of --robot ({size[1]}x{size[0]}): {sizes}"
        if sum(wrong.values()) == n_images:
            raise ConfigError(msg)
        print(f"raf calibrate: ignored {msg}", flush=True)
    kept.sort(key=lambda a: a[0])
    frames = [FrameData(s, d, o) for (s, d), o in zip(kept, interpolate_odometry(odom, [s for s, _ in kept]))]
    print(f"raf calibrate: {n_images} images from {source}, {len(frames)} with markers of field {fld.name}, "
          f"{len(odom)} odometry messages", flush=True)
    res = calibrate(frames, fld, robot, cfg)
    path = write_calibration(args.out, res)
    c = res.camera
    print(f"camera: fx {c.fx:.3f} +- {res.sigma.get('fx', 0):.3f}  fy {c.fy:.3f} +- {res.sigma.get('fy', 0):.3f}  "
          f"cx {c.cx:.3f} +- {res.sigma.get('cx', 0):.3f}  cy {c.cy:.3f} +- {res.sigma.get('cy', 0):.3f} px")
    print(f"mount: xyz {tuple(round(v, 4) for v in c.xyz)} m  pitch down {c.pitch_down_deg:.3f} "
          f"+- {res.sigma.get('pitch_down_deg', 0):.3f} deg  roll {c.roll_deg:.3f} +- {res.sigma.get('roll_deg', 0):.3f} deg")
    print(f"fit: residual {res.residual_px_rms:.3f} px RMS over {res.detections} markers in {res.frames} frames "
          f"({res.wall_detections} on walls), {res.rejected} rejected, {res.odometry_links} odometry links")
    for n in res.notes:
        print(f"note: {n}")
    print(f"wrote {path}")
    if args.json:
        flat = {"source": source, "images": n_images, **{f"{k}": v for k, v in res.summary().items()
                                                          if not isinstance(v, (dict, list))}}
        flat.update({f"{k}_px" if k in ("fx", "fy", "cx", "cy") else k: getattr(c, k)
                     for k in ("fx", "fy", "cx", "cy", "pitch_down_deg", "roll_deg")})
        flat.update({"camera_x_m": c.xyz[0], "camera_y_m": c.xyz[1], "camera_z_m": c.xyz[2]})
        flat.update({f"sigma_{k}": v for k, v in res.sigma.items()})
        flat.update({f"change_{k}": round(v, 4) for k, v in compare(c, robot.camera).items()})
        flat["degenerate"] = ",".join(res.degenerate) or "none"
        Path(args.json).write_text(json.dumps(flat, indent=1))
        print(f"wrote {args.json}")
    return 0
