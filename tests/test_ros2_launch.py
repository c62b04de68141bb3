"""launch/ros2/*.launch.py, checked statically (ROS 2's ``launch`` package has no wheel, so they cannot run
here): parsed with ``ast``, they declare the same arguments with the same defaults as their ROS 1 twins
(launch/*.launch), start the same executables under the same node names, set the same parameters (each one
a parameter the node declares), use parameter files and included launch files that exist, and reference only
arguments they declare. The package files (package.xml, CMakeLists.txt) install what they name."""
from __future__ import annotations

import ast
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAUNCH2 = ROOT / "launch" / "ros2"
NAMES = ("bridge", "localization", "sim", "competition")


# ---- reading the files ------------------------------------------------------------------------------

def _tree(name: str) -> ast.Module:
    return ast.parse((LAUNCH2 / f"{name}.launch.py").read_text(), filename=f"{name}.launch.py")


def _calls(tree, func: str):
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            f = node.func
            if (isinstance(f, ast.Name) and f.id == func) or (isinstance(f, ast.Attribute) and f.attr == func):
                yield node


def _kw(call: ast.Call, name: str):
    return next((k.value for k in call.keywords if k.arg == name), None)


def _strings(node) -> list[str]:
    return [n.value for n in ast.walk(node) if isinstance(n, ast.Constant) and isinstance(n.value, str)]


def _args2(name: str) -> dict:
    """name -> default (a string, or the ast node when it is a substitution) of the DeclareLaunchArguments."""
    out = {}
    for c in _calls(_tree(name), "DeclareLaunchArgument"):
        d = _kw(c, "default_value")
        out[c.args[0].value] = d.value if isinstance(d, ast.Constant) else d
    return out


def _xml(name: str) -> ET.Element:
    return ET.parse(ROOT / "launch" / f"{name}.launch").getroot()


def _args1(name: str) -> dict:
    return {a.get("name"): a.get("default") for a in _xml(name).findall("arg")}


def _nodes2(name: str) -> list[ast.Call]:
    return [c for c in _calls(_tree(name), "Node")]


def _node_params2(call: ast.Call) -> dict:
    """The literal-keyed dict in a Node's parameters=[...] (key -> value node)."""
    params = _kw(call, "parameters")
    out = {}
    for el in (params.elts if params is not None else []):
        if isinstance(el, ast.Dict):
            out.update({k.value: v for k, v in zip(el.keys, el.values)})
    return out


def _cmake_programs() -> set[str]:
    text = (ROOT / "CMakeLists.txt").read_text()
    ros2 = text.split('STREQUAL "2")', 1)[1].split("else()", 1)[0]
    progs = ros2.split("install(PROGRAMS", 1)[1].split("DESTINATION", 1)[0].split()
    return {Path(p).name for p in progs}


# ---- tests -------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", NAMES)
def test_launch_file_defines_a_launch_description(name):
    tree = _tree(name)
    funcs = [n.name for n in tree.body if isinstance(n, ast.FunctionDef)]
    assert "generate_launch_description" in funcs
    assert ast.get_docstring(tree) and f"launch/{name}.launch" in ast.get_docstring(tree), "names its ROS 1 twin"
    for node in ast.walk(tree):  # only the launch system's own modules (and the standard library)
        if isinstance(node, ast.ImportFrom):
            assert node.module.split(".")[0] in ("launch", "launch_ros", "ament_index_python"), node.module
        elif isinstance(node, ast.Import):
            assert all(a.name in ("os", "shlex") for a in node.names)


@pytest.mark.parametrize("name", NAMES)
def test_same_arguments_and_defaults_as_ros1(name):
    a1, a2 = _args1(name), _args2(name)
    assert set(a2) == set(a1), f"only ROS 1: {set(a1) - set(a2)}, only ROS 2: {set(a2) - set(a1)}"
    for k, d1 in a1.items():
        d2 = a2[k]
        if k == "config":  # $(find robotatfactory)/config/X.yaml -> config/ros2/X.yaml of the installed package
            parts = set(_strings(d2))  # PathJoinSubstitution([FindPackageShare("robotatfactory"), "config", ...])
            assert parts == {"robotatfactory", "config", "ros2", Path(d1).name}, parts
            assert (ROOT / "config" / "ros2" / Path(d1).name).is_file()
        else:
            assert d2 == d1, f"{name}: argument {k}: ROS 1 default {d1!r}, ROS 2 {d2!r}"


@pytest.mark.parametrize("name", NAMES)
def test_every_launch_configuration_is_declared(name):
    declared = set(_args2(name))
    used = {c.args[0].value for c in _calls(_tree(name), "LaunchConfiguration") if c.args and isinstance(c.args[0], ast.Constant)}
    used |= {c.args[0].value for c in _calls(_tree(name), "arg") if c.args and isinstance(c.args[0], ast.Constant)}
    used |= {c.args[0].value for c in _calls(_tree(name), "a") if c.args and isinstance(c.args[0], ast.Constant)}
    used |= {c.args[0].value for c in _calls(_tree(name), "typed") if c.args and isinstance(c.args[0], ast.Constant)}
    assert used <= declared, f"undeclared: {used - declared}"


@pytest.mark.parametrize("name", NAMES)
def test_same_executables_and_node_names_as_ros1(name):
    ros1 = {n.get("name"): n for n in _xml(name).iter("node") if n.get("pkg") == "robotatfactory"
            and n.get("type") != "raf"}
    ros2 = {_kw(c, "name").value: c for c in _nodes2(name) if _kw(c, "package").value == "robotatfactory"}
    assert set(ros2) == set(ros1)
    for node_name, c in ros2.items():
        exe = _kw(c, "executable").value
        assert exe == ros1[node_name].get("type")
        assert (ROOT / "nodes" / exe).is_file() and exe in _cmake_programs(), f"{exe} is installed to lib/robotatfactory"
        env = _kw(c, "additional_env")
        assert env is not None and _strings(env) == ["RAF_MIDDLEWARE", "ros2"]


def _declared_params(node_name: str) -> set[str]:
    from robotatfactory.ros.mw.base import flatten

    if node_name == "raf_bridge":
        from robotatfactory.ros.config import default_params

        return set(flatten(default_params(), "."))
    if node_name == "raf_localization":
        from robotatfactory.ros.localization_node import default_params

        return set(flatten(default_params(), "."))
    from dataclasses import fields

    from robotatfactory.ros.agent_node import AgentNodeConfig

    return {f.name for f in fields(AgentNodeConfig)}


@pytest.mark.parametrize("name", NAMES)
def test_same_parameters_as_ros1_and_each_is_declared_by_the_node(name):
    ros1 = {n.get("name"): n for n in _xml(name).iter("node") if n.get("pkg") == "robotatfactory"}
    for c in _nodes2(name):
        if _kw(c, "package").value != "robotatfactory":
            continue
        node_name = _kw(c, "name").value
        p2 = set(_node_params2(c))
        p1 = {p.get("name").replace("/", ".") for p in ros1[node_name].findall("param")}
        assert p2 - {"use_sim_time"} == p1, f"{node_name}: only ROS 1 {p1 - p2}, only ROS 2 {p2 - p1}"
        assert "use_sim_time" in p2
        assert p1 <= _declared_params(node_name), p1 - _declared_params(node_name)


@pytest.mark.parametrize("name", NAMES)
def test_included_launch_files_exist_and_take_the_arguments_given(name):
    ros1_includes = sorted(Path(i.get("file")).name.replace(".launch", "") for i in _xml(name).iter("include")
                           if "rviz" not in i.get("file"))
    seen = []
    for c in _calls(_tree(name), "IncludeLaunchDescription"):
        target = [s for s in _strings(c.args[0]) if s.endswith(".launch.py")]
        assert len(target) == 1 and "ros2" in _strings(c.args[0])
        inc = target[0].replace(".launch.py", "")
        assert (LAUNCH2 / target[0]).is_file()
        seen.append(inc)
        given = _kw(c, "launch_arguments")
        keys = {k.value for k in given.func.value.keys} if given is not None else set()
        assert keys <= set(_args2(inc)), f"{inc} does not declare {keys - set(_args2(inc))}"
        xml_inc = next(i for i in _xml(name).iter("include") if i.get("file").endswith(f"/{inc}.launch"))
        assert keys == {a.get("name") for a in xml_inc.findall("arg")}, inc
    assert sorted(seen) == ros1_includes


def test_sim_runs_raf_sim_with_the_ros1_arguments():
    """raf sim is a process (not a node): the same options as sim.launch's args string."""
    ros1 = next(n for n in _xml("sim").iter("node") if n.get("type") == "raf").get("args")
    opts1 = [w for w in ros1.split() if w.startswith("--")]
    fn = next(n for n in _tree("sim").body if isinstance(n, ast.FunctionDef) and n.name == "_raf_sim")
    opts2 = [s for s in _strings(fn) if s.startswith("--")]
    assert opts2 == opts1
    assert "raf" in _strings(fn) and "lib" in _strings(fn), "the package's raf launcher"
    assert _cmake_programs() >= {"raf", "bridge_node", "localization_node", "agent_node"}


def test_package_xml_builds_with_catkin_on_ros1_and_ament_on_ros2():
    import os

    from catkin_pkg.package import parse_package

    for version, build_type, tool in (("1", "catkin", "catkin"), ("2", "ament_cmake", "ament_cmake")):
        pkg = parse_package(str(ROOT / "package.xml"))
        pkg.evaluate_conditions({**os.environ, "ROS_VERSION": version})
        assert pkg.package_format == 3
        assert pkg.get_build_type() == build_type
        assert tool in [d.name for d in pkg.buildtool_depends if d.evaluated_condition]
    pkg = parse_package(str(ROOT / "package.xml"))
    pkg.evaluate_conditions({**os.environ, "ROS_VERSION": "2"})
    deps = {d.name for d in pkg.exec_depends if d.evaluated_condition}
    assert {"rclpy", "launch_ros", "robotatfactory_msgs", "tf2_msgs"} <= deps and "rospy" not in deps


def _ros2_prefix() -> Path:
    import importlib.util
    import sys

    if importlib.util.find_spec("rclpy") is not None:
        return Path(sys.prefix)
    prefix = ROOT / ".venv-ros2"
    assert (prefix / "bin" / "python").exists(), "the ROS 2 environment is missing: scripts/bootstrap.sh builds .venv-ros2"
    return prefix


@pytest.mark.slow
def test_ament_cmake_build_installs_what_ros2_launch_and_ros2_run_need(tmp_path):
    """What ``colcon build`` does with this package on ROS 2 (ament_cmake: configure, build, install), with the
    ament_cmake of the ROS 2 wheels: the node launchers in lib/robotatfactory, the launch and parameter files
    in share/robotatfactory, the package in the ament index, the Python package importable."""
    import os
    import subprocess

    prefix = _ros2_prefix()
    build, inst = tmp_path / "build", tmp_path / "install"
    env = {**os.environ, "ROS_VERSION": "2", "PATH": f"{prefix / 'bin'}:{os.environ['PATH']}"}
    for cmd in (["cmake", "-S", str(ROOT), "-B", str(build), f"-DCMAKE_PREFIX_PATH={prefix}",
                 f"-DPython3_EXECUTABLE={prefix / 'bin' / 'python'}", f"-DCMAKE_INSTALL_PREFIX={inst}",
                 "-DBUILD_TESTING=OFF"],
                ["cmake", "--build", str(build)], ["cmake", "--install", str(build)]):
        r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, f"{' '.join(cmd)}:\n{r.stdout[-2000:]}\n{r.stderr[-2000:]}"
    for exe in ("bridge_node", "localization_node", "agent_node", "raf"):
        assert os.access(inst / "lib" / "robotatfactory" / exe, os.X_OK), exe
    share = inst / "share" / "robotatfactory"
    for name in NAMES:
        assert (share / "launch" / "ros2" / f"{name}.launch.py").is_file()
    for name in ("bridge", "localization"):
        assert (share / "config" / "ros2" / f"{name}.yaml").read_text() == (ROOT / "config" / "ros2" / f"{name}.yaml").read_text()
    assert (share / "package.xml").is_file()
    assert (inst / "share" / "ament_index" / "resource_index" / "packages" / "robotatfactory").is_file()
    site = next(inst.glob("lib/python3*/site-packages"))
    assert (site / "robotatfactory" / "ros" / "bridge_node.py").is_file()
    assert (site / "robotatfactory" / "data" / "field_rules2026.json").is_file(), "package data installed too"
