"""``raf experiment localization``'s pictures of the running graph, taken while the processes still run:
one ``aruco/debug_image`` frame (the paper's figure 6), the RViz configuration and an RViz screenshot under
Xvfb (the paper's figure 7; :func:`read_xwd` reads the X window dump) and the TF tree from tf2_tools
view_frames (the paper's figure 8). The screenshot and the TF tree are ROS 1's tools; on ROS 2 only the debug
image and the RViz configuration are made (:func:`pictures`)."""
from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ._localization_record import Graph


def pictures(args, graph: Graph, data: dict, out_dir: Path, log_dir: Path, notes: list) -> None:
    """The debug image, the TF tree and the RViz screenshot (ROS 1's tools), while the processes still run."""
    env = graph.env()
    save_debug_image(graph.exp, out_dir / "localization_debug_image.png", notes)
    cfg = out_dir / "localization.rviz"
    # look over the robot's shoulder at what its camera sees (the paper's figure 7)
    x, y, th = data["gt"][-1, 1:4] if len(data["gt"]) else (0.0, 0.0, 0.0)
    fx, fy = x + 0.25 * math.cos(th), y + 0.25 * math.sin(th)
    view = RVIZ.replace("X: 0.0\n        Y: -0.15", f"X: {fx:.3f}\n        Y: {fy:.3f}")
    view = view.replace("Yaw: 4.71", f"Yaw: {(th + math.pi) % (2 * math.pi):.3f}")
    cfg.write_text(view)
    if graph.middleware != "ros1":
        notes.append("TF tree and RViz screenshot: ROS 1's view_frames and rviz; not made on ROS 2 (no tf2_tools "
                     "or rviz2 wheels)")
        return
    if not args.no_tf_tree:
        why = tf_tree(env, out_dir, log_dir)
        if why:
            notes.append(f"TF tree: {why}")
    if not args.no_rviz:
        why = rviz_screenshot(env, cfg, out_dir / "localization_rviz.png", log_dir)
        if why:
            notes.append(f"RViz screenshot: {why}")


RVIZ = """Panels:
  - Class: rviz/Displays
    Name: Displays
Visualization Manager:
  Class: ""
  Displays:
    - Class: rviz/Grid
      Name: Grid
      Enabled: true
      Cell Size: 0.1
      Plane Cell Count: 20
      Reference Frame: map
      Color: 160; 160; 164
    - Class: rviz/MarkerArray
      Name: Field markers
      Enabled: true
      Marker Topic: /field/markers
    - Class: rviz/TF
      Name: TF
      Enabled: true
      Show Names: true
      Show Axes: true
      Show Arrows: true
      Marker Scale: 0.25
      Frame Timeout: 15
      Frames:
        All Enabled: true
    - Class: rviz/MarkerArray
      Name: Detected markers
      Enabled: true
      Marker Topic: /aruco/markers
    - Class: rviz/PoseWithCovariance
      Name: EKF pose
      Enabled: true
      Topic: /pose
      Shape: Arrow
      Color: 0; 120; 255
      Shaft Length: 0.12
      Shaft Radius: 0.01
      Head Length: 0.04
      Head Radius: 0.025
    - Class: rviz/PoseWithCovariance
      Name: Camera pose (closest marker)
      Enabled: true
      Topic: /camera_pose
      Shape: Axes
      Axes Length: 0.08
      Axes Radius: 0.006
    - Class: rviz/LaserScan
      Name: LIDAR
      Enabled: true
      Topic: /scan
      Size (m): 0.01
      Color Transformer: FlatColor
      Color: 255; 0; 0
    - Class: rviz/Image
      Name: Debug image
      Enabled: true
      Image Topic: /aruco/debug_image
  Enabled: true
  Global Options:
    Fixed Frame: map
    Background Color: 40; 40; 40
    Frame Rate: 15
  Views:
    Current:
      Class: rviz/Orbit
      Distance: 1.0
      Focal Point:
        X: 0.0
        Y: -0.15
        Z: 0.0
      Pitch: 0.6
      Yaw: 4.71
      Target Frame: map
Window Geometry:
  Width: 1600
  Height: 1000
  X: 0
  Y: 0
  Displays:
    collapsed: false
  Debug image:
    collapsed: false
"""


def save_debug_image(exp, path: Path, notes: list) -> None:
    """One aruco/debug_image frame (the paper's figure 6) as PNG."""
    from sensor_msgs.msg import Image

    from ..ros.mw import QoS

    try:
        msg = exp.wait_for_message("aruco/debug_image", Image, timeout=10.0, qos=QoS.SENSOR)
        if msg is None:
            raise TimeoutError("no aruco/debug_image in 10 s")
        import cv2

        img = np.frombuffer(msg.data, dtype=np.uint8).reshape(msg.height, msg.width, 3)
        cv2.imwrite(str(path), img)
    except Exception as ex:  # noqa: BLE001 - a figure, not the measurement
        notes.append(f"debug image: {type(ex).__name__}: {ex}")


def _free_display() -> int:
    for n in range(91, 200):
        if not os.path.exists(f"/tmp/.X{n}-lock") and not os.path.exists(f"/tmp/.X11-unix/X{n}"):
            return n
    raise RuntimeError("no free X display number")


def rviz_screenshot(env: dict, cfg: Path, png: Path, log_dir: Path, wait: float = 20.0, attempts: int = 3) -> str:
    """RViz under Xvfb, then xwd of the root window converted to PNG; RViz with software OpenGL sometimes
    aborts at start-up, so it gets a few attempts. Returns '' or what went wrong."""
    why = ""
    for _ in range(attempts):
        why = _rviz_once(env, cfg, png, log_dir, wait)
        if not why:
            return ""
    return f"{why} (after {attempts} attempts)"


def _rviz_once(env: dict, cfg: Path, png: Path, log_dir: Path, wait: float) -> str:
    from ..ros.master import stop_process

    for tool in ("Xvfb", "rviz", "xwd"):
        if shutil.which(tool) is None:
            return f"{tool} not installed"
    disp = _free_display()
    xlog = open(log_dir / "xvfb.log", "wb")
    xvfb = subprocess.Popen(["Xvfb", f":{disp}", "-screen", "0", "1600x1000x24", "-nolisten", "tcp"],
                            stdout=xlog, stderr=subprocess.STDOUT, start_new_session=True)
    rv = None
    try:
        time.sleep(1.5)
        e = dict(env, DISPLAY=f":{disp}", LIBGL_ALWAYS_SOFTWARE="1")
        rlog = open(log_dir / "rviz.log", "wb")
        rv = subprocess.Popen(["rviz", "-d", str(cfg)], env=e, stdout=rlog, stderr=subprocess.STDOUT,
                              start_new_session=True)
        time.sleep(wait)
        if rv.poll() is not None:
            return f"rviz exited with code {rv.returncode} (see rviz.log)"
        xwd = png.with_suffix(".xwd")
        subprocess.run(["xwd", "-root", "-silent", "-display", f":{disp}", "-out", str(xwd)], check=True,
                       timeout=30)
        img = read_xwd(xwd)
        import cv2

        cv2.imwrite(str(png), img)
        xwd.unlink()
        return ""
    except Exception as ex:  # noqa: BLE001 - a figure, not the measurement
        return f"{type(ex).__name__}: {ex}"
    finally:
        if rv is not None:
            stop_process(rv)
        stop_process(xvfb)


def read_xwd(path: Path) -> np.ndarray:
    """An X window dump (ZPixmap, 24/32 bits per pixel, as xwd writes from a 24-bit Xvfb) to BGR."""
    b = path.read_bytes()
    h = np.frombuffer(b[:100], dtype=">u4")
    header_size, fmt, depth, width, height = int(h[0]), int(h[2]), int(h[3]), int(h[4]), int(h[5])
    bpp, bpl, ncolors = int(h[11]), int(h[12]), int(h[19])
    byte_order = int(h[7])
    if fmt != 2 or bpp not in (24, 32):
        raise ValueError(f"unsupported xwd: format {fmt}, {bpp} bits per pixel, depth {depth}")
    off = header_size + ncolors * 12
    data = np.frombuffer(b[off:off + bpl * height], dtype=np.uint8).reshape(height, bpl)
    px = data[:, :width * bpp // 8].reshape(height, width, bpp // 8)
    if byte_order == 0:  # LSBFirst: B G R (X)
        return np.ascontiguousarray(px[:, :, :3])
    return np.ascontiguousarray(px[:, :, 1:4][:, :, ::-1] if bpp == 32 else px[:, :, ::-1])


def tf_tree(env: dict, out_dir: Path, log_dir: Path) -> str:
    script = "/usr/lib/tf2_tools/view_frames.py"
    if not os.path.exists(script):
        exe = shutil.which("view_frames")
        if exe is None:
            return "tf2_tools view_frames not found"
        cmd = [exe]
    else:
        cmd = [sys.executable, script]
    try:
        with open(log_dir / "view_frames.log", "wb") as log:
            subprocess.run(cmd, env=env, cwd=out_dir, stdout=log, stderr=subprocess.STDOUT, timeout=120, check=True)
        if shutil.which("dot") and (out_dir / "frames.gv").exists():
            subprocess.run(["dot", "-Tpng", "-Gdpi=70", "frames.gv", "-o", "frames.png"], cwd=out_dir, timeout=60,
                           check=True)
        return "" if (out_dir / "frames.pdf").exists() else "view_frames wrote no frames.pdf"
    except Exception as ex:  # noqa: BLE001
        return f"{type(ex).__name__}: {ex}"
