"""ROS 2's simulation_interfaces (issue 24): the interface files are the Jazzy release's, byte for byte, and
their type hashes are the released package's; the bridge serves the standard's calls on ROS 2 with the
stand-in (all of them) and SimTwo's subset (through a SimTwo-like simulator here; the real SimTwo in
tests/test_simtwo_real.py); on ROS 1 the project's own ``sim/*`` services serve instead."""
from __future__ import annotations

import hashlib
import json
import math
import re
import socket
import subprocess
import textwrap
import time
from pathlib import Path

import pytest

from rosutil import (Collector, free_port, raf_process, ros_graph, service_names, stop_process,  # noqa: F401
                     test_node, wait_for_service, wait_until)

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "ros2" / "simulation_interfaces"
ROS2_PY = ROOT / ".venv-ros2" / "bin" / "python"

# The type hashes (RIHS01) of simulation_interfaces 1.5.1, the version Jazzy releases: what Jazzy's rosidl
# (rosidl_generator_type_description 4.6.6, the wheels') computes from the release tag's files, as the build farm
# does. The messages' and the services' request/response hashes are also recomputed below by rosbags, an
# independent implementation of RIHS01. (The released .deb itself cannot be fetched from this machine: no
# packages.ros.org; on a Jazzy install, /opt/ros/jazzy/share/simulation_interfaces/*/*.json hold the same.)
JAZZY_HASHES = {f"simulation_interfaces/{k}": v for k, v in {
    "action/SimulateSteps": "RIHS01_f0837c898e1219cd73bf4c041feab41e8c533e8e1057e982744dba7b093467eb",
    "msg/Bounds": "RIHS01_e8624fe51f0f5548197542697d924c5699ac7198f1e4c68e50c3ca2af73f5b3f",
    "msg/EntityCategory": "RIHS01_43bdf7933fddf75f6970f7a8fe7078524355d821d390b3954bb46ac36c03dfe1",
    "msg/EntityFilters": "RIHS01_8e7b12e8ea062f14c55de4877221fe1b7cd9749665a7ad8a4ab855fc4b148303",
    "msg/EntityInfo": "RIHS01_3b9a2e7fa00f9a59d325b6e47904044c421561a385682027c7fc06c359806319",
    "msg/EntityState": "RIHS01_2e0464a85eb80a939025075d6c20761eca6a4cb9d6baf2c0ba373467c8b598d0",
    "msg/NamedPose": "RIHS01_b32da2a039b1840f605ec025b7991a18efacac662fac272818d1ae6e2b12bc27",
    "msg/Resource": "RIHS01_2bb1939cf80f8d2f284afba53cbec60b5ff33759bd39b714128ea8867a34c51a",
    "msg/Result": "RIHS01_cf43a306adff3337a0a47143d8f5689933bc70a30478f13b077dc1fe3bc5ad17",
    "msg/SimulationState": "RIHS01_bb9f87ccdd98fba113052a512d9801e84ce732d0a2b3c2b0cb281828de36e415",
    "msg/SimulatorFeatures": "RIHS01_8b101c8529bc0ea3dcf056078254768f39832b9ef0adaf93bd5cea96c0de3305",
    "msg/SpawnEntity": "RIHS01_94a349a865ccf673c18c080520299c88c3d8d5f4842ecf1482d6c997ac4b69f9",
    "msg/SpawnResult": "RIHS01_dbc277304b6c24bfb2a631cea8f52e2b005d583ec0a6c86b11613f5ce6486da1",
    "msg/Spawnable": "RIHS01_8c22025d840e7a05ab31ba56f998b06458b549a9744b4695be25b778829fc176",
    "msg/TagsFilter": "RIHS01_5c3efc51e8ed04c266c09cb4691ec95b964cd410558e01d8c83646b038826b45",
    "msg/WorldResource": "RIHS01_e3b65ecf904b9b115673e4a343c6aa3d28c19e185a71228faa64b783afcf2403",
    "srv/DeleteEntity": "RIHS01_ff7e96a5b83dc8e2bb34b8b034480028b3a24d9f8376b2c0590bac3704be3e28",
    "srv/GetAvailableWorlds": "RIHS01_ce5589b5523f2732d1969a3c5a7e6b17a387091df8190c62f78d7fdd1109e3e3",
    "srv/GetCurrentWorld": "RIHS01_79ed4e910e1b7a1c9f7950ff758bfba3535bf0dec669054e8af115a099724ddd",
    "srv/GetEntities": "RIHS01_cb90004c48cd50f37732fb008e22c34c261dd680a723bf0f85d8437ea4498bf7",
    "srv/GetEntitiesStates": "RIHS01_0a76170d0c1c90e1eaf805cfab78ea801d1f82df309a28c1f0fae4b570f19754",
    "srv/GetEntityBounds": "RIHS01_17be8d36231178a5eed0de0344b55c19975581627a9aec30a4fee9926a35deed",
    "srv/GetEntityInfo": "RIHS01_953b7ab6bfc35063f5c9a72463c6ce489baa10249a7fa510926d342a34b0d29e",
    "srv/GetEntityState": "RIHS01_749c91f2a2353d98367b64f2995a0f5842ce92a08ec1ffb3e185540a91557fb5",
    "srv/GetNamedPoseBounds": "RIHS01_59fa8dd2c68ba6771160cc66a628ac99fa95e2748fa0a43c2cc62a2e5f3f6fdc",
    "srv/GetNamedPoses": "RIHS01_c3d12ab920115bfd4733f6d20516adc3968fb438538540997c37e200e02b04e3",
    "srv/GetSimulationState": "RIHS01_3362dcebee4b1afebbf9c4beee5c79c1455385aded62092a892d61fde8644f30",
    "srv/GetSimulatorFeatures": "RIHS01_abb9439c8cf196722a469fb6c68b44b484f198c2a1356ac38849a29c2a20a794",
    "srv/GetSpawnables": "RIHS01_3bc0266bf8236058ff589c44512e013afe4f295427c39d44cff363d1c956bf36",
    "srv/LoadWorld": "RIHS01_f210682338f195f6f06191b46b20ec4992bddf485d33e2cffab2dd15341b4e3e",
    "srv/ResetSimulation": "RIHS01_4ce285d7ff9b8ac70dcc95161f32bf54c05a6f4b13427990e41ab40c36c39646",
    "srv/SetEntityInfo": "RIHS01_867fe2b6812f3e021859171f9b788560d66bb7079d640030baf6c0bb2dd2631e",
    "srv/SetEntityState": "RIHS01_ca210e7d2b66629ae133c8e1edf5246e618106d75c78ed0556c0e7a33c59ee5e",
    "srv/SetSimulationState": "RIHS01_a868b916dce49974f637ba252141258c4b07b0c06858b88af560e3eb6bfbcb30",
    "srv/SpawnEntities": "RIHS01_41703a359ee032bf4fc230f144f531705ba039a2e97edeae1f7997dd83b04857",
    "srv/SpawnEntity": "RIHS01_d4c086345d4194a5fc4c9ae45095736ca4062b5cdac4d06a42dec93d683e03cf",
    "srv/StepSimulation": "RIHS01_913fe0653690ce6bf8f09f316e6a626747012e9fca31e26719910d417aa8565c",
    "srv/UnloadWorld": "RIHS01_ac7f9a73df1b5b15015d854c5ac552b7726506e22f886c6792804f0b7f88b30b",
}.items()}


def _blob_id(data: bytes) -> str:
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


def test_interface_files_are_the_released_ones():
    """Every file in ros2/simulation_interfaces (but our UPSTREAM and COLCON_IGNORE) has the git blob id
    of the upstream file at tag 1.5.1, and every interface upstream's CMakeLists builds is here."""
    lines = [ln.split() for ln in (PKG / "UPSTREAM").read_text().splitlines() if ln and not ln.startswith("#")]
    upstream = {path: blob for blob, path in lines}
    here = {p.relative_to(PKG).as_posix(): _blob_id(p.read_bytes()) for p in PKG.rglob("*") if p.is_file()
            and p.name not in ("UPSTREAM", "COLCON_IGNORE")}
    assert here == upstream
    built = re.findall(r'"((?:msg|srv|action)/\w+\.(?:msg|srv|action))"', (PKG / "CMakeLists.txt").read_text())
    assert len(built) == 38 and set(built) <= set(here)
    assert {f"simulation_interfaces/{b.split('.')[0]}" for b in built} == set(JAZZY_HASHES)


def _ros2(code: str, timeout: float = 120) -> str:
    r = subprocess.run([str(ROS2_PY), "-c", textwrap.dedent(code)], capture_output=True, text=True,
                       timeout=timeout, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-3000:]
    return r.stdout


def test_type_hashes_equal_the_jazzy_release():
    """The package scripts/bootstrap_ros2.sh built into .venv-ros2 has the release's hashes, and rosbags'
    own RIHS01 gives the same for every message and every service's request and response."""
    out = json.loads(_ros2(r"""
        import glob, json, os, pathlib, sys
        from rosbags.typesys import Stores, get_typestore, get_types_from_msg
        built = {}
        for f in glob.glob(os.path.join(sys.prefix, "share", "simulation_interfaces", "*", "*.json")):
            for h in json.load(open(f))["type_hashes"]:
                built[h["type_name"]] = h["hash_string"]
        ts = get_typestore(Stores.ROS2_JAZZY)
        texts = {}
        for f in sorted(pathlib.Path("ros2/simulation_interfaces").glob("msg/*.msg")):
            texts[f"simulation_interfaces/msg/{f.stem}"] = f.read_text()
        for f in sorted(pathlib.Path("ros2/simulation_interfaces").glob("srv/*.srv")):
            req, resp = f.read_text().split("\n---\n")
            texts[f"simulation_interfaces/srv/{f.stem}_Request"] = req
            texts[f"simulation_interfaces/srv/{f.stem}_Response"] = resp
        types = {}
        for name, text in texts.items():
            # rosbags parses a srv part under srv/msg/: its own name and its references go back to srv/ and msg/
            got = json.dumps(get_types_from_msg(text, name)).replace("simulation_interfaces/srv/msg/",
                                                                      "simulation_interfaces/msg/")
            parsed = json.loads(got)
            types.update({name: parsed.popitem()[1]})
        ts.register({k: (tuple(v[0]), [tuple(f) for f in v[1]]) for k, v in types.items()})
        print(json.dumps({"built": built, "rosbags": {n: ts.hash_rihs01(n) for n in texts}}))
    """))
    built, independent = out["built"], out["rosbags"]
    assert {n: built.get(n) for n in JAZZY_HASHES} == JAZZY_HASHES
    assert len(independent) == 15 + 2 * 22
    assert {n: built[n] for n in independent} == independent


def test_the_cores_numbers_are_the_standards():
    """sim/standard.py writes the standard's constants out (the core imports no ROS): each equals the
    generated message class's constant of the same meaning."""
    pairs = {  # core name -> (interface, constant)
        **{n: ("msg.SimulatorFeatures", n) for n in (
            "SPAWNING", "DELETING", "NAMED_POSES", "POSE_BOUNDS", "ENTITY_TAGS", "ENTITY_BOUNDS", "ENTITY_BOUNDS_BOX",
            "ENTITY_BOUNDS_CONVEX", "ENTITY_CATEGORIES", "SPAWNING_RESOURCE_STRING", "ENTITY_STATE_GETTING",
            "ENTITY_STATE_SETTING", "ENTITY_INFO_GETTING", "ENTITY_INFO_SETTING", "SPAWNABLES", "SIMULATION_RESET",
            "SIMULATION_RESET_TIME", "SIMULATION_RESET_STATE", "SIMULATION_RESET_SPAWNED",
            "SIMULATION_STATE_GETTING", "SIMULATION_STATE_SETTING", "SIMULATION_STATE_PAUSE",
            "STEP_SIMULATION_SINGLE", "STEP_SIMULATION_MULTIPLE", "STEP_SIMULATION_ACTION")},
        "FEATURE_UNSUPPORTED": ("msg.Result", "RESULT_FEATURE_UNSUPPORTED"), "OK": ("msg.Result", "RESULT_OK"),
        "NOT_FOUND": ("msg.Result", "RESULT_NOT_FOUND"), "INCORRECT_STATE": ("msg.Result", "RESULT_INCORRECT_STATE"),
        "OPERATION_FAILED": ("msg.Result", "RESULT_OPERATION_FAILED"),
        **{n: ("msg.SimulationState", f"STATE_{n}") for n in ("STOPPED", "PLAYING", "PAUSED", "QUITTING",
                                                               "NO_WORLD", "LOADING_WORLD")},
        **{n: ("srv.SetSimulationState.Response", n) for n in ("ALREADY_IN_TARGET_STATE", "STATE_TRANSITION_ERROR",
                                                               "INCORRECT_TRANSITION")},
        **{n: ("srv.SpawnEntity.Response", n) for n in ("NAME_NOT_UNIQUE", "NAME_INVALID", "UNSUPPORTED_FORMAT",
                                                        "NO_RESOURCE")},
        "INVALID_SPAWN_POSE": ("srv.SpawnEntity.Response", "INVALID_POSE"),
        "INVALID_POSE": ("srv.SetEntityState.Response", "INVALID_POSE"),
        "SPAWNING_ENTITIES": ("msg.SimulatorFeatures", "SPAWNING_ENTITIES"),
        "ENTITIES_SPAWN_FAILED": ("srv.SpawnEntities.Response", "ENTITIES_SPAWN_FAILED"),
        **{n: ("srv.ResetSimulation.Request", n) for n in ("SCOPE_DEFAULT", "SCOPE_TIME", "SCOPE_STATE",
                                                           "SCOPE_SPAWNED", "SCOPE_ALL")},
        **{n: ("msg.EntityCategory", n) for n in ("CATEGORY_OBJECT", "CATEGORY_ROBOT", "CATEGORY_DYNAMIC_OBJECT",
                                                  "CATEGORY_STATIC_OBJECT")},
        **{n: ("msg.TagsFilter", n) for n in ("FILTER_MODE_ANY", "FILTER_MODE_ALL")},
        **{f"BOUNDS_{n}": ("msg.Bounds", f"TYPE_{n}") for n in ("EMPTY", "BOX", "CONVEX_HULL", "SPHERE")},
    }
    from robotatfactory.sim import standard as st

    theirs = json.loads(_ros2(f"""
        import json, operator, simulation_interfaces
        import simulation_interfaces.msg, simulation_interfaces.srv
        pairs = {json.dumps(pairs)}
        get = lambda a, c: operator.attrgetter(f"{{a}}.{{c}}")(simulation_interfaces)
        print(json.dumps({{k: get(a, c) for k, (a, c) in pairs.items()}}))
    """))
    assert {k: getattr(st, k) for k in pairs} == theirs


def test_planar_poses_only():
    from robotatfactory.sim.standard import quaternion_of_yaw, yaw_of_quaternion

    for yaw in (0.0, 1.0, -2.5, math.pi):
        got, err = yaw_of_quaternion(*quaternion_of_yaw(yaw))
        assert err == "" and math.remainder(got - yaw, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
    assert yaw_of_quaternion(0.0, 0.0, 0.0, 0.5)[0] is None  # not unit length
    assert "roll" in yaw_of_quaternion(math.sin(0.1), 0.0, 0.0, math.cos(0.1))[1]  # 11.5 deg of roll
    assert yaw_of_quaternion(math.sin(0.005), 0.0, 0.0, math.cos(0.005))[0] == pytest.approx(0.0, abs=1e-9)


# ---- the services, through ROS ---------------------------------------------------------------------------------
def _types():
    from robotatfactory.ros.mw import api

    return api().standard_sim_types()


def _call(service: str, /, **fields):
    from robotatfactory.ros.simulation_interfaces import SERVICE_NAMES

    return test_node().call(f"/{service}", getattr(_types().srv, SERVICE_NAMES[service]), 30.0, **fields)


def _pose(x: float, y: float, yaw: float, frame: str = ""):
    from geometry_msgs.msg import PoseStamped

    p = PoseStamped()
    p.header.frame_id = frame
    p.pose.position.x, p.pose.position.y = x, y
    p.pose.orientation.z, p.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return p


def _entity_state(x: float, y: float, yaw: float, vx: float = 0.0, q=None):
    s = _types().msg.EntityState()
    p = _pose(x, y, yaw).pose
    s.pose = p
    if q is not None:
        s.pose.orientation.x, s.pose.orientation.y, s.pose.orientation.z, s.pose.orientation.w = q
    s.twist.linear.x = vx
    return s


def _yaw(q) -> float:
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


class ActionClient:
    """A SimulateSteps client on a node of its own (a single-threaded executor: rclpy's EventsExecutor, the
    test node's, does not run action clients in Jazzy)."""

    def __init__(self, name: str = "/simulate_steps"):
        import threading

        import rclpy
        from rclpy.action import ActionClient as RclActionClient
        from rclpy.executors import SingleThreadedExecutor

        ctx = test_node().node.context
        self.node = rclpy.create_node("raf_test_actions", context=ctx)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(self.node)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()
        self.client = RclActionClient(self.node, _types().action.SimulateSteps, name)
        assert self.client.wait_for_server(timeout_sec=20)

    def _spin(self):
        while not self.stop.is_set():
            self.ex.spin_once(timeout_sec=0.05)

    def send(self, steps: int, cancel_after: int | None = None, timeout: float = 60.0):
        """(status, result, [completed_steps of each feedback])."""
        import time

        feedback = []
        goal = self.client.send_goal_async(_types().action.SimulateSteps.Goal(steps=steps),
                                           feedback_callback=lambda m: feedback.append(m.feedback.completed_steps))
        wait_until(goal.done, 20, what="the goal's acceptance")
        handle = goal.result()
        assert handle.accepted
        res = handle.get_result_async()
        end = time.monotonic() + timeout
        cancelled = False
        while not res.done():
            if cancel_after is not None and not cancelled and len(feedback) >= cancel_after:
                handle.cancel_goal_async()
                cancelled = True
            assert time.monotonic() < end, f"no result in {timeout} s ({len(feedback)} feedbacks)"
            time.sleep(0.01)
        # feedback and result come on separate channels: a step's feedback may arrive after the result (under
        # load in the full suite, 8 steps' worth did): wait until none has come for 0.3 s
        seen, quiet_since = len(feedback), time.monotonic()
        while time.monotonic() - quiet_since < 0.3 and time.monotonic() < end:
            if len(feedback) != seen:
                seen, quiet_since = len(feedback), time.monotonic()
            time.sleep(0.01)
        return res.result().status, res.result().result, feedback

    def close(self):
        self.client.destroy()
        self.stop.set()
        self.thread.join(2)
        self.ex.shutdown(timeout_sec=1)
        self.node.destroy_node()


def _parts_truth(collector, pid: int):
    """(x, y) of part ``pid`` in the bridge's parts ground truth (the SensorFrame's Parts) now."""
    m = collector.wait(1, timeout=5)[-1]
    p = m.poses[pid - 1].position
    return p.x, p.y


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.middlewares
def test_standard_services_with_the_stand_in(middleware, ros_graph, field, tmp_path):
    """Every call of the standard on the stand-in, each effect checked in the ground truth the bridge
    publishes (``ground_truth``, ``parts_ground_truth``, ``/clock``), not in the services' own answers."""
    from geometry_msgs.msg import PoseArray
    from nav_msgs.msg import Odometry
    from rosgraph_msgs.msg import Clock

    from robotatfactory.ros.messages import stamp_to_s
    from robotatfactory.ros.simulation_interfaces import SERVICE_NAMES
    from robotatfactory.sim import standard as st

    test_node()
    env = ros_graph.env()
    port, sim_port, ctl_port = (free_port(socket.SOCK_DGRAM) for _ in range(3))
    bridge = raf_process(["bridge", "--port", str(port), "--no-camera", "--set",
                          f"simulator/control=127.0.0.1:{ctl_port}"], env, tmp_path / "bridge.log")
    procs = [bridge]
    action = None
    try:
        if middleware == "ros1":  # ROS 1: the project's own sim/* services, not the ROS 2 standard
            wait_for_service("/sim/get_state", timeout=30)
            names = service_names()
            assert "/sim/reset" in names and not any(f"/{n}" in names for n in SERVICE_NAMES)
            return
        for name in SERVICE_NAMES:
            wait_for_service(f"/{name}", timeout=30)
        gt, clock = Collector("/ground_truth", Odometry), Collector("/clock", Clock)
        parts = Collector("/ground_truth/parts", PoseArray)
        procs.append(raf_process(["sim", "--port", str(sim_port), "--control-port", str(ctl_port), "--bridge",
                                  f"127.0.0.1:{port}", "--no-camera", "--no-server", "--status-every", "0",
                                  "--round", "1", "--seed", "3"], env, tmp_path / "sim.log"))
        gt.wait(10, timeout=30)
        ok, msg = st.OK, lambda r: r.result.error_message

        f = _call("get_simulator_features").features
        assert sorted(f.features) == sorted(st.STANDIN_FEATURES) and list(f.spawn_formats) == ["raf"]

        # entities, with each filter
        r = _call("get_entities")
        assert r.result.result == ok and r.entities[0] == "robot"
        names = list(r.entities)
        part_names = [n for n in names if n.startswith("part_")]
        assert len(part_names) >= 2 and len(parts.wait(1)[-1].poses) >= len(part_names)
        EF = _types().msg.EntityFilters
        assert list(_call("get_entities", filters=EF(filter="^part_")).entities) == part_names
        cat = _types().msg.EntityCategory(category=st.CATEGORY_ROBOT)
        assert list(_call("get_entities", filters=EF(categories=[cat])).entities) == ["robot"]
        tf = _types().msg.TagsFilter(tags=["part"])
        assert list(_call("get_entities", filters=EF(tags=tf)).entities) == part_names
        g = gt.wait(1)[-1].pose.pose.position
        bounds = _types().msg.Bounds(type=st.BOUNDS_SPHERE)
        from geometry_msgs.msg import Vector3

        bounds.points = [Vector3(x=g.x, y=g.y, z=0.0), Vector3(x=0.05, y=0.0, z=0.0)]
        assert "robot" in _call("get_entities", filters=EF(bounds=bounds)).entities
        r = _call("get_entities", filters=EF(filter="(unclosed"))
        assert r.result.result == st.OPERATION_FAILED and "regular expression" in msg(r)
        bounds.type = st.BOUNDS_CONVEX_HULL
        assert _call("get_entities", filters=EF(bounds=bounds)).result.result == st.FEATURE_UNSUPPORTED
        r = _call("get_entities_states", filters=EF(filter="^robot$"))
        assert list(r.entities) == ["robot"] and len(r.states) == 1

        # entity state and info against the ground truth
        r = _call("get_entity_state", entity="robot")
        g = gt.wait(1)[-1].pose.pose
        assert r.result.result == ok and r.state.header.frame_id == "map"
        assert math.hypot(r.state.pose.position.x - g.position.x, r.state.pose.position.y - g.position.y) < 0.01
        assert _call("get_entity_state", entity="nobody").result.result == st.NOT_FOUND
        info = _call("get_entity_info", entity=part_names[0]).info
        assert info.category.category == st.CATEGORY_DYNAMIC_OBJECT and "part" in info.tags
        assert _call("get_entity_info", entity="robot").info.category.category == st.CATEGORY_ROBOT

        sp = field.start_pose
        tx, ty = sp.x + 0.3, sp.y + 0.05
        r = _call("set_entity_state", entity="robot", state=_entity_state(tx, ty, 1.2))
        assert r.result.result == ok, msg(r)
        g = gt.wait(1, timeout=5, pred=lambda m: abs(m.pose.pose.position.x - tx) < 0.01)[-1].pose.pose
        assert abs(g.position.y - ty) < 0.01 and abs(math.remainder(_yaw(g.orientation) - 1.2, 2 * math.pi)) < 0.02
        for bad, code in ((_entity_state(tx, ty, 0.0, q=(0.0, 0.0, 0.0, 2.0)), st.INVALID_POSE),
                          (_entity_state(tx, ty, 0.0, q=(0.3827, 0.0, 0.0, 0.9239)), st.INVALID_POSE),  # rolled
                          (_entity_state(9.0, 0.0, 0.0), st.INVALID_POSE),
                          (_entity_state(tx, ty, 0.0, vx=0.1), st.OPERATION_FAILED)):
            r = _call("set_entity_state", entity="robot", state=bad)
            assert r.result.result == code, msg(r)

        # a part: moved, deleted, spawned back at a named pose with a new colour
        slots = {p.name: p for p in _call("get_named_poses").poses}
        assert "start" in slots and {s.name for s in field.slots} <= set(slots)
        tags = _types().msg.TagsFilter(tags=["start"])
        assert [p.name for p in _call("get_named_poses", tags=tags).poses] == ["start"]
        pid = int(part_names[0].split("_")[1])
        px, py = sp.x + 0.3, sp.y - 0.15
        r = _call("set_entity_state", entity=part_names[0], state=_entity_state(px, py, 0.5))
        assert r.result.result == ok, msg(r)
        wait_until(lambda: math.dist(_parts_truth(parts, pid), (px, py)) < 0.01, 5, what="the part moved")
        r = _call("delete_entity", entity=part_names[0])
        assert r.result.result == ok, msg(r)
        wait_until(lambda: not field.floor.contains(*_parts_truth(parts, pid)), 5, what="the part off the field")
        assert part_names[0] not in _call("get_entities").entities
        assert _call("delete_entity", entity="robot").result.result == st.OPERATION_FAILED
        assert _call("delete_entity", entity=part_names[0]).result.result == st.NOT_FOUND
        target = slots["outgoing_1"].pose
        yaw = _yaw(target.orientation)
        spawn = dict(name=part_names[0], allow_renaming=False,
                     initial_pose=_pose(target.position.x, target.position.y, yaw))
        assert _call("spawn_entity", **spawn).result.result == st.NO_RESOURCE
        assert _call("spawn_entity", uri="model://box", **spawn).result.result == st.UNSUPPORTED_FORMAT
        r = _call("spawn_entity", uri="raf://part/blue", **spawn)
        assert r.result.result == ok and r.entity_name == part_names[0], msg(r)
        wait_until(lambda: math.dist(_parts_truth(parts, pid), (target.position.x, target.position.y)) < 0.01, 5,
                   what="the spawned part at outgoing_1")
        assert "blue" in _call("get_entity_info", entity=part_names[0]).info.tags
        r = _call("spawn_entity", uri="raf://part", **spawn)
        assert r.result.result == st.NAME_NOT_UNIQUE, msg(r)
        spawn.update(name="", allow_renaming=True)
        r = _call("spawn_entity", uri="raf://part", **spawn)
        assert r.result.result == st.OPERATION_FAILED and "delete one first" in msg(r)

        # bounds, spawnables, several spawns in one call
        b = _call("get_entity_bounds", entity="robot").bounds
        assert b.type == st.BOUNDS_BOX and b.points[0].x < 0 < b.points[1].x and b.points[1].z > 0.05
        b = _call("get_entity_bounds", entity=part_names[0]).bounds
        assert b.points[1].y - b.points[0].y == pytest.approx(field.part.width)
        assert _call("get_entity_bounds", entity="nobody").result.result == st.NOT_FOUND
        b = _call("get_named_pose_bounds", name="start").bounds
        assert b.points[0].x < 0 < b.points[1].x and b.points[0].y < 0 < b.points[1].y
        assert _call("get_named_pose_bounds", name="nowhere").result.result == st.NOT_FOUND
        uris = [s.uri for s in _call("get_spawnables").spawnables]
        assert uris == ["raf://part", "raf://part/red", "raf://part/green", "raf://part/blue"]
        two = part_names[:2]
        for n in two:
            assert _call("delete_entity", entity=n).result.result == ok
        SE, R = _types().msg.SpawnEntity, _types().msg.Resource
        at = {"outgoing_2": two[0], "outgoing_3": two[1]}
        reqs = [SE(name=n, entity_resource=R(uri="raf://part"), initial_pose=_pose(
                    slots[s].pose.position.x, slots[s].pose.position.y, _yaw(slots[s].pose.orientation)))
                for s, n in at.items()]
        reqs.append(SE(allow_renaming=True, entity_resource=R(uri="raf://part"), initial_pose=_pose(9.0, 0.0, 0.0)))
        r = _call("spawn_entities", spawn_requests=reqs)
        assert r.result.result == st.ENTITIES_SPAWN_FAILED
        assert [x.result.result for x in r.results] == [ok, ok, st.INVALID_SPAWN_POSE]
        assert [x.entity_name for x in r.results] == [*two, ""]
        for s, n in at.items():
            xy = (slots[s].pose.position.x, slots[s].pose.position.y)
            wait_until(lambda n=n, xy=xy: math.dist(_parts_truth(parts, int(n.split("_")[1])), xy) < 0.01, 5,
                       what=f"{n} at {s}")

        # state, steps, the action
        SS = _types().msg.SimulationState
        assert _call("get_simulation_state").state.state == st.PLAYING
        r = _call("step_simulation", steps=3)
        assert r.result.result == st.OPERATION_FAILED and "pause" in msg(r)
        assert _call("set_simulation_state", state=SS(state=st.PAUSED)).result.result == ok
        assert _call("set_simulation_state", state=SS(state=st.PAUSED)).result.result == st.ALREADY_IN_TARGET_STATE
        assert _call("get_simulation_state").state.state == st.PAUSED

        def sim_time() -> float:
            return stamp_to_s(_call("get_entity_state", entity="robot").state.header.stamp)

        t0 = sim_time()
        clock.clear()
        assert _call("step_simulation", steps=5).result.result == ok
        assert sim_time() == pytest.approx(t0 + 0.2, abs=1e-6)
        # /clock reaches the stepped time (the five steps' clocks may arrive one by one) and goes no further: paused.
        # The wait returns at the first clock that reaches it; a clock running on would come after, so listen on
        reached = clock.wait(1, timeout=5, pred=lambda c: stamp_to_s(c.clock) >= t0 + 0.2 - 1e-6)
        assert max(stamp_to_s(c.clock) for c in reached) == pytest.approx(t0 + 0.2, abs=1e-6)
        time.sleep(0.4)  # ten control cycles (0.04 s) of wall time more
        assert max(stamp_to_s(c.clock) for c in clock.wait(1, timeout=1)) == pytest.approx(t0 + 0.2, abs=1e-6)
        action = ActionClient()
        status, result, fb = action.send(10)
        assert status == 4 and result.result.result == ok, result.result.error_message  # STATUS_SUCCEEDED
        assert fb == list(range(1, 11)) and sim_time() == pytest.approx(t0 + 0.6, abs=1e-6)
        status, result, fb = action.send(2000, cancel_after=3)
        assert status == 5 and 3 <= fb[-1] < 2000  # STATUS_CANCELED
        assert sim_time() == pytest.approx(t0 + 0.6 + 0.04 * fb[-1], abs=0.041)
        assert _call("set_simulation_state", state=SS(state=st.PLAYING)).result.result == ok
        status, result, fb = action.send(3)
        assert status == 6 and result.result.result == st.OPERATION_FAILED  # STATUS_ABORTED: not paused
        r = _call("set_simulation_state", state=SS(state=st.QUITTING))
        assert r.result.result == st.FEATURE_UNSUPPORTED

        # resets: only the whole one; STOPPED is paused at t = 0
        assert _call("reset_simulation", scope=1).result.result == st.FEATURE_UNSUPPORTED
        clock.clear()
        r = _call("reset_simulation", scope=0)
        assert r.result.result == ok, msg(r)
        g = gt.wait(1, timeout=5, pred=lambda m: math.hypot(m.pose.pose.position.x - sp.x,
                                                             m.pose.pose.position.y - sp.y) < 0.01)
        assert min(stamp_to_s(c.clock) for c in clock.wait(3, timeout=5)) < 0.5  # /clock went back
        assert _call("set_simulation_state", state=SS(state=st.STOPPED)).result.result == ok
        assert _call("get_simulation_state").state.state == st.STOPPED and sim_time() == 0.0
        assert _call("set_simulation_state", state=SS(state=st.PLAYING)).result.result == ok
        wait_until(lambda: sim_time() > 0.2, 10, what="the simulation playing again")
        assert _call("get_simulation_state").state.state == st.PLAYING
    finally:
        if action is not None:
            action.close()
        for p in procs:
            stop_process(p)


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.middlewares
def test_standard_services_with_a_simtwo_like_simulator(middleware, ros_graph, field, tmp_path):
    """A simulator that does not answer the control channel is SimTwo: GetSimulatorFeatures lists SimTwo's
    subset, the robot moves by the Command datagram's teleport labels, the rest answers FEATURE_UNSUPPORTED
    (the fake sends no Parts: the robot is the only entity; the real SimTwo's parts: test_simtwo_real.py)."""
    from fakesim import FakeSim
    from nav_msgs.msg import Odometry

    from robotatfactory.ros.simulation_interfaces import SERVICE_NAMES
    from robotatfactory.sim import standard as st

    test_node()
    env = ros_graph.env()
    port, nobody = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_DGRAM)
    bridge = raf_process(["bridge", "--port", str(port), "--no-camera", "--set",
                          f"simulator/control=127.0.0.1:{nobody}"], env, tmp_path / "bridge.log")
    fake = None
    try:
        if middleware == "ros1":  # ROS 1 serves the package's own sim/* services only, with SimTwo as well
            wait_for_service("/sim/get_state", timeout=30)
            names = service_names()
            assert "/sim/set_robot_pose" in names and not any(f"/{n}" in names for n in SERVICE_NAMES)
            return
        wait_for_service("/get_simulator_features", timeout=30)
        odom = Collector("/odom", Odometry)
        fake = FakeSim(bridge=("127.0.0.1", port)).start()
        odom.wait(5, timeout=20)
        f = _call("get_simulator_features").features
        assert sorted(f.features) == sorted(st.SIMTWO_FEATURES) and "simtwo" in f.custom_info
        assert list(_call("get_entities").entities) == ["robot"]
        assert _call("get_simulation_state").state.state == st.PLAYING
        for service, fields in (("reset_simulation", {}), ("step_simulation", {"steps": 1}),
                                ("set_simulation_state", {"state": _types().msg.SimulationState(state=st.PAUSED)})):
            r = _call(service, **fields)
            assert r.result.result == st.FEATURE_UNSUPPORTED and "simtwo" in r.result.error_message, service
        r = _call("set_entity_state", entity="robot", state=_entity_state(0.2, 0.1, 1.0))
        assert r.result.result == st.OK, r.result.error_message
        assert fake.pose() == pytest.approx((0.2, 0.1, 1.0), abs=1e-5)
        r = _call("get_entity_state", entity="robot")
        assert (r.state.pose.position.x, r.state.pose.position.y) == pytest.approx((0.2, 0.1), abs=0.01)
        r = _call("spawn_entity", name="part_1", uri="raf://part/red", initial_pose=_pose(0.0, 0.0, 0.0))
        assert r.result.result == st.NAME_INVALID and "off the field: none" in r.result.error_message
        assert [p.name for p in _call("get_named_poses").poses][0] == "start"
        assert [s.uri for s in _call("get_spawnables").spawnables] == ["raf://part"]  # no recolouring in SimTwo
    finally:
        if fake is not None:
            fake.stop()
        stop_process(bridge)
