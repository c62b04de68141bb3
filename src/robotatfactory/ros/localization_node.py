"""The localization node (thin wiring around :mod:`robotatfactory.localization`, on either middleware: :mod:`.mw`).

Subscribes (relative names): ``camera/image_raw`` + ``camera/camera_info`` (stamped by the bridge with the
estimated simulation time of the render), ``odom`` (nav_msgs/Odometry, ``base_link`` in ``odom``), ``scan``,
``electromagnet`` (std_msgs/Bool: the robot's own command to its magnet, the agent's; while it is on, the EKF
turns with the carrying process noise, :meth:`~robotatfactory.localization.ekf.Ekf.set_carrying`; a Bool has no
stamp, so a switch counts from the latest odometry the node has taken: the command acts on the wheels' cycles
after it).
Publishes: ``aruco/markers`` (visualization_msgs/MarkerArray: each detected marker in ``camera_optical``
with its ID), ``aruco/poses`` (geometry_msgs/PoseArray, the same poses), ``aruco/debug_image`` (only while
subscribed), ``camera_pose`` (PoseWithCovarianceStamped: ``camera_optical`` in ``map`` by the paper's
closest-marker method), ``aruco/fixes/<method>`` (base_link in map per method), ``pose`` (the EKF,
PoseWithCovarianceStamped, base_link in map), TF ``map -> odom`` (REP 105) and ``/diagnostics`` with the
rejection counts by reason. Every callback survives bad input: it is counted, logged (rate-limited) and
skipped.

QoS: images, camera_info and scans are sensor data (ROS 2: best effort, which also matches reliable
publishers); odometry and every output (the debug image too) are reliable. Each callback runs one message at a
time, as rospy's one thread per subscription does (ROS 2's executor would otherwise run two images at once).
"""
from __future__ import annotations

import math
import sys
import threading
import time
from collections import Counter
from dataclasses import replace

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import CameraInfo, Image, LaserScan
from std_msgs.msg import Bool
from visualization_msgs.msg import Marker, MarkerArray

from ..errors import ConfigError
from ..field import load_field
from ..localization import reasons
from ..localization.config import LocalizationConfig, from_dict, robot_for
from ..localization.ekf import SCAN, Ekf
from ..localization.geometry import inv, matrix_se2, se2_matrix
from ..localization.lidar import extract_beacons
from ..localization.pipeline import FrameLocalizer
from ..localization.scanmatch import ScanLocalizer
from ..settings import describer, tree
from . import messages as rm
from .cli import publish_every, spin_node
from .mw import QoS, api
from .mw.base import OK, WARN, Node


class LocalizationNode:
    """The localization on a middleware node (:mod:`.mw`): ``start()`` subscribes and publishes,
    ``stop()`` ends the diagnostics and ignores further messages."""

    def __init__(self, cfg: LocalizationConfig, node: Node):
        self.cfg = cfg
        self.node = node
        self.field = load_field(cfg.field)
        self.robot = robot_for(cfg)  # the calibration file's camera, if any
        nc = cfg.node
        self.loc = FrameLocalizer(self.field, self.robot, cfg.detector, cfg.pose, nc.methods())
        self.ekf = Ekf(replace(cfg.ekf, track_m=self.robot.odometry_track))  # the track: the robot file's
        self.beacon_xy = np.array(self.field.beacons, dtype=float).reshape(-1, 2)
        self.laser_xy = tuple(self.robot.lidar.xyz[:2])
        self.scan_matcher = ScanLocalizer(self.field, self.robot, cfg.scan_match) if cfg.scan_match.enabled else None
        self.lock = threading.RLock()
        self.counts: Counter = Counter()
        self._last_warn: dict[str, float] = {}
        self._odom: tuple[float, tuple[float, float, float]] | None = None
        self._magnet: bool | None = None  # the robot's last magnet command (None: none heard yet)
        self._carry_due = False  # a magnet command heard before any odometry: applied with the first
        self._last_fix_t: float | None = None
        self._last_fix_wall: float | None = None
        self._frame_ms: list[float] = []
        self._K_from_info = False
        self._running = False
        self.frames = {k: cfg.frame(k) for k in tree(cfg.frames)}  # prefixed
        self.pacer = None  # paced (pace.enabled): inputs held until their frame's cycle (_paced_cycle)
        self._inbox: dict = {}  # paced: input key -> [(stamp, order, n, handler, message)] received, not yet run
        self._taken: Counter = Counter()  # paced: messages of each input run so far

    # ------------------------------------------------------------------ wiring
    def start(self) -> "LocalizationNode":
        t, nc, node = self.cfg.topics, self.cfg.node, self.node
        R = QoS.RELIABLE
        self.pub_markers = node.publisher(t.markers, MarkerArray, R, 2)
        self.pub_poses = node.publisher(t.marker_poses, PoseArray, R, 2)
        # reliable: it then reaches reliable viewers (RViz's default) as well as best-effort ones
        self.pub_debug = node.publisher(t.debug_image, Image, R, 1)
        self.pub_camera_pose = node.publisher(t.camera_pose, PoseWithCovarianceStamped, R, 5)
        self.pub_fix = {m: node.publisher(f"{t.fixes}/{m}", PoseWithCovarianceStamped, R, 5)
                        for m in nc.methods()}
        # the filter's final verdict on each camera fix (once it leaves the filter's history): accepted / gated
        self.pub_verdict = {ok: node.publisher(f"{t.fixes}/filter_{'accepted' if ok else 'rejected'}",
                                               PoseWithCovarianceStamped, R, 50) for ok in (True, False)}
        self.pub_pose = node.publisher(t.pose, PoseWithCovarianceStamped, R, 10)
        self.pub_diag = node.publisher(t.diagnostics, DiagnosticArray, R, 5)
        self._running = True
        self.use_beacons = bool(nc.use_lidar and len(self.beacon_xy))
        scans = self.use_beacons or self.scan_matcher is not None
        paced = self.cfg.pace.enabled
        if paced:  # one cycle per paced frame (docs/pacing.md); every input counts: deeper queues
            from .pace import Pacer

            # the agent's magnet command of cycle k - 1 (sent after this node's cycle k - 1) before cycle k
            self.pacer = Pacer(node, "localization", {"bridge": ("odom",) + (("scan",) if scans else ()),
                                                      "camera": ("image", "camera_info")},
                               on_cycle=self._paced_cycle, timeout=self.cfg.pace.timeout,
                               behind={"agent": ("electromagnet",)})
        inbox = self._held if paced else (lambda key, order, fn: fn)
        sensor = QoS.RELIABLE if paced else QoS.SENSOR  # paced: every message counts (pace.py), also on ROS 2
        # odom: the bridge writes it reliably (QoS.SYNCHRONOUS); every message counts for the filter
        self.subs = [
            node.subscribe(t.odom, Odometry, inbox("odom", 3, self._guard(self.on_odom)), R, 50),
            node.subscribe(t.image, Image, inbox("image", 1, self._guard(self.on_image)), sensor,
                           4 if paced else 1, large=True),
            node.subscribe(t.camera_info, CameraInfo, inbox("camera_info", 0, self._guard(self.on_camera_info)),
                           sensor, 4 if paced else 1),
        ]
        # the agent's magnet command, reliable as the agent and the referee have it; taken at once (a Bool has no
        # stamp): a switch counts from the latest odometry taken, the cycle the agent decided it on (paced: held,
        # and taken first in the cycle that waits for it, from the previous cycle's odometry: the agent's cycle
        # runs beside this node's, so taken at once it would count from either, run by run)
        self.subs.append(node.subscribe(t.magnet, Bool, inbox("electromagnet", -1, self._guard(self.on_magnet)), R,
                                        10))
        if scans:
            self.subs.append(node.subscribe(t.scan, LaserScan, inbox("scan", 2, self._guard(self.on_scan)),
                                            sensor, 10 if paced else 5))
        self._diag_thread = threading.Thread(target=self._diag_loop, name="raf-localize-diag", daemon=True)
        self._diag_thread.start()
        node.info(f"localization: field {self.field.name}, camera fixes by '{nc.filter_method}', camera_pose "
                      f"by '{nc.camera_pose_method}', {len(self.beacon_xy)} LIDAR beacons "
                      f"{'used' if nc.use_lidar else 'ignored'}, scan matching "
                      f"{'on' if self.scan_matcher is not None else 'off'}; waiting for "
                      f"{'odometry' if nc.initial_pose == 'start' else 'a confident camera fix'}")
        return self

    def stop(self) -> None:
        self._running = False
        for s in getattr(self, "subs", []):
            self.node.close(s)

    def _guard(self, fn):
        """``fn`` as a callback: one message at a time, any exception counted and logged (rate-limited)."""
        one = threading.Lock()

        def run(msg):
            if not self._running:
                return
            with one:
                try:
                    fn(msg)
                except Exception as e:  # noqa: BLE001 - a callback must never take the node down
                    self.counts[f"callback_error:{fn.__name__}"] += 1
                    self._warn(fn.__name__, f"localization: {fn.__name__} failed on a message: {e!r}")
        return run

    def _held(self, key: str, order: int, fn):
        """Paced: a callback that holds the message for its frame's cycle (``order`` among one stamp's inputs:
        camera_info, image, scan, odom last: the odom publishes the pose; the magnet command, unstamped, before
        everything) and counts it."""
        def hold(msg):
            stamp = rm.stamp_to_s(msg.header.stamp) if hasattr(msg, "header") else -math.inf  # (a Bool: first)
            with self.lock:
                q = self._inbox.setdefault(key, [])
                q.append((stamp, order, len(q), fn, msg))
            self.pacer.got(key)
        return hold

    def _paced_cycle(self, t: float) -> None:
        """Paced: the frame stamped ``t``: of each input, the messages the paces count for it (later ones may be in
        already: the agent's cycle runs beside this one, and the next frame's may follow), in stamp order; then the
        pace."""
        need = self.pacer.book.required(t)
        with self.lock:
            todo = []
            for key, q in self._inbox.items():
                n = max(0, need.get(key, self._taken[key]) - self._taken[key])
                todo += q[:n]
                del q[:n]
                self._taken[key] += n
            todo.sort(key=lambda e: e[:3])
        for _stamp, _order, _n, fn, msg in todo:
            fn(msg)
        self.pacer.done(t)

    def _warn(self, key: str, text: str) -> None:
        now = time.monotonic()
        if now - self._last_warn.get(key, -1e9) >= self.cfg.node.log_period:
            self._last_warn[key] = now
            self.node.warn(text)

    # ------------------------------------------------------------------ callbacks
    def on_camera_info(self, msg: CameraInfo) -> None:
        if not self.cfg.node.use_camera_info or self.cfg.calibration:  # a calibration file takes precedence
            return
        D_msg, K_msg, _, _ = rm.camera_matrices(msg)
        K = np.array(K_msg, dtype=float).reshape(3, 3)
        D = np.zeros(5)
        if D_msg:
            D[:min(5, len(D_msg))] = np.asarray(D_msg, dtype=float)[:5]
        D_now = self.loc.D if self.loc.D is not None else np.zeros(5)
        if np.allclose(K, self.loc.K) and np.allclose(D, D_now):
            self._K_from_info = True
            return
        try:
            with self.lock:
                self.loc.set_intrinsics(K, D)
            self._K_from_info = True
            self.node.info(f"localization: camera matrix from camera_info: fx {K[0, 0]:.2f} fy {K[1, 1]:.2f} "
                          f"cx {K[0, 2]:.2f} cy {K[1, 2]:.2f}, distortion {np.round(D, 5).tolist()}")
        except ConfigError as e:
            self.counts["bad_camera_info"] += 1
            self._warn("camera_info", f"localization: ignoring camera_info: {e}")

    def on_magnet(self, msg: Bool) -> None:
        """The robot's magnet command: carrying a part (or no longer) from the latest odometry's stamp on."""
        on = bool(msg.data)
        with self.lock:
            self.counts["magnet_commands"] += 1
            if on != self._magnet:
                self._magnet = on
                self.counts["carry_switches"] += 1
                if self._odom is None:
                    self._carry_due = True
                else:
                    self.ekf.set_carrying(self._odom[0], on)

    def on_odom(self, msg: Odometry) -> None:
        t = rm.stamp_to_s(msg.header.stamp)
        p = msg.pose.pose
        pose = (p.position.x, p.position.y, rm.quaternion_yaw(p.orientation))
        if not all(math.isfinite(v) for v in (t,) + pose):
            self.counts["bad_odom"] += 1
            return
        with self.lock:
            if self._odom is not None and t < self._odom[0] - 1.0:  # the simulation restarted
                self.node.warn("localization: odometry went back in time: restarting the filter")
                self.ekf = Ekf(self.ekf.cfg)
                if self.scan_matcher is not None:
                    self.scan_matcher.reset()
                self.counts["restarts"] += 1
                self._odom = None  # (else every later message looks older still and restarts it again)
                self._carry_due = self._magnet is not None  # the new filter learns what the magnet does
            if self._odom is not None and t <= self._odom[0]:
                self.counts["odom_not_newer"] += 1
                return
            if not self.ekf.initialised and self.cfg.node.initial_pose == "start" and self.ekf.t == -math.inf:
                sp = self.field.start_pose
                s = self.cfg.node
                self.ekf.initialise(t, (sp.x, sp.y, sp.theta), np.diag(
                    [s.initial_sigma_xy ** 2, s.initial_sigma_xy ** 2, math.radians(s.initial_sigma_theta_deg) ** 2]))
            if self._carry_due:
                self.ekf.set_carrying(t, bool(self._magnet))
                self._carry_due = False
            self.ekf.odometry_pose(t, pose)
            if self.scan_matcher is not None:
                self.scan_matcher.add_odom(t, pose)
                self._match_scan()
            finished = self.ekf.pop_finished_fixes()
            self._odom = (t, pose)
            self.counts["odom"] += 1
            self._publish_filter(t, pose)
        for f in finished:  # (messages nobody subscribes to are not built: lazy, as image_transport does)
            if f.source == "camera" and self.pub_verdict[f.accepted].subscriber_count() > 0:
                self.pub_verdict[f.accepted].publish(self._verdict_msg(f))

    def _verdict_msg(self, f) -> PoseWithCovarianceStamped:
        m = PoseWithCovarianceStamped()
        m.header.stamp = rm.stamp_s(f.t)
        m.header.frame_id = self.frames["map"]
        m.pose.pose = rm.planar_pose(*f.z)
        m.pose.covariance = rm.pose_cov6(f.R)
        return m

    def _publish_filter(self, t: float, odom_pose) -> None:
        x, P = self.ekf.pose(), self.ekf.covariance()
        if x is None:
            return
        stamp = rm.stamp_s(t)
        m = PoseWithCovarianceStamped()
        m.header.stamp = stamp
        m.header.frame_id = self.frames["map"]
        m.pose.pose = rm.planar_pose(*x)
        m.pose.covariance = rm.pose_cov6(P)
        self.pub_pose.publish(m)
        if self.pacer is not None:
            self.pacer.sent("pose")
        if self.cfg.node.publish_tf:
            map_odom = matrix_se2(se2_matrix(*x) @ inv(se2_matrix(*odom_pose)))  # map <- odom (REP 105)
            self.node.send_tf([rm.planar_transform(self.frames["map"], self.frames["odom"], *map_odom,
                                                   rm.stamp_s(t + self.cfg.node.tf_future_s))])

    def on_image(self, msg: Image) -> None:
        t = rm.stamp_to_s(msg.header.stamp)
        try:
            img = rm.image_to_bgr(msg)
        except ValueError as e:
            self.counts["bad_image"] += 1
            self._warn("image", f"localization: ignoring an image: {e}")
            return
        nc = self.cfg.node
        with self.lock:
            prior = self.ekf.pose() if nc.use_prior else None
        t0 = time.perf_counter()
        res = self.loc.process(img, prior=prior, stamp=t)
        self._frame_ms.append((time.perf_counter() - t0) * 1e3)
        self._frame_ms = self._frame_ms[-200:]
        self.counts["frames"] += 1
        header_cam = msg.header.frame_id or self.frames["camera_optical"]
        if self.pub_markers.subscriber_count() > 0 or self.pub_poses.subscriber_count() > 0:
            self._publish_markers(res, msg.header.stamp, header_cam)
        for name, e in res.estimates.items():
            if e.ok and name in self.pub_fix and self.pub_fix[name].subscriber_count() > 0:
                self.pub_fix[name].publish(self._fix_msg(e, msg.header.stamp))
        cp = res.estimates.get(nc.camera_pose_method)
        if cp is not None and cp.ok and cp.cov6 is not None and self.pub_camera_pose.subscriber_count() > 0:
            m = PoseWithCovarianceStamped()
            m.header.stamp = msg.header.stamp
            m.header.frame_id = self.frames["map"]
            m.pose.pose = rm.pose_from_matrix(cp.T_world_cam)
            m.pose.covariance = np.asarray(cp.cov6, dtype=float).ravel().tolist()
            self.pub_camera_pose.publish(m)
        fix = res.estimates.get(nc.filter_method)
        if fix is not None and fix.ok:
            self.counts["fixes"] += 1
            with self.lock:
                r = self.ekf.pose_fix(t, fix.base, fix.cov)
            if r.accepted or r.reason == "pending":
                self._last_fix_t, self._last_fix_wall = t, time.monotonic()
            elif r.reason == reasons.TOO_OLD:
                self._warn("too_old", f"localization: a camera frame stamped {t:.3f} s is older than the filter's "
                                      f"history ({self.ekf.cfg.history_s} s): dropped")
        if nc.debug_image and self.pub_debug.subscriber_count() > 0:
            from ..localization.draw import draw_debug

            with self.lock:
                fp = self.ekf.pose()
            out = draw_debug(img if img.ndim == 3 else img, res, self.loc.K, nc.debug_axis_m, fp, nc.filter_method)
            self.pub_debug.publish(rm.image_bgr8(msg.header.stamp, msg.header.frame_id, out.tobytes(),
                                                 out.shape[1], out.shape[0]))

    def _fix_msg(self, e, stamp) -> PoseWithCovarianceStamped:
        m = PoseWithCovarianceStamped()
        m.header.stamp = stamp
        m.header.frame_id = self.frames["map"]
        m.pose.pose = rm.planar_pose(*e.base)
        m.pose.covariance = rm.pose_cov6(e.cov)
        return m

    def _publish_markers(self, res, stamp, frame: str) -> None:
        arr = MarkerArray()
        clear = Marker()
        clear.action = Marker.DELETEALL
        arr.markers.append(clear)
        pa = PoseArray()
        pa.header.stamp, pa.header.frame_id = stamp, frame
        used = set()
        lifetime = api().duration_msg(0.5)
        fix = res.estimates.get(self.cfg.node.filter_method)
        if fix is not None and fix.ok:
            used = set(fix.marker_ids)
        for o in res.observations:
            T = o.solutions[o.checked if o.checked is not None else 0]
            p = rm.pose_from_matrix(T)
            pa.poses.append(p)
            for kind in ("cube", "text"):
                m = Marker()
                m.header.stamp, m.header.frame_id = stamp, frame
                m.ns = f"aruco_{kind}"
                m.id = int(o.id)
                m.pose = p
                m.lifetime = lifetime
                if kind == "cube":
                    m.type = Marker.CUBE
                    m.scale.x = m.scale.y = float(o.marker.size)
                    m.scale.z = 0.002
                    ok = o.id in used
                    m.color.r, m.color.g, m.color.b, m.color.a = (0.1, 0.9, 0.1, 0.8) if ok else (0.9, 0.6, 0.1, 0.8)
                else:
                    m.type = Marker.TEXT_VIEW_FACING
                    m.text = str(o.id)
                    m.scale.z = 0.03
                    m.color.r = m.color.g = m.color.b = m.color.a = 1.0
                arr.markers.append(m)
        self.pub_markers.publish(arr)
        self.pub_poses.publish(pa)

    def on_scan(self, msg: LaserScan) -> None:
        n = len(msg.ranges)
        if n < 3 or not (math.isfinite(msg.angle_increment) and msg.angle_increment != 0):
            self.counts["bad_scan"] += 1
            return
        with self.lock:
            if not self.ekf.initialised:
                return
        angles = msg.angle_min + msg.angle_increment * np.arange(n)
        ranges = np.asarray(msg.ranges, dtype=float)
        range_max = msg.range_max if msg.range_max > 0 else np.inf
        self.counts["scans"] += 1
        t0 = rm.stamp_to_s(msg.header.stamp)
        dt = msg.time_increment if math.isfinite(msg.time_increment) and msg.time_increment > 0 else 0.0
        if self.scan_matcher is not None:
            with self.lock:
                rejected = self.scan_matcher.add_scan(ranges, angles, t0, dt, msg.range_min, range_max)
                if rejected is not None:
                    self.counts[f"scan_unmatched_{rejected.reason}"] += 1
                self._match_scan()
        if not self.use_beacons:
            return
        obs = extract_beacons(ranges, angles, self.cfg.beacons, range_min=msg.range_min, range_max=range_max)
        for o in obs:
            with self.lock:
                r = self.ekf.beacons(t0 + o.index * dt, [o.as_tuple()], self.beacon_xy, self.laser_xy)
            self.counts["beacons_seen"] += 1
            if r.accepted:
                self.counts["beacons_used"] += 1

    def _match_scan(self) -> None:
        """The waiting scan's fix, once odometry covers it (called with the lock held)."""
        fix = self.scan_matcher.fix_pending(self.ekf.t, self.ekf.pose())
        if fix is None:
            return
        if fix.ok:
            r = self.ekf.pose_fix(fix.t, fix.pose, fix.cov, source=SCAN)
            self.counts["scan_fixes"] += 1
            if fix.every_ray:
                self.counts["scan_fixes_every_ray"] += 1
            if not r.accepted and r.reason not in ("pending",):
                self.counts[f"scan_fix_{r.reason}"] += 1
        else:
            self.counts[f"scan_unmatched_{fix.reason}"] += 1

    # ------------------------------------------------------------------ diagnostics
    def _diag_loop(self) -> None:
        publish_every(self.cfg.node.diagnostics_period, lambda: self._running and self.node.ok(),
                      self.pub_diag, self.diagnostics, errors=(Exception,),
                      on_error=lambda e: self._warn("diag", f"localization: diagnostics failed: {e!r}"))

    def diagnostics(self) -> DiagnosticArray:
        name = self.node.name
        arr = DiagnosticArray()
        arr.header.stamp = self.node.now()

        with self.lock:
            c = dict(self.counts)
            lc = dict(self.loc.counts)
            ec = dict(self.ekf.counts)
            x, P = self.ekf.pose(), self.ekf.covariance()
            carrying = self.ekf.carrying
        age = None if self._last_fix_wall is None else time.monotonic() - self._last_fix_wall
        frames = c.get("frames", 0)
        if frames == 0:
            level, text = WARN, "no camera image yet"
        elif age is None or age > 5.0:
            level, text = WARN, "no usable camera fix for a while (no markers in view?)"
        else:
            level, text = OK, "camera fixes coming in"
        vals = {"frames": frames, "fixes": c.get("fixes", 0), "frame_ms_median":
                float(np.median(self._frame_ms)) if self._frame_ms else -1.0,
                "camera_matrix_from_camera_info": self._K_from_info,
                "last_fix_age_wall_s": -1.0 if age is None else age, "bad_images": c.get("bad_image", 0)}
        vals.update({f"rejected_{k}": v for k, v in lc.items()})
        st1 = rm.diagnostic_status(f"{name}: camera", level, text, "aruco", dict(sorted(vals.items())), ".4g")
        if x is None:
            level, text = WARN, "not initialised: waiting for a confident camera fix"
            vals = {}
        else:
            sx = math.sqrt(max(P[0, 0], P[1, 1]))
            level = OK if sx < 0.05 else WARN
            text = f"x {x[0]:+.3f} y {x[1]:+.3f} heading {math.degrees(x[2]):+.1f} deg, sigma {sx * 1000:.1f} mm"
            vals = {"x": x[0], "y": x[1], "theta_deg": math.degrees(x[2]), "sigma_xy_m": sx,
                    "sigma_theta_deg": math.degrees(math.sqrt(P[2, 2]))}
        vals.update({f"filter_{k}": v for k, v in ec.items()})
        vals.update({"odom_messages": c.get("odom", 0), "scans": c.get("scans", 0),
                     "beacons_seen": c.get("beacons_seen", 0), "beacons_used": c.get("beacons_used", 0),
                     "scan_fixes": c.get("scan_fixes", 0), "scan_fixes_every_ray": c.get("scan_fixes_every_ray", 0),
                     "restarts": c.get("restarts", 0), "carrying": carrying,
                     "magnet_commands": c.get("magnet_commands", 0), "carry_switches": c.get("carry_switches", 0)})
        vals.update({k: v for k, v in c.items()
                     if k.startswith(("callback_error", "bad_", "scan_unmatched_", "scan_fix_"))})
        st2 = rm.diagnostic_status(f"{name}: filter", level, text, "ekf", dict(sorted(vals.items())), ".4g")
        arr.status = [st1, st2]
        return arr


def default_params() -> dict:
    """The node's parameters with their defaults (what ROS 2 declares): every localization setting
    (:class:`~..localization.config.LocalizationConfig`'s tree), but ``detector.extra``, whose OpenCV names are
    declared only when given (``--set detector.extra.minDistanceToBorder=2``)."""
    params = tree(LocalizationConfig())
    params["detector"].pop("extra")
    return params


_describe = describer(LocalizationConfig)


def describe_param(name: str) -> tuple[str, tuple[float, float] | None]:
    """(description, (min, max) or None) of a parameter (``ekf.history_s``): its setting's."""
    if name.startswith("detector.extra."):
        return f"cv2.aruco.DetectorParameters.{name.rsplit('.', 1)[1]} (detector.extra)", None
    return _describe(name)


def node_params(node: Node, settings: dict | None = None) -> dict:
    """The node's parameters as a settings tree: ``default_params()`` (updated with ``settings``: options
    given on the command line that the defaults lack, ``detector.extra``'s names, are declared too)."""
    return node.params(default_params(), describe_param, settings)


def main(argv: list[str] | None = None) -> int:
    return spin_node("raf_localization", lambda node: LocalizationNode(from_dict(node_params(node)), node).start(),
                     argv)


if __name__ == "__main__":
    sys.exit(main())
