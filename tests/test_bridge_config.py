"""The bridge's settings (robotatfactory.ros.config): defaults, the generated YAML file, the robot file and the
calibration under them, validation messages. Pure."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from robotatfactory.errors import ConfigError
from robotatfactory.ros.config import load_config
from robotatfactory.settings import parse_set

ROOT = Path(__file__).resolve().parents[1]


def test_config_bridge_yaml_is_the_defaults_generated_from_the_settings():
    from robotatfactory.ros.config import HEADER, BridgeSettings
    from robotatfactory.settings import to_yaml

    assert (ROOT / "config" / "bridge.yaml").read_text() == to_yaml(BridgeSettings(), HEADER), \
        "config/bridge.yaml is out of date: raf bridge --print-params --defaults > config/bridge.yaml"
    from_file = load_config(yaml.safe_load((ROOT / "config" / "bridge.yaml").read_text()))
    assert from_file.params == load_config({}).params


def test_defaults_follow_the_robot_spec(robot):
    c = load_config({})
    assert (c.geometry.wheel_radius, c.geometry.track, c.geometry.ticks_per_rev) == \
        (robot.wheel_radius, robot.track, robot.ticks_per_rev)
    assert c.robot.camera == robot.camera and c.robot.lidar == robot.lidar
    assert (c.camera.fx, c.camera.cx, c.camera.cy, c.camera.bottom_up) == \
        (robot.camera.fx, robot.camera.cx, robot.camera.cy, robot.camera.bottom_up)
    assert c.lidar.range_max == 6.0 and c.lidar.period == 0.2 and c.watchdog.timeout == 0.5
    assert c.udp.port == 9810 and c.sim_host == "127.0.0.1" and c.control_period_ms == 40
    assert c.odometry.track == robot.odometry_track and c.stream.max_wheel_speed == 54.4


def test_another_robot_file_brings_its_own_geometry_and_camera(tmp_path, robot):
    """The robot file's values are unset in the settings, so a robot file named by ``robot`` is what the bridge
    runs with (config/bridge.yaml no longer pins SimTwo's values over it), and a value given still wins."""
    import json

    raw = json.loads((ROOT / "src" / "robotatfactory" / "data" / "robot_simtwo.json").read_text())
    raw["wheel_radius"], raw["camera"]["fx"], raw["camera"]["fy"] = 0.04, 300.0, 300.0
    raw["lidar"]["range_max"] = 3.5
    path = tmp_path / "robot_other.json"
    path.write_text(json.dumps(raw))
    from_file = yaml.safe_load((ROOT / "config" / "bridge.yaml").read_text())
    c = load_config({**from_file, "robot": str(path)})
    assert c.robot.wheel_radius == 0.04 and c.robot.camera.fx == 300.0 and c.lidar.range_max == 3.5
    assert c.robot.track == robot.track
    c = load_config({"robot": str(path), "camera": {"fx": 250.0}})
    assert c.robot.camera.fx == 250.0 and c.robot.camera.fy == 300.0


def test_frame_prefix_applies_to_robot_frames_only():
    c = load_config({"frame_prefix": "robot1"})
    assert c.frames["base_link"] == "robot1/base_link" and c.frames["odom"] == "robot1/odom"
    assert c.frames["camera_optical"] == "robot1/camera_optical"
    assert c.frames["map"] == "map" and c.marker_frame(13) == "aruco_13"


@pytest.mark.parametrize("over, names", [
    ({"udp": {"port": 70000}}, "udp.port must be a whole number in [0, 65535]"),
    ({"udp": {"port": "ninety"}}, "udp.port"),
    ({"camera": {"fx": -1}}, "camera.fx must be a number > 0"),
    ({"camera": {"fxx": 300}}, "camera.fxx"),
    ({"camera": {"bottom_up": "yes"}}, "camera.bottom_up must be true or false"),
    ({"camera": {"endpoint": "9899"}}, "camera.endpoint must be a ZMQ endpoint"),
    ({"camera": {"cx": 9000}}, "camera.cx"),
    ({"camera": 3}, "camera"),
    ({"watchdog": {"timeout": 0}}, "watchdog.timeout"),
    ({"lidar": {"xyz": [0, 0]}}, "lidar.xyz must be a list of 3 numbers"),
    ({"camera": {"distortion": [0.1, "x"]}}, "camera.distortion"),
    ({"lidar": {"mode": "burst"}}, "lidar.mode must be one of sweep, cycle"),
    ({"lidar": {"range_min": 7.0}}, "lidar.range_min"),
    ({"lidar": {"delivery_lag": 0.05}}, "lidar.delivery_lag"),
    ({"simulator": {"host": "no such host.invalid"}}, "simulator.host"),
    ({"simulator": {"control": "9812"}}, "simulator.control"),
    ({"frame_prefix": "/robot1"}, "frame_prefix"),
    ({"frames": {"base_link": "base link"}}, "frames.base_link"),
    ({"field": "atlantis"}, "field"),
    ({"robot": "no_such_robot"}, "robot"),
    ({"geometry": {"control_period": 0.0405}}, "geometry.control_period"),
    ({"geometry": {"physics_step": 0.05}}, "geometry.physics_step"),
    ({"diagnostics": {"stale_warn": 3.0, "stale_error": 1.0}}, "diagnostics.stale_error"),
    ({"tf": {"map_to_odom": "yes"}}, "tf.map_to_odom"),
])
def test_bad_values_name_the_setting(over, names):
    with pytest.raises(ConfigError) as e:
        load_config(over)
    assert names in str(e.value)


def test_the_camera_half_in_the_bridge_process_is_ros1_only():
    from robotatfactory.ros.config import check_camera_process

    composed = load_config({"camera": {"process": "bridge"}})
    check_camera_process(composed, "ros1")
    with pytest.raises(ConfigError) as e:
        check_camera_process(composed, "ros2")
    assert str(e.value) == ("camera.process: bridge: ROS 1 only (one node per process there); on ros2 the camera "
                            "runs in a process of its own (camera.process: own)")
    check_camera_process(load_config({}), "ros2")  # its own process (the default)
    check_camera_process(load_config({"camera": {"process": "bridge", "enabled": False}}), "ros2")  # no camera


def test_any_host_and_hostnames():
    assert load_config({"simulator": {"host": "*"}}).sim_host == "*"
    assert load_config({"simulator": {"host": "localhost"}}).sim_host == "127.0.0.1"


def test_parse_set():
    d = parse_set(["udp/port=9811", "camera/enabled=false", "~camera/fx=283.5", "frame_prefix="])
    assert d == {"udp": {"port": 9811}, "camera": {"enabled": False, "fx": 283.5}, "frame_prefix": ""}
    with pytest.raises(ConfigError):
        parse_set(["udp/port"])
    c = load_config(d)
    assert c.udp.port == 9811 and not c.camera.enabled and c.robot.camera.fx == 283.5


def test_flat_params_round_trip():
    c = load_config({"udp": {"port": 9999}})
    flat = c.flat_params()
    assert flat["udp/port"] == 9999 and flat["camera/xyz"] == [0.05, 0.0, 0.1169]
    nested: dict = {}
    for k, v in flat.items():
        d = nested
        *head, last = k.split("/")
        for h in head:
            d = d.setdefault(h, {})
        d[last] = v
    assert load_config(nested).params == c.params


def test_raf_bridge_print_params_and_bad_option(raf_cmd):
    import subprocess

    out = subprocess.run(raf_cmd + ["bridge", "--port", "9999", "--set", "camera/fx=283", "--print-params"],
                         capture_output=True, text=True, check=True).stdout
    p = yaml.safe_load(out)
    assert p["udp"]["port"] == 9999 and p["camera"]["fx"] == 283
    r = subprocess.run(raf_cmd + ["bridge", "--set", "camera/fx=-3", "--print-params"], capture_output=True, text=True)
    assert r.returncode == 2 and "camera.fx" in r.stderr and "Traceback" not in r.stderr
    defaults = subprocess.run(raf_cmd + ["bridge", "--print-params", "--defaults"], capture_output=True, text=True,
                              check=True).stdout
    assert defaults == (ROOT / "config" / "bridge.yaml").read_text()
