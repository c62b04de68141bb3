"""The bridge's parameters (robotatfactory.ros.config): defaults, the YAML file, validation messages. Pure."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from robotatfactory.errors import ConfigError
from robotatfactory.ros.config import load_config
from robotatfactory.settings import parse_set

ROOT = Path(__file__).resolve().parents[1]


def test_yaml_file_equals_the_code_defaults():
    from_file = load_config(yaml.safe_load((ROOT / "config" / "bridge.yaml").read_text()))
    assert from_file.params == load_config({}).params


def test_defaults_follow_the_robot_spec(robot):
    c = load_config({})
    assert (c.wheel_radius, c.track, c.ticks_per_rev) == (robot.wheel_radius, robot.track, robot.ticks_per_rev)
    assert (c.fx, c.cx, c.cy, c.bottom_up) == (robot.camera.fx, robot.camera.cx, robot.camera.cy, robot.camera.bottom_up)
    assert c.lidar_range_max == 6.0 and c.lidar_period == 0.2 and c.watchdog_timeout == 0.5
    assert c.port == 9810 and c.sim_host == "127.0.0.1" and c.control_period_ms == 40


def test_frame_prefix_applies_to_robot_frames_only():
    c = load_config({"frame_prefix": "robot1"})
    assert c.frames["base_link"] == "robot1/base_link" and c.frames["odom"] == "robot1/odom"
    assert c.frames["camera_optical"] == "robot1/camera_optical"
    assert c.frames["map"] == "map" and c.marker_frame(13) == "aruco_13"


@pytest.mark.parametrize("over, names", [
    ({"udp": {"port": 70000}}, "~udp/port"),
    ({"udp": {"port": "ninety"}}, "~udp/port"),
    ({"camera": {"fx": -1}}, "~camera/fx"),
    ({"camera": {"fxx": 300}}, "~camera/fxx"),
    ({"camera": {"bottom_up": "yes"}}, "~camera/bottom_up"),
    ({"camera": {"endpoint": "9899"}}, "~camera/endpoint"),
    ({"camera": {"cx": 9000}}, "~camera/cx"),
    ({"camera": 3}, "~camera"),
    ({"watchdog": {"timeout": 0}}, "~watchdog/timeout"),
    ({"lidar": {"xyz": [0, 0]}}, "~lidar/xyz"),
    ({"lidar": {"mode": "burst"}}, "~lidar/mode"),
    ({"lidar": {"range_min": 7.0}}, "~lidar/range_min"),
    ({"simulator": {"host": "no such host.invalid"}}, "~simulator/host"),
    ({"frame_prefix": "/robot1"}, "~frame_prefix"),
    ({"frames": {"base_link": "base link"}}, "~frames/base_link"),
    ({"field": "atlantis"}, "~field"),
    ({"geometry": {"control_period": 0.0405}}, "~geometry/control_period"),
    ({"diagnostics": {"stale_warn": 3.0, "stale_error": 1.0}}, "~diagnostics/stale_error"),
    ({"tf": {"map_to_odom": "yes"}}, "~tf/map_to_odom"),
])
def test_bad_values_name_the_parameter(over, names):
    with pytest.raises(ConfigError) as e:
        load_config(over)
    assert names in str(e.value)


def test_any_host_and_hostnames():
    assert load_config({"simulator": {"host": "*"}}).sim_host == "*"
    assert load_config({"simulator": {"host": "localhost"}}).sim_host == "127.0.0.1"


def test_parse_set():
    d = parse_set(["udp/port=9811", "camera/enabled=false", "~camera/fx=283.5", "frame_prefix="])
    assert d == {"udp": {"port": 9811}, "camera": {"enabled": False, "fx": 283.5}, "frame_prefix": ""}
    with pytest.raises(ConfigError):
        parse_set(["udp/port"])
    c = load_config(d)
    assert c.port == 9811 and not c.camera_enabled and c.fx == 283.5


def test_flat_params_round_trip():
    c = load_config({"udp": {"port": 9999}})
    flat = c.flat_params()
    assert flat["udp/port"] == 9999 and flat["camera/xyz"] == [0.05, 0.0, 0.1165]
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
    assert r.returncode == 2 and "~camera/fx" in r.stderr and "Traceback" not in r.stderr
