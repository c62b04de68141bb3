"""The stand-in simulator's camera: markers OpenCV finds where the field map says, SimTwo's render cadence
(and the k/15 s grid idealisation), wire format, deterministic frames."""
import math

import cv2
import numpy as np
import pytest

from robotatfactory.sim import SimConfig
from robotatfactory.simtwo import Command, decode_frame

pytestmark = pytest.mark.render

# (x, y, theta) robot poses and markers that must be found there (within ~0.35 m of the camera)
POSES = [
    ((-0.71, -0.28, math.pi / 2), {17, 10}),  # near the start pose, looking along the west column
    ((-0.60, -0.20, 0.3), {18, 11, 56, 60}),  # floor markers and machine A's input face
    ((-0.545, 0.22, math.pi / 2), {1, 51}),  # a floor marker and a wall marker of the incoming warehouse
    ((0.62, 0.075, math.pi), {55, 59, 8, 15}),  # machine B's output face
    ((0.10, -0.25, -0.4), {23, 24, 63}),  # the south row and the outgoing warehouse
]


@pytest.fixture(scope="module")
def sim(field, robot):
    from robotatfactory.sim import Simulator

    s = Simulator(field, robot, SimConfig(camera=True, competition=True, lidar=False))
    yield s
    s.close()


@pytest.fixture(scope="module")
def detector(field):
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    return cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, field.dictionary)), params)


def nominal_camera_pose(robot, pose):
    """world <- camera_optical from the robot pose and the camera mount of robot_simtwo.json."""
    x, y, th = pose
    T = np.eye(4)
    T[:2, :2] = [[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]]
    T[:2, 3] = (x, y)
    return T @ robot.camera.base_to_optical()


def project(robot, T_world_cam, points):
    T = np.linalg.inv(T_world_cam)
    rvec, _ = cv2.Rodrigues(T[:3, :3])
    uv, _ = cv2.projectPoints(np.asarray(points, dtype=np.float64), rvec, T[:3, 3], robot.camera.K, np.zeros(5))
    return uv.reshape(-1, 2), (T[:3, :3] @ np.asarray(points).T).T + T[:3, 3]


@pytest.mark.parametrize("pose,must_see", POSES)
def test_markers_found_where_the_field_map_projects_them(sim, field, robot, detector, pose, must_see):
    sim.set_pose(*pose)
    T = nominal_camera_pose(robot, pose)
    # the simulated camera sits where the mount says (the robot rests on the floor within microns)
    assert np.allclose(sim.camera_pose(), T, atol=2e-4)
    img = sim.render_camera()
    assert img.shape == (robot.camera.height, robot.camera.width, 3) and img.dtype == np.uint8
    corners, ids, _ = detector.detectMarkers(img)
    assert ids is not None
    found = {int(i): c.reshape(4, 2) for c, i in zip(corners, ids.ravel())}
    assert must_see <= set(found), (sorted(found), must_see)
    assert set(found) <= set(field.marker_ids) | set(sim.info.part_tags.values())
    close = 0
    for mid, det in found.items():
        if not field.has_marker(mid):
            continue
        uv, cam_pts = project(robot, T, field.marker(mid).corners)
        err = np.linalg.norm(uv - det, axis=1)
        dist = float(np.linalg.norm(cam_pts.mean(axis=0)))
        assert err.max() < 5.0, (mid, err)  # right id, right corner order (orientation), anywhere
        if dist < 0.35:
            assert err.max() < 2.0, (mid, dist, err)
            close += 1
    assert close >= 2


def test_expected_markers_are_the_projected_ones(sim, field, robot, detector):
    """Every marker the map puts fully inside the image, closer than 0.3 m and facing the camera is found."""
    pose = (-0.30, 0.25, 0.2)
    sim.set_pose(*pose)
    T = nominal_camera_pose(robot, pose)
    corners, ids, _ = detector.detectMarkers(sim.render_camera())
    found = set() if ids is None else {int(i) for i in ids.ravel()}
    expected = set()
    cam_pos = T[:3, 3]
    for m in field.markers:
        uv, cam_pts = project(robot, T, m.corners)
        inside = np.all((uv > 10) & (uv < [robot.camera.width - 10, robot.camera.height - 10]))
        facing = float(m.normal @ (cam_pos - m.position)) > 0
        if inside and facing and np.all(cam_pts[:, 2] > 0) and np.linalg.norm(cam_pts.mean(0)) < 0.3:
            expected.add(m.id)
    assert len(expected) >= 2
    assert expected <= found, (expected, found)


def test_grid_frames_follow_the_nominal_render_clock_and_ordering_rule(field, robot):
    """The grid idealisation: 15 frames per simulation second, on ticks k/60 s with k = 4j; a frame is taken
    before the sensor frame of the first cycle ending at or after its tick."""
    from robotatfactory.sim import Simulator

    s = Simulator(field, robot, SimConfig(camera=True, competition=False, lidar=False, camera_timing="grid"))
    period = robot.camera.decimation / robot.camera.render_fps
    seen = []
    prev_end = -1e-9
    for _ in range(25):  # 1.0 s
        f = s.step_cycle(Command(0.1, 0.5, False))
        end = f.time_ms / 1000
        for fr in s.take_frames():
            assert prev_end < fr.tick_time <= end + 1e-9 or (fr.index == 0 and fr.tick_time == 0.0)
            assert fr.tick == fr.index * robot.camera.decimation
            assert fr.tick_time == pytest.approx(fr.index * period)
            assert fr.tick_time <= fr.time < fr.tick_time + s.dt  # the first physics step at/after the tick
            seen.append(fr.index)
        prev_end = end
    assert seen == list(range(16))  # t = 0, 1/15, ..., 1.0 s
    s.close()


def test_wire_frames_are_simtwos_raw_bgra_bottom_up(field, robot):
    from robotatfactory.sim import Simulator

    s = Simulator(field, robot, SimConfig(camera=True, competition=True, lidar=False, camera_timing="grid"))
    s.step_cycle(Command(0.0, 0.0, False))
    (fr,) = s.take_frames()
    wire = fr.wire(bottom_up=True)
    assert wire.shape == (480, 640, 4) and wire.dtype == np.uint8 and wire.nbytes == 640 * 480 * 4
    assert np.all(wire[:, :, 3] == 255)
    img = fr.bgr()
    assert np.array_equal(decode_frame(wire.tobytes(), bottom_up=True), img)
    assert np.array_equal(wire[-1, :, :3], img[0])  # the last row on the wire is the image's top row
    assert np.array_equal(decode_frame(fr.wire(bottom_up=False).tobytes(), bottom_up=False), img)
    assert np.array_equal(img, s.render_camera())  # nothing moved since: the same picture
    s.close()


def test_same_seed_same_frames(field, robot):
    from robotatfactory.sim import Simulator

    def run():
        s = Simulator(field, robot, SimConfig(seed=7, round_no=3, camera=True, competition=True, lidar=True))
        out = []
        for i in range(12):
            s.step_cycle(Command(0.25, 0.6 * math.cos(i / 3), False))
            out.extend(fr.wire().tobytes() for fr in s.take_frames())
        s.close()
        return out

    a, b = run(), run()
    assert len(a) >= 5 and a == b  # SimTwo's cadence: a frame every 68 ms or more of the 480 ms
    assert len(set(a)) > 1  # the robot moved: the frames differ from each other


def test_simtwo_frames_show_chunk_ends_on_a_cadence_that_is_no_grid(field, robot):
    """The default cadence (SimTwo's GUI loop): every frame shows the state at the end of a 17 ms physics
    chunk, frames are 4 renders apart (68 ms) or more after a catch-up (85, 102 ms: the renders of the
    chunks run in a burst are skipped), their offset in the 40 ms control cycle wanders, and they obey the
    ordering rule (taken before the SensorFrame of the first cycle ending at or after them)."""
    from robotatfactory.sim import Simulator

    s = Simulator(field, robot, SimConfig(camera=True, competition=False, lidar=False, seed=3))
    frames, prev_end = [], 0.0
    for _ in range(50):  # 2 s
        f = s.step_cycle(Command(0.1, 0.5, False))
        end = f.time_ms / 1000
        for fr in s.take_frames():
            assert prev_end < fr.time <= end + 1e-9
            frames.append(fr)
        prev_end = end
    s.close()
    steps = [round(fr.time * 1000) for fr in frames]
    assert all(k % 17 == 0 for k in steps)
    gaps = {b - a for a, b in zip(steps, steps[1:])}
    assert 68 in gaps and gaps <= {68, 85, 102, 119, 136}
    assert len({k % 40 for k in steps}) >= 8  # no fixed phase to the control cycle
    assert [fr.index for fr in frames] == list(range(len(frames))) and 24 <= len(frames) <= 30
    assert all(fr.tick % robot.camera.decimation == 0 for fr in frames)
    assert all(b.wall > a.wall for a, b in zip(frames, frames[1:]))


def test_camera_every_publishes_one_frame_in_n_of_the_same_cadence(field, robot):
    """``camera_every`` (a slower host's SimTwo): of the frames the cadence gives, the first and every n-th
    after it are published, numbered 0, 1, 2, ... as published frames are, showing the same states and
    images; the physics is untouched."""
    from robotatfactory.sim import Simulator

    def run(every):
        s = Simulator(field, robot, SimConfig(camera=True, competition=False, lidar=False, seed=3,
                                              camera_every=every))
        frames, poses = [], []
        for _ in range(50):  # 2 s
            s.step_cycle(Command(0.1, 0.5, False))
            frames += [(fr.index, fr.tick, fr.time, fr.wire().tobytes()) for fr in s.take_frames()]
            poses.append(tuple(s.pose))
        s.close()
        return frames, poses

    (all_frames, p1), (thinned, p3) = run(1), run(3)
    assert p1 == p3
    assert len(all_frames) >= 24 and len(thinned) == len(all_frames[::3])
    assert [f[0] for f in thinned] == list(range(len(thinned)))
    assert [f[1:] for f in thinned] == [f[1:] for f in all_frames[::3]]


def test_render_cadence_is_seeded_and_catches_up_like_the_cadencer():
    """Pure schedule checks (no rendering): same seed same schedule, another seed another one; the
    simulation advances 17 ms per 1/60 s wall tick (1.02x real time, SimTwo's fixed chunk); the grid mode is
    today's exact k/15 s."""
    import itertools

    from robotatfactory.errors import ConfigError
    from robotatfactory.sim.camera import GuiLoopModel, RenderCadence

    def take(mode, seed, n=600, gui=None):
        return list(itertools.islice(RenderCadence(mode, 0.001, 60, 4, seed, gui).frames(), n))

    a, b, c = take("simtwo", 1), take("simtwo", 1), take("simtwo", 2)
    assert a == b and a != c
    assert a[0].step == 68 and a[0].tick == 4
    assert a[-1].step / 1000 / a[-1].wall == pytest.approx(1.02, abs=0.01)  # chunks of 17 ms per 16.67 ms
    skipped = sum((y.step - x.step) // 17 - 4 for x, y in zip(a, a[1:]))
    assert 0 < skipped < 0.2 * len(a)  # catch-up bursts happen, the GUI mostly keeps up
    # a GUI that never stalls renders every chunk: a 68 ms grid of simulation time
    calm = take("simtwo", 1, 100, GuiLoopModel(hiccup_prob=0.0, render_sigma=0.0))
    assert {y.step - x.step for x, y in zip(calm, calm[1:])} == {68}
    # a GUI slower than 60 FPS (about 28 ms per iteration) runs one or two chunks per render: frames 6-8
    # chunks apart, and simulation time still keeps 1.02x the wall clock
    slow = take("simtwo", 1, 100, GuiLoopModel(render=0.025, render_sigma=0.0, hiccup_prob=0.0))
    assert {y.step - x.step for x, y in zip(slow, slow[1:])} <= {102, 119, 136}
    assert slow[-1].step / 1000 / slow[-1].wall == pytest.approx(1.02, abs=0.03)
    g = take("grid", 5, 31)
    assert [f.step for f in g] == [math.ceil(j * 1000 / 15 - 1e-6) for j in range(31)]
    assert all(f.tick == 4 * f.index and f.tick_time == pytest.approx(f.index / 15) for f in g)
    with pytest.raises(ConfigError):
        RenderCadence("wall", 0.001)
