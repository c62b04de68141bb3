"""The field as RViz markers (visualization_msgs/MarkerArray, frame ``map``) and the markers' static TFs.

Floor, walls and ribs, slots (part footprints, coloured by zone), the start area, team areas, beacons, and
every ArUco marker as a black square with a white inner square (a target-like "texture") and its ID as text.
"""
from __future__ import annotations


import numpy as np
from geometry_msgs.msg import Point, Pose, Quaternion, Vector3
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from .messages import matrix_quaternion, transform, yaw_quaternion

ZONE_COLOURS = {"incoming": (0.9, 0.6, 0.1), "outgoing": (0.2, 0.6, 0.9), "machine_A": (0.8, 0.2, 0.2),
                "machine_B": (0.3, 0.7, 0.3)}


def _marker(ns, mid, mtype, frame, pose: Pose, scale, rgba, text="") -> Marker:
    m = Marker()
    m.header.frame_id = frame
    m.ns = ns
    m.id = mid
    m.type = mtype
    m.action = Marker.ADD
    m.pose = pose
    sx, sy, sz = (float(v) for v in scale)
    m.scale = Vector3(x=sx, y=sy, z=sz)  # keyword arguments, floats: ROS 2 messages take nothing else
    r, g, b, a = (float(v) for v in rgba)
    m.color = ColorRGBA(r=r, g=g, b=b, a=a)
    m.text = text
    m.frame_locked = False
    return m


def _pose(xyz, q: Quaternion | None = None) -> Pose:
    p = Pose()
    x, y, z = map(float, xyz)
    p.position = Point(x=x, y=y, z=z)
    p.orientation = q or Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
    return p


def field_marker_array(field, frame: str = "map") -> MarkerArray:
    arr = MarkerArray()
    ms = arr.markers
    fx, fy = field.floor.x, field.floor.y
    ms.append(_marker("floor", 0, Marker.CUBE, frame, _pose(((fx[0] + fx[1]) / 2, (fy[0] + fy[1]) / 2, -0.0025)),
                      (fx[1] - fx[0], fy[1] - fy[0], 0.005), (0.93, 0.93, 0.9, 1.0)))
    for i, b in enumerate(field.boxes):
        ms.append(_marker("walls", i, Marker.CUBE, frame, _pose(b.center, yaw_quaternion(b.yaw)), b.size,
                          (0.55, 0.55, 0.6, 1.0)))
    part = field.part
    for i, s in enumerate(field.slots):
        r, g, bl = ZONE_COLOURS.get(s.zone, (0.5, 0.5, 0.5))
        # footprint of a part standing in the slot: plate width across, depth behind the plate
        ms.append(_marker("slots", i, Marker.CUBE, frame, _pose((s.xy[0], s.xy[1], 0.0015), yaw_quaternion(s.facing)),
                          (part.depth, part.width, 0.002), (r, g, bl, 0.5)))
        ms.append(_marker("slot_names", i, Marker.TEXT_VIEW_FACING, frame, _pose((s.xy[0], s.xy[1], 0.09)),
                          (0, 0, 0.03), (r * 0.7, g * 0.7, bl * 0.7, 1.0), s.name))
    areas = [field.start_area] + list(field.team_areas)
    for i, a in enumerate(areas):
        cx, cy = a.center
        ms.append(_marker("areas", i, Marker.CUBE, frame, _pose((cx, cy, 0.001)),
                          (a.x[1] - a.x[0], a.y[1] - a.y[0], 0.001),
                          (0.2, 0.8, 0.2, 0.25) if a.name == "start" else (0.6, 0.6, 0.9, 0.35)))
    for i, (bx, by) in enumerate(field.beacons):
        ms.append(_marker("beacons", i, Marker.CYLINDER, frame, _pose((bx, by, field.beacon_height / 2)),
                          (field.beacon_diameter, field.beacon_diameter, field.beacon_height), (0.95, 0.85, 0.1, 0.8)))
    for m in field.markers:
        q = matrix_quaternion(m.rotation)
        n = m.normal
        s = m.size
        ms.append(_marker("aruco", m.id, Marker.CUBE, frame, _pose(m.position + n * 0.0005, q), (s, s, 0.001),
                          (0.02, 0.02, 0.02, 1.0)))
        ms.append(_marker("aruco_inner", m.id, Marker.CUBE, frame, _pose(m.position + n * 0.0012, q),
                          (s * 5 / 7, s * 5 / 7, 0.0006), (1.0, 1.0, 1.0, 1.0)))
        ms.append(_marker("aruco_core", m.id, Marker.CUBE, frame, _pose(m.position + n * 0.0018, q),
                          (s * 2 / 7, s * 2 / 7, 0.0006), (0.02, 0.02, 0.02, 1.0)))
        text_at = m.position + n * 0.03 + (np.array([0, 0, 0.02]) if m.kind == "wall" else 0)
        ms.append(_marker("aruco_ids", m.id, Marker.TEXT_VIEW_FACING, frame, _pose(text_at), (0, 0, 0.035),
                          (0.1, 0.1, 0.9, 1.0), str(m.id)))
    return arr


def marker_transforms(field, parent: str = "map", prefix: str = "aruco_") -> list:
    """Static TFs parent -> ``aruco_<id>`` for every marker (marker frame: x right, y up the printed face,
    z out of it, OpenCV's convention)."""
    return [transform(parent, f"{prefix}{m.id}", m.pose) for m in field.markers]


def robot_static_transforms(cfg) -> list:
    """base_link -> laser, base_link -> camera_link (pitched down), camera_link -> camera_optical."""
    T_laser = np.eye(4)
    T_laser[:3, 3] = cfg.lidar.xyz
    f = cfg.frames
    return [transform(f["base_link"], f["laser"], T_laser),
            transform(f["base_link"], f["camera_link"], cfg.robot.camera.base_to_link()),
            transform(f["camera_link"], f["camera_optical"], cfg.robot.camera.link_to_optical())]
