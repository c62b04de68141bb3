"""config/ros2/*.yaml (ROS 2 parameter files) are generated from config/*.yaml (ROS 1) and cannot drift:
regenerating gives the committed files, every leaf of the nodes' defaults is in them with the type of its
default, the values are the ROS 1 files'. The last test loads each file into the real node's parameter
declaration on rclpy (the ROS 2 interpreter, in a subprocess on a private domain)."""
from __future__ import annotations

import math
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml

from robotatfactory.ros.mw.base import flatten
from robotatfactory.ros.params2 import NODES, render, scalar, tree

ROOT = Path(__file__).resolve().parents[1]
KINDS = sorted(NODES)


def _committed(kind: str) -> dict:
    doc = yaml.safe_load(NODES[kind].target.read_text())
    assert list(doc) == [f"/**/{NODES[kind].node}"], "one node, matched in any namespace"
    assert list(doc[f"/**/{NODES[kind].node}"]) == ["ros__parameters"]
    return doc[f"/**/{NODES[kind].node}"]["ros__parameters"]


@pytest.mark.parametrize("kind", KINDS)
def test_regenerating_gives_the_committed_file(kind):
    assert NODES[kind].target.read_text() == render(kind), \
        f"{NODES[kind].target} is out of date: python -m robotatfactory.ros.params2 --write"


def test_check_option_agrees():
    r = subprocess.run([sys.executable, "-m", "robotatfactory.ros.params2", "--check"], cwd=ROOT,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr


@pytest.mark.parametrize("kind", KINDS)
def test_every_default_leaf_is_present_with_its_type(kind):
    # every leaf that has a value (an unset one, e.g. the agent's drive.* from the robot file, is declared unset)
    defaults = {k: v for k, v in flatten(NODES[kind].defaults(), ".").items() if v is not None}
    got = flatten(_committed(kind), ".")
    assert set(defaults) <= set(got), f"missing: {sorted(set(defaults) - set(got))}"
    for key, d in defaults.items():
        v = got[key]
        if isinstance(d, bool) or isinstance(d, str):
            assert type(v) is type(d), (key, v, d)
        elif isinstance(d, float):
            assert type(v) is float, f"{key}: {v!r} must be written as a real (its default is {d!r})"
        elif isinstance(d, int):
            assert type(v) is int, (key, v, d)
        elif isinstance(d, list) and any(isinstance(x, float) for x in d):
            assert all(type(x) is float for x in v), (key, v)


@pytest.mark.parametrize("kind", KINDS)
def test_values_are_the_ros1_files(kind):
    ros1 = flatten(yaml.safe_load(NODES[kind].source.read_text()), ".")
    got = flatten(_committed(kind), ".")
    assert ros1, "the ROS 1 file has values"
    for key, v in ros1.items():
        if v == {}:  # an empty section (every setting in it unset): nothing to write
            continue
        assert key in got, key
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            assert got[key] == pytest.approx(v, rel=0, abs=0), key
        elif isinstance(v, list):
            assert [float(x) for x in got[key]] == [float(x) for x in v], key
        else:
            assert got[key] == v, key
    # and where the ROS 1 file says nothing, the node's default
    defaults = {k: v for k, v in flatten(NODES[kind].defaults(), ".").items() if v is not None}
    for key in set(defaults) - set(ros1):
        assert got[key] == defaults[key], key


def test_tree_is_the_defaults_updated_by_the_ros1_file():
    t = tree("bridge")
    assert t["udp"]["port"] == 9810 and t["stream"]["takeover_after"] == 2.0 and t["frame_prefix"] == ""
    assert t["stream"]["max_wheel_speed"] is None and t["camera"]["fx"] is None  # unset: the robot file's
    assert set(t) == set(NODES["bridge"].defaults())


@pytest.mark.parametrize("value", [1e-9, 1e-4, 0.5, 3.0, 1e20, -2.5e-7, 60.0])
def test_reals_are_written_so_both_parsers_read_a_real(value):
    text = scalar(value)
    back = yaml.safe_load(f"v: {text}")["v"]
    assert type(back) is float and math.isclose(back, value, rel_tol=1e-15)


@pytest.mark.parametrize("value", ["none", "true", "", "127.0.0.1:9812", "tcp://127.0.0.1:9899", "/clock", "1.5"])
def test_strings_stay_strings(value):
    assert yaml.safe_load(f"v: {scalar(value)}")["v"] == value


def _ros2_python() -> str:
    import importlib.util

    if importlib.util.find_spec("rclpy") is not None:
        return sys.executable
    py = ROOT / ".venv-ros2" / "bin" / "python"
    assert py.exists(), "the ROS 2 environment is missing: scripts/bootstrap.sh builds .venv-ros2"
    return str(py)


LOADER = textwrap.dedent("""
    import json, sys
    from robotatfactory.ros.mw import ros2
    from robotatfactory.ros.params2 import NODES
    kind, path = sys.argv[1], sys.argv[2]
    n = ros2.init_node(NODES[kind].node, argv=["x", "--ros-args", "--params-file", path], namespace="robot1")
    try:
        if kind == "bridge":
            from robotatfactory.ros.config import default_params, describe_param, load_config
            got = n.params(default_params(), describe_param)
            load_config(got)
        elif kind == "agent":
            from robotatfactory.ros.agent_node import config_from_params, node_params
            got = node_params(n)
            config_from_params(got)
        else:
            from robotatfactory.localization.config import from_dict
            from robotatfactory.ros.localization_node import node_params
            got = node_params(n)
            from_dict(got)
        print(json.dumps(got))
    finally:
        n.destroy()
        import rclpy
        rclpy.try_shutdown()
""")


@pytest.mark.ros
@pytest.mark.parametrize("kind", KINDS)
def test_the_file_loads_into_the_ros2_node(kind, tmp_path):
    """The committed file, with one value changed, given to the node as ``--params-file`` in namespace robot1:
    every parameter is accepted with its declared type and the node reads the changed value."""
    import json

    from robotatfactory.ros.master import PrivateDomain

    doc = yaml.safe_load(NODES[kind].target.read_text())
    params = doc[f"/**/{NODES[kind].node}"]["ros__parameters"]
    if kind == "bridge":
        params["udp"]["port"] = 9999
    elif kind == "agent":
        params["dock"]["place_speed"] = 0.12
    else:
        params["node"]["log_period"] = 7.0
    f = tmp_path / "p.yaml"
    f.write_text(yaml.safe_dump(doc))
    with PrivateDomain() as dom:
        r = subprocess.run([_ros2_python(), "-c", LOADER, kind, str(f)], env=dom.env(), cwd=ROOT,
                           capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-3000:]
    got = json.loads(r.stdout.strip().splitlines()[-1])
    expect = tree(kind)
    if kind == "bridge":
        assert got["udp"]["port"] == 9999
        expect["udp"]["port"] = 9999
    elif kind == "agent":
        assert got["dock"]["place_speed"] == 0.12 and got["drive"]["k_heading"] is None  # unset: declared unset
        expect["dock"]["place_speed"] = 0.12
    else:
        assert got["node"]["log_period"] == 7.0
        expect["node"]["log_period"] = 7.0
    assert got == json.loads(json.dumps(expect))
