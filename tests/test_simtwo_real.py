"""The whole stack against the real SimTwo (the Linux build of raf simtwo build), on each middleware.

One ``raf up --simulator simtwo`` per test process (SimTwo needs about one core and 10-20 s to start: the
tests share it): the real SimTwo with the project's control.pas, LIDAR and settings, raf bridge and raf
localize on a private graph. The tests look at it only through ROS topics and services and through
SimTwo's own log (the script's status lines), never through the bridge's counters. The bounds come from
runs on 2-core machines (docs/simtwo.md, "SimTwo on Linux": what was measured).
"""
from __future__ import annotations

import math
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from rosutil import (Collector, call_service, publisher, ros_graph, srv_types, stamp_s, test_node,  # noqa: F401
                     wait_until)

pytestmark = [pytest.mark.ros, pytest.mark.middlewares, pytest.mark.simtwo]

ROOT = Path(__file__).resolve().parents[1]
STATUS_EVERY = 125  # the script's status line every 125 cycles (5 s) instead of 1500, as a user edits it


def _script(tmp: Path) -> Path:
    text = (ROOT / "simtwo" / "control.pas").read_text(encoding="latin-1")
    text, n = re.subn(r"^(\s*STATUS_EVERY\s*=\s*)\d+;", rf"\g<1>{STATUS_EVERY};", text, flags=re.M)
    assert n == 1
    p = tmp / "control.pas"
    p.write_text(text, encoding="latin-1")
    return p


@pytest.fixture(scope="module")
def stack(ros_graph, middleware, tmp_path_factory):
    """``raf up --simulator simtwo`` (SimTwo, bridge, localization) on this test process's graph."""
    from robotatfactory.simtwo_linux import build

    build.require()  # built by scripts/bootstrap.sh (raf simtwo build): the tests never skip it
    d = tmp_path_factory.mktemp("simtwo_up")
    keep = d / "simtwo"
    cmd = [sys.executable, "-m", "robotatfactory", "up", "--simulator", "simtwo", "--free-ports",
           "--log-dir", str(d / "logs"), f"--sim-arg=--keep={keep}", f"--sim-arg=--script={_script(d)}",
           "--ready-timeout", "120"]
    out = open(d / "up.log", "wb")
    p = subprocess.Popen(cmd, env=ros_graph.env(), stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    end = time.monotonic() + 180
    while b"raf up: running" not in (d / "up.log").read_bytes():
        if p.poll() is not None or time.monotonic() > end:
            p.kill()
            pytest.fail(f"raf up --simulator simtwo did not come up:\n{(d / 'up.log').read_text()}")
        time.sleep(0.2)
    test_node()
    yield {"dir": d, "simtwo_log": keep / "simtwo.log", "up": p}
    from robotatfactory.proc import stop_process

    stop_process(p, timeout=30)
    out.close()
    left = subprocess.run(["pgrep", "-f", str(keep / "scene")], capture_output=True, text=True).stdout.split()
    assert not left, f"SimTwo still running after raf up stopped: {left}"


def _msg(pkg: str, name: str):
    """A message class by package and name (the same modules on ROS 1 and ROS 2)."""
    import importlib

    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def test_up_starts_simtwo_bridge_and_localization(stack):
    text = (stack["dir"] / "up.log").read_text()
    for name in ("sim", "bridge", "localize"):
        assert re.search(rf"^\s+{name}\s+pid \d+", text, re.M), text
    assert "the real SimTwo" in text
    log = stack["simtwo_log"].read_text()
    assert "script: raf: streaming to 127.0.0.1:" in log
    assert not re.search(r"^SimTwo: .*(\[Error\]|Error while executing)", log, re.M), log


def test_sensor_topics_at_simtwo_rates(stack):
    Odometry, LaserScan, JointState = (_msg("nav_msgs", "Odometry"), _msg("sensor_msgs", "LaserScan"),
                                       _msg("sensor_msgs", "JointState"))
    odom, gt, scan, js = (Collector("/odom", Odometry), Collector("/ground_truth", Odometry),
                          Collector("/scan", LaserScan), Collector("/joint_states", JointState))
    try:
        time.sleep(6.0)
        rates = {}
        for name, c in (("odom", odom), ("ground_truth", gt), ("scan", scan), ("joint_states", js)):
            st = [stamp_s(m.header.stamp) for m in list(c.msgs)]
            assert len(st) >= 3, f"{name}: {len(st)} messages in 6 s"
            rates[name] = (len(st) - 1) / (st[-1] - st[0])  # per second of simulation time
        print("rates (sim time):", {k: round(v, 2) for k, v in rates.items()})
        # SimTwo's control period is 40 ms (25 Hz) and its LIDAR sweeps every 0.2 s (5 Hz)
        for name in ("odom", "ground_truth", "joint_states"):
            assert 24.0 <= rates[name] <= 26.0, rates
        assert 4.8 <= rates["scan"] <= 5.2, rates
    finally:
        for c in (odom, gt, scan, js):
            c.close()


def test_one_command_per_sensor_frame(stack):
    """SimTwo's side counts what it applied (control.pas's status line): no reply was refused, and replies
    arrive in most cycles (not all: SimTwo's GUI loop, see below)."""
    pat = re.compile(r"script: raf: frames (\d+), replies applied (\d+), ignored (\d+), timeouts (\d+)")
    before = len(pat.findall(stack["simtwo_log"].read_text()))  # lines from before the bridge was up
    end = time.monotonic() + 3 * STATUS_EVERY * 0.04 + 10
    while time.monotonic() < end:
        lines = pat.findall(stack["simtwo_log"].read_text())[before:]
        if len(lines) >= 2:
            break
        time.sleep(0.5)
    assert len(lines) >= 2, stack["simtwo_log"].read_text()[-2000:]
    (f0, a0, i0, _t0), (f1, a1, i1, _t1) = [tuple(map(int, x)) for x in lines[-2:]]
    share = (a1 - a0) / (f1 - f0)
    print(f"frames {f0}->{f1}, replies applied {a0}->{a1} ({100 * share:.0f} % of the cycles), ignored {i1}")
    assert f1 - f0 == STATUS_EVERY
    assert i1 == i0  # every reply that arrived was valid and newer than the last
    # The bridge answers every frame at once, but SimTwo reads datagrams only between iterations of its GUI
    # loop, which renders the scene: with Mesa's software rendering an iteration often spans two 40 ms
    # cycles, so a reply is applied in 55-70 % of them (2-core machines, camera on; docs/simtwo.md)
    assert 0.45 <= share <= 1.0, share


def test_scan_from_simtwo(stack):
    LaserScan = _msg("sensor_msgs", "LaserScan")
    c = Collector("/scan", LaserScan)
    try:
        msgs = c.wait(4, timeout=15)
    finally:
        c.close()
    m = msgs[-1]
    r = np.asarray(m.ranges, dtype=float)
    assert len(r) == 360
    nan = np.isnan(r).sum()
    # SimTwo's rays hit the robot's own wheels (about +/-23 deg around +/-90 deg): the bridge marks them NaN
    assert 70 <= nan <= 110, nan
    fin = r[np.isfinite(r)]
    assert len(fin) > 0 and fin.min() > 0.05 and fin.max() <= 6.0
    st = [stamp_s(x.header.stamp) for x in msgs]
    steps = np.diff(st)
    assert np.allclose(steps, 0.2, atol=0.041), steps  # one scan per 0.2 s sweep
    # stamped at the sweep's first ray: its delivery (1 ms after a 40 ms script cycle, simtwo/scan.py) - 0.2 s
    assert all(abs((s - 0.001) / 0.04 - round((s - 0.001) / 0.04)) < 1e-3 for s in st), st


def test_camera_frames_and_camera_info(stack):
    Image, CameraInfo = _msg("sensor_msgs", "Image"), _msg("sensor_msgs", "CameraInfo")
    img, info = Collector("/camera/image_raw", Image), Collector("/camera/camera_info", CameraInfo)
    try:
        t0 = time.monotonic()
        frames = img.wait(4, timeout=30)
        wall = time.monotonic() - t0
        infos = info.wait(1, timeout=10)
    finally:
        img.close()
        info.close()
    m = frames[-1]
    assert (m.width, m.height, m.encoding) == (640, 480, "bgr8")
    a = np.frombuffer(bytes(m.data), np.uint8).reshape(480, 640, 3).astype(float)
    assert a.std() > 10  # a rendered scene, not a blank (a covered GL window reads back black)
    top, bottom = a[:40].mean(axis=(0, 1)), a[-40:].mean(axis=(0, 1))
    assert top[0] > top[2] + 20, (top, bottom)  # BGR: the sky (blue) at the top: the image is upright
    k = list(getattr(infos[-1], "K", None) or infos[-1].k)
    assert k[0] > 100 and abs(k[2] - 319.5) < 1 and abs(k[5] - 239.5) < 1
    st = [stamp_s(f.header.stamp) for f in frames]
    assert all(b > a_ for a_, b in zip(st, st[1:]))
    print(f"camera: 4 frames in {wall:.1f} s of wall time")


def _service(name: str, typ, **fields):
    return call_service(f"/sim/{name}", typ, timeout=20, **fields)


def _latest(c: Collector):
    m = list(c.msgs)[-1]
    p = m.pose.pose
    yaw = 2 * math.atan2(p.orientation.z, p.orientation.w)
    return p.position.x, p.position.y, yaw


def test_set_robot_pose_reset_and_unsupported_services(stack):
    t = srv_types()
    st = _service("get_state", t.GetSimulationState)
    assert st.success and st.simulator == "simtwo", st
    assert {"set_robot_pose", "place_part", "reset"} <= set(st.supported)
    assert "pause" not in st.supported
    gt = Collector("/ground_truth", _msg("nav_msgs", "Odometry"))
    try:
        r = _service("set_robot_pose", t.SetRobotPose, x=0.1, y=-0.33, theta=0.3)
        assert r.success, r.message
        gt.wait(5, timeout=5)
        x, y, th = _latest(gt)
        assert math.hypot(x - 0.1, y + 0.33) < 0.01 and abs(math.remainder(th - 0.3, 2 * math.pi)) < 0.03
        r = _service("reset", t.ResetSimulation)
        assert r.success, r.message
        time.sleep(0.5)
        from robotatfactory.field import load_field

        sp = load_field("simtwo2022").start_pose
        x, y, th = _latest(gt)
        assert math.hypot(x - sp.x, y - sp.y) < 0.01 and abs(math.remainder(th - sp.theta, 2 * math.pi)) < 0.03
    finally:
        gt.close()
    r = _service("pause", t.Trigger)
    assert not r.success and "not supported" in r.message


def test_simulation_interfaces_on_simtwo(stack, middleware):
    """ROS 2's simulation_interfaces on the real SimTwo: the features its script API allows, the robot and a
    part moved, deleted and spawned by teleport, each effect seen in SimTwo's ground truth (``ground_truth``,
    ``ground_truth/parts``: the script's own labels); reset, pause and step unsupported. ROS 1: the package's
    own sim/* services only."""
    from rosutil import service_names

    from robotatfactory.field import load_field
    from robotatfactory.ros.mw import api
    from robotatfactory.ros.simulation_interfaces import SERVICE_NAMES
    from robotatfactory.sim import standard as st

    if middleware == "ros1":
        names = service_names()
        assert "/sim/set_robot_pose" in names and not any(f"/{n}" in names for n in SERVICE_NAMES)
        return
    T = api().standard_sim_types()

    def call(service, **fields):
        return call_service(f"/{service}", getattr(T.srv, SERVICE_NAMES[service]), timeout=20, **fields)

    def state(x, y, yaw):
        s = T.msg.EntityState()
        s.pose.position.x, s.pose.position.y = x, y
        s.pose.orientation.z, s.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
        return s

    floor = load_field("simtwo2022").floor
    f = call("get_simulator_features").features
    assert sorted(f.features) == sorted(st.SIMTWO_FEATURES)
    for service, fields in (("reset_simulation", {}), ("step_simulation", {"steps": 1}),
                            ("set_simulation_state", {"state": T.msg.SimulationState(state=st.PAUSED)})):
        r = call(service, **fields)
        assert r.result.result == st.FEATURE_UNSUPPORTED, service
    assert call("get_simulation_state").state.state == st.PLAYING
    gt = Collector("/ground_truth", _msg("nav_msgs", "Odometry"))
    parts = Collector("/ground_truth/parts", _msg("geometry_msgs", "PoseArray"))
    try:
        r = call("set_entity_state", entity="robot", state=state(0.1, -0.33, 0.3))
        assert r.result.result == st.OK, r.result.error_message
        gt.wait(5, timeout=5)
        x, y, th = _latest(gt)
        assert math.hypot(x - 0.1, y + 0.33) < 0.01 and abs(math.remainder(th - 0.3, 2 * math.pi)) < 0.03
        r = call("get_entity_state", entity="robot")
        assert math.hypot(r.state.pose.position.x - x, r.state.pose.position.y - y) < 0.01

        truth = parts.wait(1, timeout=5)[-1].poses
        names = list(call("get_entities").entities)
        on = [k + 1 for k, p in enumerate(truth) if floor.contains(p.position.x, p.position.y)]
        assert names == ["robot"] + [f"part_{k}" for k in on]
        pid = len(truth)  # the last part: deleted (if on the field), spawned at a free spot, deleted again
        if pid in on:
            assert call("delete_entity", entity=f"part_{pid}").result.result == st.OK
        parts.clear()
        p = parts.wait(1, timeout=5)[-1].poses[pid - 1].position
        assert not floor.contains(p.x, p.y) and f"part_{pid}" not in call("get_entities").entities
        from geometry_msgs.msg import PoseStamped

        pose = PoseStamped()
        pose.pose.position.x, pose.pose.position.y, pose.pose.orientation.w = 0.35, -0.33, 1.0
        r = call("spawn_entity", name=f"part_{pid}", uri="raf://part", initial_pose=pose)
        assert r.result.result == st.OK and r.entity_name == f"part_{pid}", r.result.error_message
        parts.clear()
        p = parts.wait(1, timeout=5)[-1].poses[pid - 1].position
        assert math.hypot(p.x - 0.35, p.y + 0.33) < 0.01
        r = call("get_entity_state", entity=f"part_{pid}")
        assert math.hypot(r.state.pose.position.x - 0.35, r.state.pose.position.y + 0.33) < 0.01
        r = call("spawn_entity", name=f"part_{pid}", uri="raf://part/red", initial_pose=pose)
        assert r.result.result == st.NAME_NOT_UNIQUE
        assert call("delete_entity", entity=f"part_{pid}").result.result == st.OK
        assert [s.uri for s in call("get_spawnables").spawnables] == ["raf://part"]
        b = call("get_entity_bounds", entity="robot").bounds
        assert b.type == st.BOUNDS_BOX and b.points[0].x < 0 < b.points[1].x
        # the rest of SimTwo's subset: info, states, named poses, several spawns, a part moved
        assert call("get_entity_info", entity="robot").info.category.category == st.CATEGORY_ROBOT
        r = call("get_entities_states", filters=T.msg.EntityFilters(filter="^robot$"))
        assert list(r.entities) == ["robot"] and math.hypot(r.states[0].pose.position.x - 0.1,
                                                            r.states[0].pose.position.y + 0.33) < 0.02
        named = {p.name: p for p in call("get_named_poses").poses}
        assert "start" in named and call("get_named_pose_bounds", name="start").result.result == st.OK
        SE, R = T.msg.SpawnEntity, T.msg.Resource
        r = call("spawn_entities", spawn_requests=[SE(name=f"part_{pid}", entity_resource=R(uri="raf://part"),
                                                      initial_pose=pose)])  # free floor: (0.35, -0.33)
        assert r.result.result == st.OK and r.results[0].entity_name == f"part_{pid}", r.results[0].result
        parts.clear()
        p = parts.wait(1, timeout=5)[-1].poses[pid - 1].position
        assert math.hypot(p.x - 0.35, p.y + 0.33) < 0.01
        r = call("set_entity_state", entity=f"part_{pid}", state=state(0.35, -0.25, 0.0))
        assert r.result.result == st.OK, r.result.error_message
        parts.clear()
        p = parts.wait(1, timeout=5)[-1].poses[pid - 1].position
        assert math.hypot(p.x - 0.35, p.y + 0.25) < 0.01
        assert call("delete_entity", entity=f"part_{pid}").result.result == st.OK
    finally:
        gt.close()
        parts.close()


def _drive(pub, twist_type, v: float, w: float, seconds: float) -> None:
    msg = twist_type()
    msg.linear.x, msg.angular.z = v, w
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        pub.publish(msg)
        time.sleep(0.05)




def test_odometry_against_simtwo_ground_truth(stack):
    """A drive up the free column between the machines (0.6 m north, half a turn on the spot, 0.5 m back):
    odometry's displacement against SimTwo's ground truth. The column leaves room for the 8-13 deg the robot
    turns as its speed controllers take the reversal from the turn to the straight (the wheels do turn:
    odometry sees it); in the band south of the machines that heading took the robot into the outgoing
    warehouse's corner post now and then, which turned it where the encoders cannot see."""
    from robotatfactory.localization.geometry import between2

    t = srv_types()
    Odometry, Twist = _msg("nav_msgs", "Odometry"), _msg("geometry_msgs", "Twist")
    assert _service("set_robot_pose", t.SetRobotPose, x=0.0, y=-0.35, theta=math.pi / 2).success
    odom, gt = Collector("/odom", Odometry), Collector("/ground_truth", Odometry)
    pub = publisher("/cmd_vel", Twist)
    try:
        _drive(pub, Twist, 0.0, 0.0, 1.0)
        o0, g0 = _latest(odom), _latest(gt)
        path0 = len(gt.msgs)
        _drive(pub, Twist, 0.2, 0.0, 3.0)
        _drive(pub, Twist, 0.0, 1.5, 2.1)
        _drive(pub, Twist, 0.2, 0.0, 2.5)
        _drive(pub, Twist, 0.0, 0.0, 1.5)
        o1, g1 = _latest(odom), _latest(gt)
        pts = [(m.pose.pose.position.x, m.pose.pose.position.y) for m in list(gt.msgs)[path0:]]
    finally:
        odom.close()
        gt.close()
    path = sum(math.dist(a, b) for a, b in zip(pts, pts[1:]))
    ro, rg = between2(o0, o1), between2(g0, g1)
    err = math.hypot(ro[0] - rg[0], ro[1] - rg[1])
    herr = abs(math.degrees(math.remainder(ro[2] - rg[2], 2 * math.pi)))
    print(f"path {path:.3f} m (truth), odometry error {1000 * err:.1f} mm ({1000 * err / path:.1f} mm/m), "
          f"heading {herr:.2f} deg; truth {rg}, odom {ro}")
    assert path > 0.9
    assert err / path < 0.08 and herr < 8.0


def test_electromagnet_holds_a_part(stack):
    """A part put 1 cm in front of the magnet (sim/place_part: SimTwo's teleport of Part1): the magnet on,
    the robot creeps forward until the contact switch closes, backs away 0.2 m and the part comes along (the
    switch stays closed); the magnet off, the robot backs away and the switch opens."""
    t = srv_types()
    Twist, Bool = _msg("geometry_msgs", "Twist"), _msg("std_msgs", "Bool")
    x0, y0 = -0.1, -0.33
    assert _service("set_robot_pose", t.SetRobotPose, x=x0, y=y0, theta=0.0).success
    r = _service("place_part", t.PlacePart, part=1, x=x0 + 0.08 + 0.01 + 0.03, y=y0, facing=math.pi)
    assert r.success, r.message
    contact = Collector("/contact", Bool)
    pub, mag = publisher("/cmd_vel", Twist), publisher("/electromagnet", Bool)
    on, off = Bool(), Bool()
    on.data, off.data = True, False
    try:
        for _ in range(5):
            mag.publish(on)
            time.sleep(0.1)
        end = time.monotonic() + 6
        while time.monotonic() < end and not (contact.msgs and list(contact.msgs)[-1].data):
            _drive(pub, Twist, 0.03, 0.0, 0.2)
        assert list(contact.msgs)[-1].data, "the contact switch never closed"
        _drive(pub, Twist, -0.1, 0.0, 2.0)
        _drive(pub, Twist, 0.0, 0.0, 0.5)
        held = [m.data for m in list(contact.msgs)[-10:]]
        assert all(held), f"the part did not come along: contact {held}"
        for _ in range(5):
            mag.publish(off)
            time.sleep(0.1)
        _drive(pub, Twist, -0.1, 0.0, 1.5)
        _drive(pub, Twist, 0.0, 0.0, 0.5)
        assert not list(contact.msgs)[-1].data, "the part stayed on the magnet after it was switched off"
    finally:
        _drive(pub, Twist, 0.0, 0.0, 0.3)
        mag.publish(off)
        contact.close()
        _service("place_part", t.PlacePart, part=1, remove=True)


def test_localization_poses_on_simtwo(stack):
    """raf localize on SimTwo's camera and LIDAR: the EKF's pose (``pose``) against SimTwo's ground truth,
    at rest at a spot with floor markers in view, once it has found the teleported robot again (within 30 s)."""
    t = srv_types()
    PoseCov, Odometry = _msg("geometry_msgs", "PoseWithCovarianceStamped"), _msg("nav_msgs", "Odometry")
    fixes = {k: Collector(f"/aruco/fixes/filter_{k}", PoseCov) for k in ("accepted", "rejected")}
    track = Collector("/pose", PoseCov)
    assert _service("set_robot_pose", t.SetRobotPose, x=-0.55, y=-0.33, theta=0.0).success
    gt = Collector("/ground_truth", Odometry)
    t0 = time.monotonic()
    try:
        # The filter finds the jump again: it restarts at the 6th confident camera fix it gated in a row
        # (ekf.reinit_after_gated), 0.7-4 s after the teleport on a quiet machine (2026-12-02). In a suite run
        # under load its pose was still about where the robot had stood before the teleport (44 mm away) after
        # the 6 s this test used to wait.
        gt.wait(1, timeout=5, pred=lambda m: math.dist((m.pose.pose.position.x, m.pose.pose.position.y),
                                                       (-0.55, -0.33)) < 0.02)  # SimTwo has moved it
        try:
            wait_until(lambda: track.msgs and math.dist(_latest(track)[:2], _latest(gt)[:2]) < 0.03, 30,
                       what="the EKF's pose back within 3 cm of SimTwo's truth after the teleport")
        except TimeoutError as e:
            pytest.fail(f"{e}\n{_settling(track, fixes, _latest(gt)[:2])}")
        print(f"the EKF found the teleported pose again after {time.monotonic() - t0:.1f} s")
        time.sleep(1.0)
        track.wait(len(track.msgs) + 10, timeout=30)  # ten more poses
        gt.wait(5, timeout=5)
        px, py, pth = _latest(track)
        gx, gy, gth = _latest(gt)
    finally:
        for c in (gt, track, *fixes.values()):
            c.close()
    err = math.hypot(px - gx, py - gy)
    herr = abs(math.degrees(math.remainder(pth - gth, 2 * math.pi)))
    print(f"EKF pose ({px:.3f}, {py:.3f}, {math.degrees(pth):.1f} deg), truth ({gx:.3f}, {gy:.3f}, "
          f"{math.degrees(gth):.1f} deg): {1000 * err:.1f} mm, {herr:.2f} deg")
    assert err < 0.03 and herr < 3.0, f"the EKF {1000 * err:.1f} mm, {herr:.2f} deg off the truth\n" + \
        _settling(track, fixes, (gx, gy))


def _settling(track, fixes, truth) -> str:
    """What the filter did after the teleport (a failure's evidence): its pose every half second and the camera
    fixes it took and gated (stamp, position, sigma, distance from the truth)."""
    def xy(m):
        p = m.pose.pose.position
        return p.x, p.y

    lines, last = ["pose since the teleport (stamp s: x, y, mm from the truth):"], -math.inf
    for m in list(track.msgs):
        s = stamp_s(m.header.stamp)
        if s - last >= 0.5:
            last = s
            lines.append(f"  {s:.2f}: {xy(m)[0]:.3f}, {xy(m)[1]:.3f}, {1000 * math.dist(xy(m), truth):.0f}")
    for kind, c in fixes.items():
        lines.append(f"camera fixes {kind}: {len(c.msgs)}")
        for m in list(c.msgs)[-12:]:
            sig = 1000 * math.sqrt(max(m.pose.covariance[0], m.pose.covariance[7]))
            lines.append(f"  {stamp_s(m.header.stamp):.2f}: {xy(m)[0]:.3f}, {xy(m)[1]:.3f}, sigma {sig:.1f} mm, "
                         f"{1000 * math.dist(xy(m), truth):.0f} mm from the truth")
    return "\n".join(lines)
