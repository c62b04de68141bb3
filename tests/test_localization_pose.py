"""Pose maths on synthetic detections with known answers: the corners of known markers projected through a
known camera pose (cv2.projectPoints), with noise; each method must recover the pose."""
import math

import cv2
import numpy as np
import pytest

from robotatfactory.localization import reasons
from robotatfactory.localization.detect import Detection
from robotatfactory.localization.estimators import planar_fit
from robotatfactory.localization.geometry import (between2, compose2, inv, matrix_rt, matrix_se2, se2_exp,
                                                  se2_log, se2_matrix, split_increment, wrap_angle)
from robotatfactory.localization.markerpose import PoseConfig, observe
from robotatfactory.localization.pipeline import FrameLocalizer
from robotatfactory.localization.synth import camera_world_pose, visible_markers


def _err(est, pose):
    d = np.array(est.base) - np.array(pose)
    return math.hypot(d[0], d[1]), abs(wrap_angle(d[2]))


def _project(marker, T_world_cam, K):
    rvec, tvec = matrix_rt(inv(T_world_cam))
    return cv2.projectPoints(marker.corners, rvec, tvec, K, None)[0].reshape(4, 2)


def _detections(field, robot, pose, noise_px, rng, min_side_px=8.0):
    T = camera_world_pose(robot.camera, pose)
    dets = []
    for v in visible_markers(field, robot.camera, T, min_side_px=min_side_px):
        c = _project(field.marker(v.id), T, robot.camera.K)
        np.testing.assert_allclose(c, v.corners, atol=1e-6)  # projectPoints agrees with our projection
        dets.append(Detection(v.id, c + rng.normal(0, noise_px, (4, 2))))
    return dets


# ---------------------------------------------------------------------------------------------- geometry

def test_se2_helpers_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(200):
        a = tuple(rng.uniform(-1, 1, 2)) + (rng.uniform(-3, 3),)
        d = (rng.uniform(-0.2, 0.2), rng.uniform(-0.05, 0.05), rng.uniform(-1.5, 1.5))
        b = compose2(a, d)
        np.testing.assert_allclose(between2(a, b), d, atol=1e-12)
        np.testing.assert_allclose(se2_exp(se2_log(d)), d, atol=1e-12)
        first, rest = split_increment(d, 0.3)
        np.testing.assert_allclose(compose2(compose2(a, first), rest), b, atol=1e-12)
        np.testing.assert_allclose(se2_matrix(*b), se2_matrix(*a) @ se2_matrix(*d), atol=1e-12)
        assert matrix_se2(se2_matrix(*b)) == pytest.approx(b)


def test_split_of_a_straight_arc_is_proportional():
    first, rest = split_increment((0.1, 0.0, 0.0), 0.25)
    assert first == pytest.approx((0.025, 0.0, 0.0)) and rest == pytest.approx((0.075, 0.0, 0.0))
    # a quarter circle of radius 1 split in half ends at 45 degrees on the circle
    first, _ = split_increment((1.0, 1.0, math.pi / 2), 0.5)
    assert first == pytest.approx((math.sin(math.pi / 4), 1 - math.cos(math.pi / 4), math.pi / 4))


def test_camera_mount_matches_the_robot_file(robot):
    T = robot.camera.base_to_optical()
    assert T[:3, 3] == pytest.approx([0.05, 0.0, 0.1169])
    # optical z (forward) points along base x, 29.64 deg down (the scene's 30 on SimTwo's body, resting nose-up)
    a = math.radians(29.64)
    assert T[:3, 2] == pytest.approx([math.cos(a), 0, -math.sin(a)])
    assert T[:3, 0] == pytest.approx([0, -1, 0])  # image right = robot -y


# ---------------------------------------------------------------------------------------------- methods

POSES = [(-0.725, -0.4, math.pi / 2), (0.1, 0.08, 0.3), (0.55, -0.25, 2.5), (-0.2, 0.25, -2.0),
         (0.6, 0.3, -1.2), (-0.55, -0.05, math.pi / 2)]


@pytest.mark.parametrize("pose", POSES)
def test_noise_free_corners_give_the_exact_pose(field, robot, pose):
    loc = FrameLocalizer(field, robot)
    res = loc.process_detections(_detections(field, robot, pose, 0.0, np.random.default_rng(0)))
    assert res.observations, "the pose should see markers"
    for m in ("closest_checked", "all_pnp", "planar"):
        e = res.estimates[m]
        assert e.ok, (m, e.reason)
        dp, dth = _err(e, pose)
        assert dp < 1e-6 and dth < 1e-6, (m, dp, dth)
    # the camera pose itself, and base_link = camera * inv(mount)
    T_true = camera_world_pose(robot.camera, pose)
    np.testing.assert_allclose(res.estimates["all_pnp"].T_world_cam, T_true, atol=1e-6)
    np.testing.assert_allclose(res.estimates["planar"].T_world_cam, T_true, atol=1e-9)


def test_noisy_corners_accuracy_and_ordering(field, robot):
    """0.3 px corner noise over random poses: all-marker PnP and the planar fit are far better than the
    closest marker alone, as the reference measurement found."""
    rng = np.random.default_rng(1)
    loc = FrameLocalizer(field, robot)
    errs = {m: [] for m in ("closest_checked", "all_pnp", "planar")}
    n = 0
    while n < 150:
        pose = (rng.uniform(-0.75, 0.75), rng.uniform(-0.45, 0.45), rng.uniform(-math.pi, math.pi))
        dets = _detections(field, robot, pose, 0.3, rng)
        if not dets:
            continue
        n += 1
        res = loc.process_detections(dets)
        for m in errs:
            if res.estimates[m].ok:
                errs[m].append(_err(res.estimates[m], pose))
    med = {m: np.median(np.array(v), axis=0) for m, v in errs.items()}
    p95 = {m: np.percentile(np.array(v), 95, axis=0) for m, v in errs.items()}
    assert med["planar"][0] < 0.001 and p95["planar"][0] < 0.005  # metres
    assert med["planar"][1] < math.radians(0.1) and p95["planar"][1] < math.radians(0.5)
    assert med["all_pnp"][0] < 0.5 * med["closest_checked"][0]
    assert med["planar"][0] < 0.5 * med["closest_checked"][0]
    assert len(errs["planar"]) > 0.9 * n  # few frames rejected


def test_planar_covariance_is_consistent(field, robot):
    """With corner noise drawn from the model itself, the planar fit's normalised error squared (NEES)
    averages about 3 (3 degrees of freedom); the model-error floor is switched off for this check."""
    cfg = PoseConfig(floor_position_sigma_m=0.0, floor_heading_sigma_deg=0.0)
    loc = FrameLocalizer(field, robot, pose=cfg)
    rng = np.random.default_rng(2)
    nees = []
    while len(nees) < 300:
        pose = (rng.uniform(-0.75, 0.75), rng.uniform(-0.45, 0.45), rng.uniform(-math.pi, math.pi))
        T = camera_world_pose(robot.camera, pose)
        vis = visible_markers(field, robot.camera, T, min_side_px=8)
        if not vis:
            continue
        dets = []
        for v in vis:
            m = field.marker(v.id)
            los = T[:3, 3] - m.position
            cosv = abs(los @ m.normal) / np.linalg.norm(los)
            dets.append(Detection(v.id, v.corners + rng.normal(0, cfg.corner_sigma(np.linalg.norm(los), cosv), (4, 2))))
        e = loc.process_detections(dets).estimates["planar"]
        if e.ok:
            d = np.array(e.base) - pose
            d[2] = wrap_angle(d[2])
            nees.append(d @ np.linalg.solve(e.cov, d))
    assert 2.0 < np.mean(nees) < 4.0, np.mean(nees)


def test_covariance_grows_with_distance_and_shrinks_with_markers(field, robot):
    loc = FrameLocalizer(field, robot)
    K = loc.K
    # the robot looking at marker 13 (origin) from 0.2 m and 0.45 m, straight on
    sig = []
    for dist in (0.2, 0.3, 0.45):
        pose = (-dist, 0.0, 0.0)
        T = camera_world_pose(robot.camera, pose)
        det = [Detection(13, _project(field.marker(13), T, K))]
        e = loc.process_detections(det).estimates["planar"]
        assert e.ok or e.reason == reasons.FAR_LONE_MARKER
        sig.append(e.sigma_xy)
    assert sig[0] < sig[1] < sig[2]
    # the same pose with all its visible markers is more certain than with the closest one alone
    pose = (0.1, 0.08, 0.3)
    dets = _detections(field, robot, pose, 0.0, np.random.default_rng(0))
    assert len(dets) >= 3
    T = camera_world_pose(robot.camera, pose)
    closest = min(dets, key=lambda d: np.linalg.norm(field.marker(d.id).position - T[:3, 3]))
    one = loc.process_detections([closest]).estimates["planar"]
    many = loc.process_detections(dets).estimates["planar"]
    assert many.sigma_xy < one.sigma_xy and many.sigma_theta < one.sigma_theta
    # the 6-DoF covariance of the closest-marker method is positive definite
    c6 = loc.process_detections(dets).estimates["closest_checked"].cov6
    assert np.all(np.linalg.eigvalsh(c6) > 0)


# ---------------------------------------------------------------------------------------------- ambiguity

def _ambiguous_case(field, robot, K):
    """A lone floor marker (13, the origin) about 0.55 m away, 40 deg off the camera's axis, its corners
    nudged (about 0.2 px) towards IPPE's second solution so that IPPE's best solution is the wrong one: the
    planar ambiguity of a far marker seen at a grazing angle."""
    a = math.radians(40)
    pose = (-0.6 * math.cos(a), -0.6 * math.sin(a), a)
    m = field.marker(13)
    T = camera_world_pose(robot.camera, pose)
    true = _project(m, T, K)
    _, rvecs, tvecs, _ = cv2.solvePnPGeneric(m.corners_local, true, K, None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    T_cm_true = inv(T) @ m.pose
    alts = [(r, t) for r, t in zip(rvecs, tvecs)
            if np.linalg.norm(cv2.Rodrigues(r)[0] - T_cm_true[:3, :3]) > 1e-3]
    assert alts, "IPPE should give a second solution"
    alt = cv2.projectPoints(m.corners_local, alts[0][0], alts[0][1], K, None)[0].reshape(4, 2)
    corners = true + 0.75 * (alt - true)
    return pose, [Detection(13, corners)], float(np.abs(corners - true).max())


def test_ambiguity_is_caught_by_the_mount_check(field, robot):
    cfg = PoseConfig(lone_marker_max_distance_m=1.0)
    loc = FrameLocalizer(field, robot, pose=cfg)
    pose, dets, nudge = _ambiguous_case(field, robot, loc.K)
    assert nudge < 0.3
    res = loc.process_detections(dets)
    o = res.observations[0]
    assert o.distance_m > 0.5
    assert not o.mount[0].ok, "IPPE's best solution puts the camera off its mount"
    assert o.checked is not None and o.checked != 0
    paper = res.estimates["closest"]
    assert paper.ok  # the paper's method has no check ...
    dp, dth = _err(paper, pose)
    assert dp > 0.05 or dth > math.radians(5)  # ... and is badly wrong
    assert paper.mount_tilt_deg > cfg.mount_max_tilt_deg
    for m in ("closest_checked", "all_pnp", "planar"):
        e = res.estimates[m]
        assert e.ok, (m, e.reason)
        dp, dth = _err(e, pose)
        assert dp < 0.03 and dth < math.radians(3), (m, dp, math.degrees(dth))


def test_far_lone_marker_is_rejected_by_default(field, robot):
    loc = FrameLocalizer(field, robot)
    pose, dets, _ = _ambiguous_case(field, robot, loc.K)
    res = loc.process_detections(dets)
    assert res.estimates["planar"].reason == reasons.FAR_LONE_MARKER
    assert res.estimates["closest_checked"].reason == reasons.FAR_LONE_MARKER
    assert loc.counts["planar:" + reasons.FAR_LONE_MARKER] == 1


# ---------------------------------------------------------------------------------------------- bad input

def test_bad_detections_are_rejected_with_a_reason(field, robot):
    loc = FrameLocalizer(field, robot)
    pose = (0.1, 0.08, 0.3)
    good = _detections(field, robot, pose, 0.1, np.random.default_rng(3))
    assert len(good) >= 3
    c = good[0].corners
    bad = [
        Detection(99, c + 50),  # unknown id
        Detection(good[1].id, good[1].corners + 30), Detection(good[1].id, good[1].corners),  # duplicate id
        Detection(good[2].id, np.array([[10, 10], [10.5, 10], [10.5, 10.5], [10, 10.5]], float)),  # tiny
    ]
    res = loc.process_detections([good[0]] + good[3:] + bad)
    why = dict(res.rejected)
    assert why[99] == reasons.UNKNOWN_ID
    assert why[good[1].id] == reasons.DUPLICATE_ID
    assert why[good[2].id] == reasons.DEGENERATE
    assert loc.counts[reasons.UNKNOWN_ID] == 1 and loc.counts[reasons.DUPLICATE_ID] == 2
    e = res.estimates["planar"]
    assert e.ok and _err(e, pose)[0] < 0.005
    # non-finite and self-intersecting corners
    nan = Detection(good[0].id, np.full((4, 2), np.nan))
    bow = Detection(good[0].id, good[0].corners[[0, 2, 1, 3]])
    for d in (nan, bow):
        r = loc.process_detections([d])
        assert r.rejected == [(good[0].id, reasons.DEGENERATE)] and not r.estimates["planar"].ok
        assert r.estimates["planar"].reason == reasons.NO_MARKERS
    assert loc.counts[reasons.NO_MARKERS] == 2


def test_an_outlier_marker_is_dropped(field, robot):
    """A marker whose ID was misread (it is drawn where another marker is) disagrees with the rest."""
    loc = FrameLocalizer(field, robot)
    pose = (0.1, 0.08, 0.3)
    dets = _detections(field, robot, pose, 0.1, np.random.default_rng(4))
    assert len(dets) >= 4
    ids = {d.id for d in dets}
    wrong = next(i for i in field.marker_ids if i not in ids and field.marker(i).kind == "floor")
    far = max(dets, key=lambda d: d.corners[:, 1].min())  # the lowest in the image: a close one
    dets = [d if d is not far else Detection(wrong, d.corners) for d in dets]
    res = loc.process_detections(dets)
    e = res.estimates["planar"]
    assert e.ok and wrong in e.dropped and wrong not in e.marker_ids
    assert _err(e, pose)[0] < 0.005
    assert loc.counts[reasons.MARKER_OUTLIER] == 1
    assert (wrong, reasons.MARKER_OUTLIER) in res.rejected
    e = res.estimates["all_pnp"]  # the all-marker PnP uses the markers the consensus agreed on
    assert e.ok and wrong not in e.marker_ids and _err(e, pose)[0] < 0.005


def test_absurd_poses_are_rejected(field, robot):
    cfg = PoseConfig()
    loc = FrameLocalizer(field, robot, pose=cfg)
    # corners consistent with a robot far outside the field: shift the field's markers' frame
    pose = (0.1, 0.08, 0.3)
    dets = _detections(field, robot, pose, 0.0, np.random.default_rng(0))
    # relabel every marker with the ID of the marker 0.695 m further in x: a consistent but impossible pose
    shifted = []
    for d in dets:
        p = field.marker(d.id).position
        for m in field.floor_markers():
            if abs(m.position[0] - (p[0] - 1.39)) < 1e-6 and abs(m.position[1] - p[1]) < 1e-6:
                shifted.append(Detection(m.id, d.corners))
    if shifted:
        e = loc.process_detections(shifted).estimates["planar"]
        assert not e.ok or e.base[0] < -1.0 + 0.2
    # directly: the sanity check on an estimate outside the floor and one inside a wall
    from robotatfactory.localization.estimators import PoseEstimate, sanity

    est = PoseEstimate("planar", True, base=(1.2, 0.0, 0.0), cov=np.eye(3) * 1e-6, marker_ids=(1, 2), rms_px=0.1,
                       closest_m=0.2)
    assert sanity(est, field, cfg).reason == reasons.OUTSIDE_FIELD
    wall = next(b for b in field.boxes if b.name == "machine_A_center_wall")
    est = PoseEstimate("planar", True, base=(wall.center[0], wall.center[1], 0.0), cov=np.eye(3) * 1e-6,
                       marker_ids=(1, 2), rms_px=0.1, closest_m=0.2)
    assert sanity(est, field, cfg).reason == reasons.INSIDE_WALL
    est = PoseEstimate("planar", True, base=(0.0, 0.0, 0.0), cov=np.eye(3) * 1.0, marker_ids=(1, 2), rms_px=0.1,
                       closest_m=0.2)
    assert sanity(est, field, cfg).reason == reasons.UNCERTAIN
    est = PoseEstimate("planar", True, base=(0.0, float("nan"), 0.0), cov=np.eye(3) * 1e-6, marker_ids=(1, 2))
    assert sanity(est, field, cfg).reason == reasons.NOT_FINITE


def test_a_prior_seeds_the_planar_fit(field, robot):
    """A prior (e.g. the filter's pose) among the seeds leads to the same answer."""
    loc = FrameLocalizer(field, robot)
    pose = (0.1, 0.08, 0.3)
    dets = _detections(field, robot, pose, 0.2, np.random.default_rng(5))
    obs = observe(dets, field, loc.K, loc.T_cam_base, loc.cfg)
    a = planar_fit(obs, field, loc.K, loc.T_base_cam, loc.cfg)
    b = planar_fit(obs, field, loc.K, loc.T_base_cam, PoseConfig(refine_seeds=1),
                   prior=(pose[0] + 0.03, pose[1] - 0.02, pose[2] + 0.1))
    assert a.ok and b.ok
    np.testing.assert_allclose(a.base, b.base, atol=1e-6)


def test_jacobians_match_finite_differences(field, robot):
    from robotatfactory.localization.estimators import PlanarModel, _exp_left, _jac6, _planar_from_cam

    K = robot.camera.K
    T_bc = robot.camera.base_to_optical()
    pose = (0.1, 0.08, 0.3)
    T = camera_world_pose(robot.camera, pose)
    vis = visible_markers(field, robot.camera, T)
    assert len(vis) >= 3
    P = np.concatenate([field.marker(v.id).corners for v in vis])
    uv, J = _jac6(T, P, K)
    h = 1e-7
    for i in range(6):
        d = np.zeros(6)
        d[i] = h
        uv2, _ = _jac6(_exp_left(T, d), P, K)
        np.testing.assert_allclose(J[:, i], (uv2 - uv) / h, rtol=1e-4, atol=1e-3)
    model = PlanarModel(K, T_bc)
    r, Jp = model.residuals(np.array(pose), P, np.zeros((len(P), 2)))
    for i in range(3):
        d = np.zeros(3)
        d[i] = h
        r2, _ = model.residuals(np.array(pose) + d, P, np.zeros((len(P), 2)))
        np.testing.assert_allclose(Jp[:, i], (r2 - r) / h, rtol=1e-4, atol=1e-3)
    np.testing.assert_allclose(r, uv, atol=1e-9)  # both models project alike
    A = np.random.default_rng(0).normal(size=(6, 6))
    C = A @ A.T * 1e-4
    T_cb = inv(T_bc)
    base, cov = _planar_from_cam(T, C, T_cb)
    G = np.zeros((3, 6))
    for i in range(6):
        d = np.zeros(6)
        d[i] = h
        b = matrix_se2(_exp_left(T, d) @ T_cb)
        G[:, i] = [(b[0] - base[0]) / h, (b[1] - base[1]) / h, wrap_angle(b[2] - base[2]) / h]
    np.testing.assert_allclose(cov, G @ C @ G.T, atol=1e-10)
