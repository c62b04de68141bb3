"""The agent's one settings object (agent/settings.py) and the typed-settings machinery under it
(settings.build / tree / to_yaml / descriptions): one default and one validation per setting, filled alike
from a YAML file, --set, ROS parameters and the experiment's --agent."""
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from robotatfactory.agent.behaviour import RoundAgent
from robotatfactory.agent.follower import DriveLimits
from robotatfactory.agent.settings import HEADER, AgentSettings, Carrying, agent_settings
from robotatfactory.errors import ConfigError
from robotatfactory.settings import build, descriptions, parse_set, to_yaml, tree

ROOT = Path(__file__).resolve().parents[1]


def test_config_agent_yaml_is_the_defaults_generated_from_the_settings():
    assert (ROOT / "config" / "agent.yaml").read_text() == to_yaml(AgentSettings(), HEADER), \
        "config/agent.yaml is out of date: raf agent --print-params --defaults > config/agent.yaml"
    loaded = yaml.safe_load((ROOT / "config" / "agent.yaml").read_text())
    assert build(AgentSettings, loaded) == AgentSettings()


def test_every_setting_says_what_it_is_and_numbers_say_their_range():
    d = descriptions(AgentSettings)
    assert "dock.approach_speed" in d and "drive.k_heading" in d and "server.port" in d
    for path, (doc, _rng) in d.items():
        assert doc, f"{path} has no description"
    assert d["server.port"][1] == (1, 65535)
    assert d["dock.approach_speed"][1] == (0.0, 0.5)


def test_values_are_checked_and_errors_name_the_setting_and_what_is_allowed():
    with pytest.raises(ConfigError, match=r"dock.approach_speed must be a number in \(0, 0.5\], got 0"):
        agent_settings({"dock": {"approach_speed": 0}})
    with pytest.raises(ConfigError, match=r"recovery.replans must be a whole number in \[0, 20\], got 2.5"):
        agent_settings({"recovery": {"replans": 2.5}})
    with pytest.raises(ConfigError, match="legs.smooth must be true or false"):
        agent_settings({"legs": {"smooth": "no"}})
    with pytest.raises(ConfigError, match="unknown setting.*carry.speed; known in carry: arcs"):
        agent_settings({"carry": {"speed": 1}})
    with pytest.raises(ConfigError, match="dock: expected a mapping"):
        agent_settings({"dock": 3})
    with pytest.raises(ConfigError, match="must be a number"):
        agent_settings({"max_input_age": float("nan")})
    s = agent_settings({"legs": {"smooth": 0}, "tasks": {"give_up_after": 4}, "carry": {"w_max": 2}})
    assert s.legs.smooth is False and s.tasks.give_up_after == 4 and s.carry.w_max == 2.0
    assert isinstance(s.carry.w_max, float)


def test_set_takes_dots_or_slashes_and_the_tree_round_trips():
    given = parse_set(["dock.approach_speed=0.16", "drive/k_heading=6", "legs.smooth=false"])
    assert given == {"dock": {"approach_speed": 0.16}, "drive": {"k_heading": 6}, "legs": {"smooth": False}}
    s = agent_settings(given)
    assert build(AgentSettings, tree(s)) == s
    assert tree(s)["drive"]["k_heading"] == 6.0 and tree(s)["drive"]["v_max"] is None


def test_the_round_agent_takes_the_settings_whole():
    from robotatfactory.field import load_field
    from robotatfactory.robot import load_robot

    field, robot = load_field(), load_robot()
    default = RoundAgent(field, robot)
    assert default.limits == DriveLimits.from_robot(robot)
    assert default.carry_limits.w_max == Carrying.w_max
    a = RoundAgent(field, robot, agent_settings({"drive": {"v_max": 0.3, "k_heading": 6},
                                                 "carry": {"w_max": 1.2, "back_accel": 0.7},
                                                 "dock": {"approach_speed": 0.08}}))
    assert (a.limits.v_max, a.limits.k_heading) == (0.3, 6.0)
    assert a.carry_limits.w_max == 1.2
    assert default.docker.settings.a_back_carrying == Carrying.back_accel and a.docker.settings.a_back_carrying == 0.7
    assert a.docker.settings.v_dock == 0.08 and a.docker.approach_limits.v_max == 0.08


def test_raf_agent_reads_a_config_file_then_options_then_set(tmp_path):
    cfg = tmp_path / "agent.yaml"
    cfg.write_text("dock:\n  approach_speed: 0.12\n  place_speed: 0.14\nserver:\n  port: 40000\n")
    r = subprocess.run([sys.executable, "-m", "robotatfactory", "agent", "--config", str(cfg), "--server-port",
                        "40001", "--set", "dock.approach_speed=0.16", "--print-params"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    got = build(AgentSettings, yaml.safe_load(r.stdout))
    assert (got.dock.approach_speed, got.dock.place_speed, got.server.port) == (0.16, 0.14, 40001)
    r = subprocess.run([sys.executable, "-m", "robotatfactory", "agent", "--set", "dock.approach_speed=9",
                        "--print-params"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "dock.approach_speed must be a number in (0, 0.5]" in r.stderr
