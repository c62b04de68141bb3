"""The localization's one settings object (localization/config.py and its sections): config/localization.yaml
generated from it, one validation (settings.build) whose errors name the setting's path and what it allows,
filled alike from a YAML file, --set, the node's ROS parameters and the competition experiment's --localize."""
import subprocess
import sys

import pytest
import yaml

from robotatfactory.errors import ConfigError
from robotatfactory.localization import config as lc
from robotatfactory.localization.config import HEADER, LocalizationConfig, from_dict, load_config
from robotatfactory.localization.detect import DetectorConfig, MarkerDetector
from robotatfactory.settings import build, descriptions, parse_set, to_yaml, tree


def test_config_localization_yaml_is_the_defaults_generated_from_the_settings():
    assert lc.DEFAULT_FILE.read_text() == to_yaml(LocalizationConfig(), HEADER), \
        "config/localization.yaml is out of date: raf localize --print-params --defaults > config/localization.yaml"
    assert load_config(lc.DEFAULT_FILE) == load_config() == LocalizationConfig()
    assert from_dict(lc.read_yaml(lc.DEFAULT_FILE)) == LocalizationConfig()


def test_every_setting_says_what_it_is_and_numbers_say_their_range():
    d = descriptions(LocalizationConfig)
    assert "ekf.history_s" in d and "scan_match.outlier_m" in d and "topics.pose" in d and "calibration" in d
    for path, (doc, _rng) in d.items():
        assert doc, f"{path} has no description"
    assert d["scan_match.min_inlier_share"][1] == (0.0, 1.0)
    assert d["detector.adaptive_win_min"][1][0] == 3  # OpenCV asserts it
    assert "one of planar, all_pnp, closest_checked" in d["node.filter_method"][0]
    # set in code, not settings: the field file's dictionary, the robot file's track
    assert "detector.dictionary" not in d and "ekf.track_m" not in d


@pytest.mark.parametrize("bad, message", [
    ({"nonsense": 1}, r"unknown setting\(s\) nonsense; known: field"),
    ({"pose": {"sigma_min_pix": 0.1}}, r"unknown setting\(s\) pose.sigma_min_pix; known in pose: sigma_min_px"),
    ({"pose": {"sigma_min_px": "small"}}, r"pose.sigma_min_px must be a number > 0, got 'small'"),
    ({"pose": {"sigma_min_px": 0}}, r"pose.sigma_min_px must be a number > 0, got 0"),
    ({"ekf": {"history_s": True}}, r"ekf.history_s must be a number > 0, got True"),
    ({"ekf": {"reinit_after_gated": 2.5}}, r"ekf.reinit_after_gated must be a whole number >= 1, got 2.5"),
    ({"ekf": {"track_m": 0.14}}, r"ekf.track_m is not a setting"),
    ({"scan_match": {"outlier_m": 0}}, r"scan_match.outlier_m must be a number > 0, got 0"),
    ({"scan_match": {"min_inlier_share": 1.5}}, r"scan_match.min_inlier_share must be a number in \(0, 1\]"),
    ({"scan_match": {"enabled": "no"}}, r"scan_match.enabled must be true or false"),
    ({"beacons": {"min_points": 1}}, r"beacons.min_points must be a whole number >= 2, got 1"),
    ({"node": {"filter_method": "magic"}},
     r"node.filter_method must be one of planar, all_pnp, closest_checked, got 'magic'"),
    ({"node": {"camera_pose_method": "planar"}}, r"node.camera_pose_method must be one of closest, closest_checked"),
    ({"node": {"initial_pose": "here"}}, r"node.initial_pose must be one of none, start"),
    ({"node": {"diagnostics_period": 0}}, r"node.diagnostics_period must be a number > 0"),
    ({"node": {"max_image_age_s": 1.0}}, r"unknown setting\(s\) node.max_image_age_s"),
    ({"detector": {"corner_refinement": "magic"}},
     r"detector.corner_refinement must be one of none, subpix, contour, apriltag, got 'magic'"),
    ({"detector": {"adaptive_win_min": 2}}, r"detector.adaptive_win_min must be a whole number >= 3, got 2"),
    ({"detector": {"adaptive_win_min": 21}}, r"detector.adaptive_win_max must be at least detector.adaptive_win_min"),
    ({"detector": {"dictionary": "DICT_4X4_50"}}, r"detector.dictionary is not a setting"),
    ({"detector": {"minDistanceToBorder": 2}}, r"unknown setting\(s\) detector.minDistanceToBorder"),
    ({"detector": {"extra": {"noSuchParameter": 3}}}, r"detector.extra.noSuchParameter: not a cv2.aruco"),
    ({"detector": {"extra": {"minDistanceToBorder": 2.5}}},
     r"detector.extra.minDistanceToBorder must be of OpenCV's type for it \(int\), got 2.5"),
    ({"detector": {"extra": 3}}, r"detector.extra must be a mapping"),
    ({"detector": 3}, r"detector: expected a mapping"),
    ({"topics": {"pose": ""}}, r"topics.pose must be a name, got ''"),
    ({"topics": {"unknown": "x"}}, r"unknown setting\(s\) topics.unknown; known in topics: image"),
    ({"frames": "map"}, r"frames: expected a mapping"),
    ({"frames": {"odom": 3}}, r"frames.odom must be a str, got 3"),
])
def test_bad_settings_are_errors_naming_the_setting_and_what_is_allowed(bad, message):
    with pytest.raises(ConfigError, match=message):
        from_dict(bad)


def test_set_takes_dots_or_slashes_and_the_tree_round_trips():
    given = parse_set(["ekf.history_s=2", "node/filter_method=all_pnp", "detector.extra.minDistanceToBorder=2",
                       "pose.lone_marker_max_distance_m=0.6"])
    cfg = load_config(overrides=given)
    assert cfg.ekf.history_s == 2.0 and isinstance(cfg.ekf.history_s, float)
    assert cfg.node.filter_method == "all_pnp" and cfg.pose.lone_marker_max_distance_m == 0.6
    assert build(LocalizationConfig, tree(cfg)) == cfg
    assert yaml.safe_load(to_yaml(cfg))["detector"]["extra"] == {"minDistanceToBorder": 2}


def test_detector_extra_takes_opencv_parameters_by_name():
    extra = {"minDistanceToBorder": 2, "detectInvertedMarker": True}
    cfg = from_dict({"detector": {"adaptive_win_max": 15, "extra": extra}}).detector
    assert cfg.adaptive_win_max == 15 and cfg.extra == extra and cfg.extra is not extra
    det = MarkerDetector(cfg)
    assert det.cfg.extra["minDistanceToBorder"] == 2
    assert DetectorConfig().extra == {} and DetectorConfig().extra is not DetectorConfig().extra


def test_frame_prefix_and_methods():
    cfg = from_dict({"frame_prefix": "robot1", "node": {"filter_method": "all_pnp"}})
    assert cfg.frame("base_link") == "robot1/base_link" and cfg.frame("map") == "map"
    assert cfg.node.methods() == ("closest", "all_pnp")
    assert from_dict({"node": {"all_methods": True}}).node.methods() == ("closest", "closest_checked", "all_pnp",
                                                                          "planar")


def test_a_missing_file_is_a_user_error(tmp_path):
    with pytest.raises(ConfigError):
        load_config(tmp_path / "nope.yaml")
    p = tmp_path / "list.yaml"
    p.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError):
        load_config(p)


def test_the_node_declares_every_setting_with_its_description_and_range():
    from robotatfactory.ros.localization_node import default_params, describe_param

    params = default_params()
    assert build(LocalizationConfig, params) == LocalizationConfig()
    assert "extra" not in params["detector"]  # OpenCV's names: declared when given
    assert describe_param("scan_match.outlier_m")[1] == (0.0, 1e300)
    assert describe_param("node.filter_method")[0].startswith("the camera fixes the EKF uses")
    assert "minDistanceToBorder" in describe_param("detector.extra.minDistanceToBorder")[0]


def test_raf_localize_reads_a_config_file_then_options_then_set(tmp_path):
    cfg = tmp_path / "loc.yaml"
    cfg.write_text("ekf:\n  history_s: 2.5\n  reinit_after_s: 4.0\nframe_prefix: robot2\n")
    r = subprocess.run([sys.executable, "-m", "robotatfactory", "localize", "--config", str(cfg), "--frame-prefix",
                        "robot1", "--set", "ekf.history_s=2", "--set", "detector/extra/minDistanceToBorder=2",
                        "--print-params"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    got = from_dict(yaml.safe_load(r.stdout))
    assert (got.ekf.history_s, got.ekf.reinit_after_s, got.frame_prefix) == (2.0, 4.0, "robot1")
    assert got.detector.extra == {"minDistanceToBorder": 2}
    r = subprocess.run([sys.executable, "-m", "robotatfactory", "localize", "--set", "scan_match.outlier_m=0",
                        "--print-params"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "scan_match.outlier_m must be a number > 0" in r.stderr
