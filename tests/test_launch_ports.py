"""The launch files' ports and addresses are the shared constants (robotatfactory.simtwo.ports, raf sim's
control channel at SIMTWO_UDP_PORT + CONTROL_PORT_OFFSET, multi-robot PORT_STRIDE), so a changed constant
cannot leave a launch file behind.

ROS 1's launch/*.launch cannot import Python: their literal defaults are compared with the constants.
launch/ros2/*.launch.py import the constants: read with ``ast`` (``.venv`` has no ROS 2 ``launch``), each
port-valued default is built from names imported from the constants' own modules, with no number written
out, and evaluates to the constant's value. Every port-valued argument is found by its name or its value,
and the number found per file is asserted, so that a parsing mistake cannot pass with nothing checked."""
from __future__ import annotations

import ast
import importlib
import re
import xml.etree.ElementTree as ET
from pathlib import Path

from robotatfactory.sim.control import CONTROL_PORT_OFFSET
from robotatfactory.sim.multirunner import PORT_STRIDE
from robotatfactory.simtwo.ports import (BRIDGE_UDP_PORT, CAMERA_ZMQ_PORT, LOCALHOST, SERVER_UDP_PORT,
                                         SIMTWO_UDP_PORT)

ROOT = Path(__file__).resolve().parents[1]
LAUNCH1 = ROOT / "launch"
LAUNCH2 = LAUNCH1 / "ros2"

PORTS = "robotatfactory.simtwo.ports"
CONTROL = "robotatfactory.sim.control"
SOURCE = {  # a shared name -> the module a launch file imports it from (where it is named once)
    "SIMTWO_UDP_PORT": PORTS, "BRIDGE_UDP_PORT": PORTS, "CAMERA_ZMQ_PORT": PORTS, "SERVER_UDP_PORT": PORTS,
    "LOCALHOST": PORTS, "CONTROL_PORT_OFFSET": CONTROL,
}
CONTROL_PORT = SIMTWO_UDP_PORT + CONTROL_PORT_OFFSET

# argument -> (its default, the shared names it stands for)
EXPECTED = {
    "port": (str(BRIDGE_UDP_PORT), {"BRIDGE_UDP_PORT"}),
    "sim_port": (str(SIMTWO_UDP_PORT), {"SIMTWO_UDP_PORT"}),
    "control_port": (str(CONTROL_PORT), {"SIMTWO_UDP_PORT", "CONTROL_PORT_OFFSET"}),
    "camera_port": (str(CAMERA_ZMQ_PORT), {"CAMERA_ZMQ_PORT"}),
    "server_port": (str(SERVER_UDP_PORT), {"SERVER_UDP_PORT"}),
    "camera": (f"tcp://{LOCALHOST}:{CAMERA_ZMQ_PORT}", {"LOCALHOST", "CAMERA_ZMQ_PORT"}),
    "sim_control": (f"{LOCALHOST}:{CONTROL_PORT}", {"LOCALHOST", "SIMTWO_UDP_PORT", "CONTROL_PORT_OFFSET"}),
    "sim_host": (LOCALHOST, {"LOCALHOST"}),
    "camera_host": (LOCALHOST, {"LOCALHOST"}),
}
# reply_port is a port argument without a constant: 0 replies to the datagram's source port (SimTwo's
# SIMTWO_UDP_PORT, as it sends from the port it listens on)
REPLY_PORT = "reply_port"

# the port-valued arguments (EXPECTED's) each launch file declares; every launch file is listed
COUNT1 = {"bridge": 4, "competition": 5, "localization": 0, "multi_robot": 5, "rviz": 0, "sim": 5, "simtwo": 3}
COUNT2 = {"bridge": 4, "competition": 5, "localization": 0, "sim": 5, "simtwo": 3}

_NUMBERS = {SIMTWO_UDP_PORT, BRIDGE_UDP_PORT, CONTROL_PORT, CAMERA_ZMQ_PORT, SERVER_UDP_PORT}


def _port_like(name: str, default) -> bool:
    """An argument that holds a port or an address: by its name, or by a default that looks like one."""
    if name in EXPECTED or name == REPLY_PORT or name.endswith("port") or name.endswith("host"):
        return True
    return isinstance(default, str) and re.search(r"^\d{2,5}$|:\d+$|^\d+\.\d+\.\d+\.\d+", default) is not None


# ---- ROS 1 -------------------------------------------------------------------------------------------

def _args1(path: Path) -> dict:
    root = ET.parse(path).getroot()
    assert root.tag == "launch", path
    out = {}
    for a in root.findall("arg"):
        assert a.get("value") is None, f"{path.name}: {a.get('name')} is set, not defaulted"
        out[a.get("name")] = a.get("default")
    return out


def test_ros1_launch_files_port_defaults_are_the_constants():
    files = sorted(LAUNCH1.glob("*.launch"))
    assert {p.name.removesuffix(".launch") for p in files} == set(COUNT1), "COUNT1 lists every launch file"
    found = {}
    for path in files:
        name = path.name.removesuffix(".launch")
        args = _args1(path)
        assert args or name == "rviz", f"{path.name}: no <arg> found"
        ports = {k: v for k, v in args.items() if _port_like(k, v)}
        unknown = set(ports) - set(EXPECTED) - {REPLY_PORT}
        assert not unknown, f"{path.name}: port-valued arguments without a constant here: {unknown}"
        if REPLY_PORT in ports:
            assert ports.pop(REPLY_PORT) in ("0", str(SIMTWO_UDP_PORT))
        for k, v in ports.items():
            assert v == EXPECTED[k][0], f"{path.name}: {k} defaults to {v!r}, the constants make {EXPECTED[k][0]!r}"
        found[name] = len(ports)
    assert found == COUNT1
    assert sum(found.values()) == 22


def test_ros1_multi_robot_ports_step_by_port_stride():
    """multi_robot.launch gives robot k robot 1's ports + PORT_STRIDE * (k - 1), as raf sim derives them."""
    root = ET.parse(LAUNCH1 / "multi_robot.launch").getroot()
    steps = 0
    for inc in root.iter("include"):
        values = {a.get("name"): a.get("value") for a in inc.findall("arg")}
        m = re.fullmatch(r"robot(\d)", values.get("ns", ""))
        if not m or not inc.get("file").endswith("/bridge.launch"):
            continue
        k = int(m.group(1))
        for arg in ("port", "camera"):
            added = [int(n) for n in re.findall(r"\+\s*(\d+)", values[arg])]
            assert added == ([PORT_STRIDE * (k - 1)] if k > 1 else []), (k, arg, values[arg])
            steps += len(added)
    assert steps == 6, "robots 2..4, port and camera each"
    text = (LAUNCH1 / "multi_robot.launch").read_text()
    assert re.findall(r"\+ (\d+)\*\(k-1\)", text) == [str(PORT_STRIDE)], "the comment says the stride"


# ---- ROS 2 -------------------------------------------------------------------------------------------

def _imports(tree: ast.Module) -> dict:
    """name -> the module a launch file imports it from (``from M import name``)."""
    return {a.asname or a.name: n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) for a in n.names}


def _declared2(tree: ast.Module) -> dict:
    out = {}
    for c in ast.walk(tree):
        if isinstance(c, ast.Call) and getattr(c.func, "id", None) == "DeclareLaunchArgument":
            out[c.args[0].value] = next((k.value for k in c.keywords if k.arg == "default_value"), None)
    return out


def _literal_ports(node) -> list:
    """Numbers (and loopback addresses) written out in ``node``: constants with a port's value in them."""
    bad = []
    for n in ast.walk(node):
        if isinstance(n, ast.Constant) and not isinstance(n.value, bool) and isinstance(n.value, (int, str)):
            text = str(n.value)
            if any(re.search(rf"(?<!\d){p}(?!\d)", text) for p in _NUMBERS) or re.search(r"127\.\d+\.\d+\.\d+", text):
                bad.append(n.value)
    return bad


def test_ros2_launch_files_port_defaults_are_the_named_constants():
    files = sorted(LAUNCH2.glob("*.launch.py"))
    assert {p.name.removesuffix(".launch.py") for p in files} == set(COUNT2), "COUNT2 lists every launch file"
    found = {}
    for path in files:
        name = path.name.removesuffix(".launch.py")
        tree = ast.parse(path.read_text(), filename=path.name)
        imported = _imports(tree)
        args = _declared2(tree)
        assert args, f"{path.name}: no DeclareLaunchArgument found"
        ports = {k: d for k, d in args.items()
                 if _port_like(k, d.value if isinstance(d, ast.Constant) else None)}
        unknown = set(ports) - set(EXPECTED) - {REPLY_PORT}
        assert not unknown, f"{path.name}: port-valued arguments without a constant here: {unknown}"
        if REPLY_PORT in ports:
            d = ports.pop(REPLY_PORT)
            assert isinstance(d, ast.Constant) and d.value == "0", f"{path.name}: reply_port"
        for k, d in ports.items():
            want, names = EXPECTED[k]
            used = {n.id for n in ast.walk(d) if isinstance(n, ast.Name)} - {"str"}
            assert used == names, f"{path.name}: {k}'s default is built from {used or 'no name'}, not {names}"
            assert not _literal_ports(d), f"{path.name}: {k}'s default writes out {_literal_ports(d)}"
            for n in used:
                assert imported.get(n) == SOURCE[n], f"{path.name}: {n} is not imported from {SOURCE[n]}"
            values = {n: getattr(importlib.import_module(SOURCE[n]), n) for n in used}
            got = eval(compile(ast.Expression(d), path.name, "eval"), {"__builtins__": {"str": str}}, values)
            assert got == want, f"{path.name}: {k} defaults to {got!r}, the constants make {want!r}"
        found[name] = len(ports)
    assert found == COUNT2
    assert sum(found.values()) == 17


def test_ros2_launch_files_write_no_port_out():
    """Apart from the docstring's examples (checked below), no port number or loopback address is written out
    in launch/ros2: descriptions and command lines say the names too."""
    for path in sorted(LAUNCH2.glob("*.launch.py")):
        tree = ast.parse(path.read_text(), filename=path.name)
        body = tree.body[1:] if ast.get_docstring(tree) else tree.body
        bad = [v for node in body for v in _literal_ports(node)]
        assert not bad, f"{path.name} writes out {bad}"


def test_examples_in_launch_files_use_the_constants():
    """Endpoints in comments and docstrings (e.g. camera:=tcp://192.168.1.20:9899) are the defaults' ports."""
    seen = 0
    for path in sorted(LAUNCH1.glob("*.launch")) + sorted(LAUNCH2.glob("*.launch.py")):
        text = path.read_text()
        for port in re.findall(r"tcp://[\w.\-]+:(\d+)", text):
            assert int(port) == CAMERA_ZMQ_PORT, f"{path.name}: tcp://...:{port}"
            seen += 1
        for host in re.findall(r"(?<![\d.])127\.\d+\.\d+\.\d+", text):
            assert host == LOCALHOST, f"{path.name}: {host}"
    assert seen >= 2, "bridge.launch's and bridge.launch.py's example"
