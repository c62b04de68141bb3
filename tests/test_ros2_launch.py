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
NAMES = ("bridge", "localization", "sim", "competition", "simtwo")


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


# the shared constants a launch file may import (docs/protocol.md's ports, raf sim's control channel offset)
SHARED = ("robotatfactory.simtwo.ports", "robotatfactory.sim.control")


def _shared_names(tree: ast.Module) -> dict:
    """The names the launch file imports from SHARED, with their values."""
    import importlib

    out = {}
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.module in SHARED:
            module = importlib.import_module(node.module)
            out.update({a.asname or a.name: getattr(module, a.name) for a in node.names})
    return out


def _args2(name: str) -> dict:
    """name -> default of the DeclareLaunchArguments: a string (a literal, or built from the shared constants
    with str(), f-strings and +), or the ast node when it is a substitution."""
    tree = _tree(name)
    shared = _shared_names(tree)
    out = {}
    for c in _calls(tree, "DeclareLaunchArgument"):
        d = _kw(c, "default_value")
        if isinstance(d, ast.Constant):
            out[c.args[0].value] = d.value
        elif {n.id for n in ast.walk(d) if isinstance(n, ast.Name)} <= set(shared) | {"str"}:
            value = eval(compile(ast.Expression(d), name, "eval"), {"__builtins__": {"str": str}}, dict(shared))
            assert isinstance(value, str), f"{name}: {c.args[0].value}'s default is no string: {value!r}"
            out[c.args[0].value] = value
        else:
            out[c.args[0].value] = d
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
    for node in ast.walk(tree):  # only the launch system's own modules, the shared constants and the stdlib
        if isinstance(node, ast.ImportFrom):
            assert node.module.split(".")[0] in ("launch", "launch_ros", "ament_index_python") or node.module in SHARED, \
                node.module
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
    from robotatfactory.ros.agent_node import default_params

    return set(flatten(default_params(), "."))


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


# ---- the launch files run against stand-ins of the launch API, compared with roslaunch's resolution -------
# ROS 2's launch package is not installable here, so the test brings stand-ins with the Jazzy signatures of
# what the files use (a wrong keyword is a TypeError), runs generate_launch_description() and evaluates the
# result as `ros2 launch` would with the default arguments: launch configurations set by DeclareLaunchArgument
# defaults and IncludeLaunchDescription's arguments (unscoped: they stay set in the including context),
# GroupAction(scoped=True) copying the context, OpaqueFunction called. The resolved nodes (parameters from
# the parameter file, then the dict) and raf sim's command line must equal roslaunch's resolution of the ROS 1
# twin (roslaunch.config: rosparam load of config/*.yaml, <param> overrides, the raf node's args).

class _Sub:
    def perform(self, ctx):  # noqa: D401 - the stand-in's evaluation
        raise NotImplementedError


def _resolve(v, ctx) -> str:
    if isinstance(v, str):
        return v
    if isinstance(v, _Sub):
        return v.perform(ctx)
    if isinstance(v, (list, tuple)):
        return "".join(_resolve(x, ctx) for x in v)
    raise TypeError(f"cannot resolve {v!r}")


def _stub_modules(prefix: str, share: str) -> dict:
    import os
    import types

    class LaunchConfiguration(_Sub):
        def __init__(self, variable_name, *, default=None):
            self.name, self.default = variable_name, default

        def perform(self, ctx):
            if self.name not in ctx.configs:
                raise AssertionError(f"launch configuration {self.name!r} is not set")
            return ctx.configs[self.name]

    class PathJoinSubstitution(_Sub):
        def __init__(self, substitutions):
            self.parts = substitutions

        def perform(self, ctx):
            return os.path.join(*[_resolve(p, ctx) for p in self.parts])

    class FindPackageShare(_Sub):
        def __init__(self, package):
            assert package == "robotatfactory"

        def perform(self, ctx):
            return share

    class Action:
        def __init__(self, *, condition=None):
            self.condition = condition

    class LaunchDescription:
        def __init__(self, initial_entities=None, *, deprecated_reason=None):
            self.entities = list(initial_entities or [])

    class DeclareLaunchArgument(Action):
        def __init__(self, name, *, default_value=None, description=None, choices=None, **kw):
            super().__init__(**kw)
            self.name, self.default = name, default_value

    class ExecuteProcess(Action):
        def __init__(self, *, cmd, prefix=None, name=None, cwd=None, env=None, additional_env=None, shell=False,
                     sigterm_timeout=None, sigkill_timeout=None, emulate_tty=False, output="log",
                     output_format=None, cached_output=False, log_cmd=False, on_exit=None, respawn=False,
                     respawn_delay=None, respawn_max_retries=-1, **kw):
            super().__init__(**kw)
            self.cmd, self.name, self.env, self.on_exit, self.output = cmd, name, additional_env, on_exit, output

    class Node(ExecuteProcess):
        def __init__(self, *, executable, package=None, name=None, namespace=None, exec_name=None,
                     parameters=None, remappings=None, ros_arguments=None, arguments=None, **kw):
            super().__init__(cmd=[executable, *(arguments or [])], **kw)
            self.package, self.executable, self.node_name, self.namespace = package, executable, name, namespace
            self.parameters = parameters or []

    class IncludeLaunchDescription(Action):
        def __init__(self, launch_description_source, *, launch_arguments=None, **kw):
            super().__init__(**kw)
            self.source, self.arguments = launch_description_source, list(launch_arguments or [])

    class PythonLaunchDescriptionSource:
        def __init__(self, launch_file_path):
            self.path = launch_file_path

    class GroupAction(Action):
        def __init__(self, actions, *, scoped=True, forwarding=True, launch_configurations=None, **kw):
            super().__init__(**kw)
            self.actions, self.scoped, self.forwarding = actions, scoped, forwarding

    class OpaqueFunction(Action):
        def __init__(self, *, function, args=None, kwargs=None, **kw):
            super().__init__(**kw)
            self.function = function

    class Shutdown(Action):
        def __init__(self, *, reason="reason not given", **kw):
            super().__init__(**kw)
            self.reason = reason

    class IfCondition:
        def __init__(self, predicate_expression):
            self.expr = predicate_expression

        def evaluate(self, ctx) -> bool:
            v = _resolve(self.expr, ctx).strip().lower()
            assert v in ("true", "false", "1", "0"), v
            return v in ("true", "1")

    class UnlessCondition(IfCondition):
        def evaluate(self, ctx) -> bool:
            return not super().evaluate(ctx)

    class ParameterValue:
        def __init__(self, value, *, value_type=None):
            self.value, self.value_type = value, value_type

    def get_package_prefix(package_name):
        assert package_name == "robotatfactory"
        return prefix

    mods = {name: types.ModuleType(name) for name in (
        "launch", "launch.actions", "launch.substitutions", "launch.conditions", "launch.launch_description_sources",
        "launch_ros", "launch_ros.actions", "launch_ros.substitutions", "launch_ros.parameter_descriptions",
        "ament_index_python", "ament_index_python.packages")}
    mods["launch"].LaunchDescription = LaunchDescription
    for c in (DeclareLaunchArgument, ExecuteProcess, IncludeLaunchDescription, GroupAction, OpaqueFunction, Shutdown):
        setattr(mods["launch.actions"], c.__name__, c)
    mods["launch.substitutions"].LaunchConfiguration = LaunchConfiguration
    mods["launch.substitutions"].PathJoinSubstitution = PathJoinSubstitution
    mods["launch.conditions"].IfCondition = IfCondition
    mods["launch.conditions"].UnlessCondition = UnlessCondition
    mods["launch.launch_description_sources"].PythonLaunchDescriptionSource = PythonLaunchDescriptionSource
    mods["launch_ros.actions"].Node = Node
    mods["launch_ros.substitutions"].FindPackageShare = FindPackageShare
    mods["launch_ros.parameter_descriptions"].ParameterValue = ParameterValue
    mods["ament_index_python.packages"].get_package_prefix = get_package_prefix
    return mods


class _Ctx:
    def __init__(self, configs):
        self.configs = dict(configs)


def _run_launch(path: Path, ctx: "_Ctx", out: list, mods: dict) -> None:
    """Evaluate a launch file's description in ``ctx``: append ("node", Node, params) / ("process", cmd)."""
    import importlib.util
    import sys

    saved = {k: sys.modules.get(k) for k in mods}
    sys.modules.update(mods)
    try:
        spec = importlib.util.spec_from_file_location(f"_launch_{path.stem.replace('.', '_')}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        ld = module.generate_launch_description()
        _evaluate(ld.entities, ctx, out, mods)
    finally:
        for k, v in saved.items():
            if v is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = v


def _evaluate(entities, ctx, out, mods) -> None:
    import yaml

    A = mods["launch.actions"]
    Node = mods["launch_ros.actions"].Node
    PV = mods["launch_ros.parameter_descriptions"].ParameterValue
    for e in entities:
        if getattr(e, "condition", None) is not None and not e.condition.evaluate(ctx):
            continue
        if isinstance(e, A.DeclareLaunchArgument):
            if e.name not in ctx.configs:
                ctx.configs[e.name] = _resolve(e.default, ctx) if e.default is not None else None
        elif isinstance(e, A.GroupAction):
            _evaluate(e.actions, _Ctx(ctx.configs) if e.scoped else ctx, out, mods)
        elif isinstance(e, A.IncludeLaunchDescription):
            for k, v in e.arguments:  # set in the including context (ros2 launch's SetLaunchConfiguration)
                ctx.configs[k] = _resolve(v, ctx)
            _run_launch(Path(_resolve(e.source.path, ctx)), ctx, out, mods)
        elif isinstance(e, A.OpaqueFunction):
            _evaluate(e.function(ctx) or [], ctx, out, mods)
        elif isinstance(e, Node):
            params: dict = {}
            for p in e.parameters:
                if isinstance(p, dict):
                    for k, v in p.items():
                        if isinstance(v, PV):
                            text = _resolve(v.value, ctx)
                            v = {str: str, int: int, float: float,
                                 bool: lambda t: {"true": True, "false": False}[t.lower()]}[v.value_type](text)
                        params[k] = v
                else:  # a parameter file
                    doc = yaml.safe_load(Path(_resolve(p, ctx)).read_text())
                    (key, body), = doc.items()
                    assert key == f"/**/{e.node_name}"
                    from robotatfactory.ros.mw.base import flatten

                    params.update(flatten(body["ros__parameters"], "."))
            ns = _resolve(e.namespace, ctx) if e.namespace is not None else "/"
            out.append(("node", e, ns, params, {k: _resolve(v, ctx) for k, v in (e.env or {}).items()}))
        elif isinstance(e, A.ExecuteProcess):
            out.append(("process", [_resolve(c, ctx) for c in e.cmd], e.name, e.on_exit))
        else:
            raise AssertionError(f"unknown launch entity {e!r}")


def _roslaunch(name: str) -> tuple[dict, dict]:
    """(nodes by name: (type, namespace, args), params by full name) of launch/NAME.launch, as roslaunch
    resolves it with the default arguments."""
    import os

    import roslaunch.config  # Debian's ROS 1 (.venv): this test runs in the ROS 1 suite

    os.environ["ROS_PACKAGE_PATH"] = os.pathsep.join([str(ROOT), os.environ.get("ROS_PACKAGE_PATH", "")])
    cfg = roslaunch.config.load_config_default([str(ROOT / "launch" / f"{name}.launch")], None, verbose=False)
    nodes = {n.name: (n.type, n.namespace, n.args) for n in cfg.nodes}
    return nodes, {k: p.value for k, p in cfg.params.items()}


def _defaults(node_name: str) -> dict:
    from robotatfactory.ros.mw.base import flatten

    if node_name == "raf_bridge":
        from robotatfactory.ros.config import default_params
    elif node_name == "raf_localization":
        from robotatfactory.ros.localization_node import default_params
    else:
        from robotatfactory.ros.agent_node import default_params
    return flatten(default_params(), ".")


def _same(a, b) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        return float(a) == float(b)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


@pytest.mark.parametrize("name", NAMES)
def test_launch_files_resolve_like_their_ros1_twins(name, tmp_path):
    """Every robotatfactory node with the same namespace and every parameter value roslaunch gives its ROS 1
    twin (and use_sim_time true); raf sim with the same command line."""
    mods = _stub_modules(prefix="/opt/raf_ws/install/robotatfactory", share=str(ROOT))
    out: list = []
    _run_launch(LAUNCH2 / f"{name}.launch.py", _Ctx({}), out, mods)
    nodes1, params1 = _roslaunch(name)
    nodes2 = {e.node_name: (e, ns, params, env) for kind, e, *rest in out if kind == "node"
              for ns, params, env in [rest]}
    own = {n for n, (typ, _, _) in nodes1.items() if typ != "raf"}
    assert set(nodes2) == own | ({"rviz2"} if "rviz2" in nodes2 else set())
    for node_name in own:
        e, ns, params, env = nodes2[node_name]
        typ, ns1, _ = nodes1[node_name]
        assert (e.package, e.executable) == ("robotatfactory", typ) and ns.strip("/") == ns1.strip("/")
        assert env == {"RAF_MIDDLEWARE": "ros2"} and params.pop("use_sim_time") is True
        prefix = f"{ns1.rstrip('/')}/{node_name}/"
        expect = {k[len(prefix):].replace("/", "."): v for k, v in params1.items() if k.startswith(prefix)}
        assert set(expect) <= set(params), (node_name, set(expect) - set(params))
        bad = {k: (params[k], expect[k]) for k in expect if not _same(params[k], expect[k])}
        assert not bad, f"{node_name}: ROS 2 value, ROS 1 value: {bad}"
        # what the ROS 1 file leaves out, the ROS 2 file gives as the node's default (the node's value on ROS 1)
        defaults = _defaults(node_name)
        extra = {k: (params[k], defaults.get(k)) for k in set(params) - set(expect) if not _same(params[k], defaults.get(k))}
        assert not extra, f"{node_name}: not the defaults: {extra}"
    sims = [rest for kind, *rest in out if kind == "process"]
    raf1 = [(n, args) for n, (typ, _, args) in nodes1.items() if typ == "raf"]
    assert len(sims) == len(raf1)
    for (cmd, proc_name, on_exit), (name1, args) in zip(sims, raf1):
        # raf sim, or raf simtwo run: the same process name and command line as roslaunch's
        assert cmd[0] == "/opt/raf_ws/install/robotatfactory/lib/robotatfactory/raf" and proc_name == name1
        assert cmd[1:] == args.split(), f"the same {name1} command line as roslaunch's"
        assert on_exit is not None, f"the launch ends with {name1} (required=true)"
