"""Detection on synthetic images: markers rendered into the camera view by warping
cv2.aruco.generateImageMarker images with their homographies (robotatfactory.localization.synth)."""
import math

import numpy as np
import pytest

from robotatfactory.localization.detect import DetectorConfig, MarkerDetector
from robotatfactory.localization.geometry import wrap_angle
from robotatfactory.localization.pipeline import FrameLocalizer
from robotatfactory.localization.synth import SceneRenderer, camera_world_pose, visible_markers

POSES = [(-0.725, -0.4, math.pi / 2), (0.1, 0.08, 0.3), (0.55, -0.25, 2.5), (-0.2, 0.25, -2.0)]


@pytest.fixture(scope="module")
def robot(scene_camera_robot):
    """The detector's test camera: the SimTwo scene's numbers, fixed here so that a measured update of the robot
    file's camera does not move the poses' markers under the tests. (At the robot file's 29.64 deg marker 58 in
    the second pose, 0.21 m away, shows a bottom border 2-3 px thick after the blur and is missed, by OpenCV's
    default parameters too.)"""
    return scene_camera_robot


@pytest.fixture(scope="module")
def renderer(field, robot):
    return SceneRenderer(field, robot.camera)


@pytest.fixture(scope="module")
def images(renderer):
    rng = np.random.default_rng(0)
    return [renderer.render(p, blur_sigma=0.5, noise_sigma=2.0, rng=rng) for p in POSES]


def _corner_errors(field, robot, images, cfg):
    det = MarkerDetector(cfg)
    close, found, expected = [], 0, 0
    for pose, img in zip(POSES, images):
        truth = {v.id: v for v in visible_markers(field, robot.camera, camera_world_pose(robot.camera, pose))}
        dets = det.detect(img)
        ids = [d.id for d in dets]
        assert set(ids) <= set(truth), f"detected markers that are not in view: {set(ids) - set(truth)}"
        assert len(ids) == len(set(ids))
        for d in dets:
            e = np.linalg.norm(d.corners - truth[d.id].corners, axis=1)
            if truth[d.id].distance < 0.3:
                close.extend(e)
        near = [i for i, v in truth.items() if v.distance < 0.3]
        expected += len(near)
        found += len(set(near) & set(ids))
    return np.array(close), found, expected


def test_detects_the_close_markers_with_subpixel_corners(field, robot, images):
    close, found, expected = _corner_errors(field, robot, images, DetectorConfig())
    assert expected >= 5 and found == expected  # every marker closer than 0.3 m is found
    assert np.sqrt(np.mean(close ** 2)) < 0.5  # pixels
    assert np.max(close) < 1.2


def test_subpixel_refinement_beats_none(field, robot, images):
    sub, _, _ = _corner_errors(field, robot, images, DetectorConfig(corner_refinement="subpix"))
    raw, _, _ = _corner_errors(field, robot, images, DetectorConfig(corner_refinement="none"))
    assert np.sqrt(np.mean(sub ** 2)) < 0.7 * np.sqrt(np.mean(raw ** 2))


def test_the_image_pipeline_recovers_the_pose(field, robot, images):
    loc = FrameLocalizer(field, robot)
    for pose, img in zip(POSES, images):
        res = loc.process(img)
        e = res.estimates["planar"]
        assert e.ok, e.reason
        assert math.hypot(e.base[0] - pose[0], e.base[1] - pose[1]) < 0.005
        assert abs(wrap_angle(e.base[2] - pose[2])) < math.radians(0.5)
        assert res.detect_ms > 0 and res.pose_ms > 0


def test_empty_and_garbage_images(field, robot):
    loc = FrameLocalizer(field, robot)
    rng = np.random.default_rng(1)
    for img in (np.zeros((480, 640, 3), np.uint8), rng.integers(0, 256, (480, 640, 3), dtype=np.uint8),
                np.zeros((0, 0), np.uint8), np.full((480, 640), 200, np.uint8)):
        res = loc.process(img)
        assert res.observations == [] and not res.estimates["planar"].ok
    assert loc.counts["no_markers"] == 4


def test_bad_detector_settings_are_user_errors():
    from robotatfactory.errors import ConfigError
    from robotatfactory.settings import build

    with pytest.raises(ConfigError):
        MarkerDetector(DetectorConfig(dictionary="DICT_9X9_7"))  # the field's dictionary, set in code
    with pytest.raises(ConfigError, match="detector.corner_refinement must be one of none, subpix"):
        build(DetectorConfig, {"corner_refinement": "magic"}, "detector")
    with pytest.raises(ConfigError, match="detector.extra.noSuchParameter: not a cv2.aruco.DetectorParameters"):
        build(DetectorConfig, {"extra": {"noSuchParameter": 3}}, "detector")
    with pytest.raises(ConfigError, match="detector.extra.noSuchParameter"):  # built in code: checked when used
        MarkerDetector(DetectorConfig(extra={"noSuchParameter": 3}))
    cfg = build(DetectorConfig, {"adaptive_win_max": 15, "extra": {"minDistanceToBorder": 2}}, "detector")
    assert cfg.adaptive_win_max == 15 and cfg.extra == {"minDistanceToBorder": 2}
    MarkerDetector(cfg)
