"""ROS messages built from the bridge's pure objects. Stamps are simulation time (``Tms``), never wall time.

Written once for both middlewares (:mod:`.mw`): the message classes have the same Python names in ROS 1 and
ROS 2; what differs (the time type, CameraInfo's ``K``/``k`` spelling, DiagnosticStatus's byte level,
positional constructors, which ROS 2 lacks) is handled here, so node files never see it."""
from __future__ import annotations

import math

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, Pose, PoseArray, Quaternion, Transform, TransformStamped, Vector3
from nav_msgs.msg import Odometry
from sensor_msgs.msg import CameraInfo, Image, JointState, LaserScan

COV_FLOOR = 1e-9  # variances never exactly zero (filters invert covariances)
PLANAR_VAR = 1e-6  # z, roll, pitch of a robot on a flat floor: known, tiny


from .mw import api
from .mw.base import level_int, stamp_ns, stamp_s as stamp_to_s  # noqa: F401  (re-exported)

_time_msg = None


def stamp_from_ns(ns: int):
    """Nanoseconds to the middleware's time message (rospy.Time / builtin_interfaces/Time)."""
    global _time_msg
    if _time_msg is None:
        _time_msg = api().time_msg
    return _time_msg(ns)


def stamp_ms(ms: int):
    """Integer milliseconds of simulation time to a stamp (exact)."""
    return stamp_from_ns(int(ms) * 1_000_000)


def stamp_s(t: float):
    return stamp_from_ns(int(round(t * 1e9)))


def zero_stamp():
    return stamp_from_ns(0)


def yaw_quaternion(theta: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(theta / 2), w=math.cos(theta / 2))


def quaternion_yaw(q: Quaternion) -> float:
    """Heading (rad) of a geometry_msgs/Quaternion: the yaw of the rotated x axis."""
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def matrix_quaternion(R: np.ndarray) -> Quaternion:
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(np.asarray(R)[:3, :3]).as_quat()
    return Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))


def transform(parent: str, child: str, T: np.ndarray, stamp=None) -> TransformStamped:
    """A TransformStamped parent <- child from a 4x4 homogeneous matrix."""
    m = TransformStamped()
    m.header.stamp = stamp if stamp is not None else zero_stamp()
    m.header.frame_id = parent
    m.child_frame_id = child
    x, y, z = (float(v) for v in T[:3, 3])
    m.transform = Transform(translation=Vector3(x=x, y=y, z=z), rotation=matrix_quaternion(T[:3, :3]))
    return m


def planar_poses(stamp, frame: str, poses) -> PoseArray:
    """A PoseArray of planar poses ``(x, y, theta)`` on the floor (z 0)."""
    m = PoseArray()
    m.header.stamp = stamp
    m.header.frame_id = frame
    m.poses = [Pose(position=Point(x=float(x), y=float(y), z=0.0), orientation=yaw_quaternion(float(th)))
               for x, y, th in poses]
    return m


def planar_transform(parent: str, child: str, x: float, y: float, theta: float, stamp,
                     z: float = 0.0) -> TransformStamped:
    m = TransformStamped()
    m.header.stamp = stamp
    m.header.frame_id = parent
    m.child_frame_id = child
    m.transform.translation = Vector3(x=float(x), y=float(y), z=float(z))
    m.transform.rotation = yaw_quaternion(theta)
    return m


def wheel_transform(parent: str, child: str, y: float, radius: float, angle: float, stamp) -> TransformStamped:
    """base_link -> wheel: at (0, y, radius), turned by ``angle`` about the axle (the wheel's +y)."""
    m = TransformStamped()
    m.header.stamp = stamp
    m.header.frame_id = parent
    m.child_frame_id = child
    m.transform.translation = Vector3(x=0.0, y=float(y), z=float(radius))
    m.transform.rotation = Quaternion(x=0.0, y=math.sin(angle / 2), z=0.0, w=math.cos(angle / 2))
    return m


def pose_cov6(cov3: np.ndarray, floor: float = COV_FLOOR) -> list[float]:
    """3x3 (x, y, yaw) to ROS's row-major 6x6 (x, y, z, roll, pitch, yaw); z, roll, pitch known (flat floor)."""
    c = [0.0] * 36
    ix = (0, 1, 5)
    for a in range(3):
        for b in range(3):
            c[ix[a] * 6 + ix[b]] = float(cov3[a, b])
    for i in ix:
        c[i * 7] = max(c[i * 7], floor)
    for i in (2, 3, 4):
        c[i * 7] = PLANAR_VAR
    return c


def _twist_cov6(cov2: np.ndarray) -> list[float]:
    """2x2 (v, w) to 6x6 (vx, vy, vz, wx, wy, wz); vy = 0 (non-holonomic), flat floor."""
    c = [0.0] * 36
    c[0], c[5], c[30], c[35] = float(cov2[0, 0]), float(cov2[0, 1]), float(cov2[1, 0]), float(cov2[1, 1])
    c[0], c[35] = max(c[0], COV_FLOOR), max(c[35], COV_FLOOR)
    for i in (1, 2, 3, 4):
        c[i * 7] = PLANAR_VAR
    return c


def odometry(stamp, frame: str, child: str, x: float, y: float, theta: float, v: float, w: float,
             pose_cov: np.ndarray, twist_cov: np.ndarray) -> Odometry:
    m = Odometry()
    m.header.stamp = stamp
    m.header.frame_id = frame
    m.child_frame_id = child
    p = m.pose.pose
    p.position.x, p.position.y = float(x), float(y)
    p.orientation = yaw_quaternion(theta)
    m.pose.covariance = pose_cov6(pose_cov)
    m.twist.twist.linear.x = float(v)
    m.twist.twist.angular.z = float(w)
    m.twist.covariance = _twist_cov6(twist_cov)
    return m


def laser_scan(stamp, frame: str, ranges: np.ndarray, fov_deg: float, range_min: float, range_max: float,
               scan_time: float, time_increment: float) -> LaserScan:
    """SimTwo's ranger2d as a LaserScan: N rays from -fov/2 step fov/(N-1); -1 (no return) as +inf."""
    n = len(ranges)
    fov = math.radians(fov_deg)
    m = LaserScan()
    m.header.stamp = stamp
    m.header.frame_id = frame
    m.angle_min = -fov / 2
    m.angle_increment = fov / (n - 1) if n > 1 else 0.0
    m.angle_max = m.angle_min + m.angle_increment * (n - 1)
    m.time_increment = time_increment
    m.scan_time = scan_time
    m.range_min = range_min
    m.range_max = range_max
    r = np.asarray(ranges, dtype=np.float64)
    m.ranges = np.where(r < 0, np.inf, r).tolist()  # NaN (not received) stays NaN
    return m


def joint_states(stamp, names: tuple[str, str], angles: tuple[float, float], rates: tuple[float, float]) -> JointState:
    m = JointState()
    m.header.stamp = stamp
    m.name = list(names)
    m.position = [float(a) for a in angles]
    m.velocity = [float(r) for r in rates]
    return m


def camera_info(stamp, frame: str, width: int, height: int, fx: float, fy: float, cx: float, cy: float,
                D=None) -> CameraInfo:
    """CameraInfo of a camera with OpenCV's distortion ``D`` (k1, k2, p1, p2, k3; None: none): plumb_bob;
    P = K (the images are not rectified: consumers undistort points with K and D)."""
    m = CameraInfo()
    m.header.stamp = stamp
    m.header.frame_id = frame
    m.width, m.height = width, height
    m.distortion_model = "plumb_bob"
    fx, fy, cx, cy = float(fx), float(fy), float(cx), float(cy)
    set_camera_matrices(m, [float(v) for v in D] if D is not None else [0.0] * 5,
                        [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                        [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0])
    return m


def set_camera_matrices(m: CameraInfo, D, K, R, P) -> None:
    """CameraInfo's matrices: ``D K R P`` in ROS 1, ``d k r p`` in ROS 2."""
    if hasattr(m, "k"):
        m.d, m.k, m.r, m.p = D, K, R, P
    else:
        m.D, m.K, m.R, m.P = D, K, R, P


def camera_matrices(m: CameraInfo) -> tuple:
    """(D, K, R, P) of a CameraInfo of either middleware, as lists."""
    if hasattr(m, "k"):
        return list(m.d), list(m.k), list(m.r), list(m.p)
    return list(m.D), list(m.K), list(m.R), list(m.P)


def image_bgr8(stamp, frame: str, data: bytes, width: int, height: int) -> Image:
    m = Image()
    m.header.stamp = stamp
    m.header.frame_id = frame
    m.height, m.width = height, width
    m.encoding = "bgr8"
    m.is_bigendian = 0
    m.step = width * 3
    m.data = data
    return m


def image_to_bgr(msg: Image) -> np.ndarray:
    """sensor_msgs/Image (bgr8, rgb8, mono8, bgra8, rgba8) to an HxWx3 BGR or HxW grey uint8 array.

    Raises ValueError (naming the encoding or the sizes) for anything else or a truncated image."""
    import cv2

    enc = msg.encoding.lower()
    ch = {"bgr8": 3, "rgb8": 3, "mono8": 1, "8uc1": 1, "bgra8": 4, "rgba8": 4, "8uc3": 3}.get(enc)
    if ch is None:
        raise ValueError(f"unsupported image encoding {msg.encoding!r}")
    if msg.height <= 0 or msg.width <= 0 or msg.step < msg.width * ch or len(msg.data) < msg.step * msg.height:
        raise ValueError(f"image of {len(msg.data)} bytes does not hold {msg.height}x{msg.width}x{ch} "
                         f"(step {msg.step})")
    a = np.frombuffer(msg.data, dtype=np.uint8, count=msg.step * msg.height).reshape(msg.height, msg.step)
    a = a[:, :msg.width * ch].reshape(msg.height, msg.width, ch) if ch > 1 else a[:, :msg.width]
    if enc == "rgb8":
        return cv2.cvtColor(a, cv2.COLOR_RGB2BGR)
    if enc == "bgra8":
        return cv2.cvtColor(a, cv2.COLOR_BGRA2BGR)
    if enc == "rgba8":
        return cv2.cvtColor(a, cv2.COLOR_RGBA2BGR)
    return a


def planar_pose(x: float, y: float, theta: float) -> Pose:
    """geometry_msgs/Pose of a pose on the floor (z = 0, a rotation about z): no matrix, no general rotation."""
    p = Pose()
    p.position.x, p.position.y = float(x), float(y)
    p.orientation = yaw_quaternion(float(theta))
    return p


def pose_from_matrix(T: np.ndarray) -> Pose:
    """A 4x4 homogeneous transform to geometry_msgs/Pose."""
    p = Pose()
    p.position.x, p.position.y, p.position.z = (float(v) for v in T[:3, 3])
    p.orientation = matrix_quaternion(T[:3, :3])
    return p


def diagnostic_status(name: str, level: int, message: str, hardware_id: str, values: dict,
                      real_format: str = ".3f") -> DiagnosticStatus:
    """A DiagnosticStatus whose values are ``{key: number or text}``, reals written with ``real_format``."""
    kv = [KeyValue(key=str(k), value=format(v, real_format) if isinstance(v, float) else str(v))
          for k, v in values.items()]
    return DiagnosticStatus(level=api().diag_level(level_int(level)), name=name, message=message,
                            hardware_id=hardware_id, values=kv)


def diagnostic_values(status) -> dict[str, str]:
    """The values of a DiagnosticStatus (a middleware's or a bag's) as ``{key: text}``: what
    :func:`diagnostic_status` wrote, read back."""
    return {kv.key: kv.value for kv in status.values}
