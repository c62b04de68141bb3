"""raf simtwo: the build's steps and errors, the scene copy, the patches (no ROS; one test runs SimTwo)."""
from __future__ import annotations

import hashlib
import math
import io
import json
import re
import tarfile
from pathlib import Path

import pytest

from robotatfactory.simtwo_linux import build, scene

ROOT = Path(__file__).resolve().parents[1]


def test_every_patch_says_why_and_is_a_git_diff():
    ps = build.patches()
    assert len(ps) >= 12 and {p.parent.name for p in ps} == {"patches", "patches-5dpo_lazarus"}
    for p in ps:
        text = p.read_bytes().decode("latin-1")
        head, sep, _ = text.partition("diff --git ")
        assert sep, f"{p.name}: no git diff"
        assert head.startswith("robotatfactory: "), p.name
        assert len(head.split()) >= 15, f"{p.name}: the header must say why"


def test_bootstrap_installs_the_build_packages():
    text = (ROOT / "scripts" / "bootstrap.sh").read_text()
    listed = set(re.search(r"DEB_PACKAGES=\((.*?)\n\)", text, re.S).group(1).split())
    missing = set(build.DEBIAN_PACKAGES) - listed
    assert not missing, f"scripts/bootstrap.sh does not install {missing}"


def test_first_compiler_error_names_file_and_line():
    log = ("Hint: start\n/b/SimTwo/Viewer.pas(8,3) Fatal: (10022) Can't find unit Windows used by Viewer\n"
           "Fatal: (1018) Compilation aborted\nError: /usr/bin/ppcx64 returned an error exitcode\n")
    assert build.first_compiler_error(log).startswith("/b/SimTwo/Viewer.pas(8,3) Fatal: (10022)")


# ---- the build's steps on a miniature source set (no lazbuild needed before the patches step) ----------
def _archive(path: Path, top: str, files: dict[str, bytes]) -> str:
    with tarfile.open(path, "w:gz") as t:
        for name, data in files.items():
            info = tarfile.TarInfo(f"{top}/{name}")
            info.size = len(data)
            t.addfile(info, io.BytesIO(data))
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def mini(tmp_path, monkeypatch):
    """A sources.json with one tiny source, its archive, and a patch folder: build.py pointed at them."""
    srcdir, linux = tmp_path / "vendor", tmp_path / "linux"
    srcdir.mkdir()
    (linux / "patches").mkdir(parents=True)
    (linux / "units").mkdir()
    sha = _archive(srcdir / "simtwo-x.tar.gz", "SimTwo", {"a.pas": b"begin\r\nend.\r\n"})
    spec = {"lazarus_packages": [], "project": "SimTwo/SimTwo.lpi", "executable": "SimTwo/SimTwo2020",
            "sources": [{"name": "SimTwo", "repository": "file:///nonexistent/SimTwo", "commit": "0" * 40,
                         "archive": "simtwo-x.tar.gz", "sha256": sha, "patches": "patches"}]}
    (linux / "sources.json").write_text(json.dumps(spec))
    monkeypatch.setattr(build, "LINUX_DIR", linux)
    monkeypatch.setattr(build, "BUILD_ROOT", tmp_path / "build")
    monkeypatch.setattr(build, "missing_packages", lambda: [])
    return srcdir, linux


def test_a_patch_that_does_not_apply_is_named(mini):
    srcdir, linux = mini
    (linux / "patches" / "01-bad.patch").write_text(
        "robotatfactory: a patch for another version\n\ndiff --git a/a.pas b/a.pas\n--- a/a.pas\n+++ b/a.pas\n"
        "@@ -1,2 +1,2 @@\n-program x;\n+program y;\n end.\n")
    with pytest.raises(build.BuildError) as e:
        build.build(srcdir)
    assert e.value.step == "patches" and "01-bad.patch" in str(e.value)


def test_a_patch_applies_inside_the_source_tree_not_the_project(mini):
    srcdir, linux = mini
    (linux / "patches" / "01-good.patch").write_bytes(
        b"robotatfactory: rename\n\ndiff --git a/a.pas b/a.pas\n--- a/a.pas\n+++ b/a.pas\n"
        b"@@ -1,2 +1,2 @@\n-begin\r\n+begin {patched}\r\n end.\r\n")
    with pytest.raises(build.BuildError) as e:  # lazbuild finds no project in this miniature: that step fails
        build.build(srcdir)
    assert e.value.step == "lazbuild"
    patched = next(build.BUILD_ROOT.glob("*/src/SimTwo/a.pas")).read_bytes()
    assert patched == b"begin {patched}\r\nend.\r\n"  # applied there (build/ lies inside the project's git)


def test_an_archive_that_is_not_the_pinned_one_is_refused(mini):
    srcdir, _ = mini
    _archive(srcdir / "simtwo-x.tar.gz", "SimTwo", {"a.pas": b"something else"})
    with pytest.raises(build.BuildError) as e:
        build.build(srcdir)
    assert e.value.step == "sources" and "sha256" in str(e.value)


def test_no_archive_and_no_clone_says_what_to_pass(mini, tmp_path):
    with pytest.raises(build.BuildError) as e:
        build.build(tmp_path / "empty")
    assert e.value.step == "sources" and "--sources DIR" in str(e.value)


def test_the_cache_key_follows_the_patches(mini):
    _, linux = mini
    k0 = build.cache_key()
    (linux / "patches" / "01-x.patch").write_text("robotatfactory: x\n")
    assert build.cache_key() != k0


# ---- the real build and its scene -------------------------------------------------------------------
def test_the_build_is_cached():
    found = build.find()
    assert found is not None, "scripts/bootstrap.sh builds SimTwo before the tests (raf simtwo build)"
    b = build.build(build.default_sources())  # found, not built again
    assert b.cached and b.executable == found.executable and b.executable.exists()


def test_scene_copy_has_the_projects_side(tmp_path):
    from robotatfactory.competition.rounds import RoundSetup
    from robotatfactory.field import load_field

    b = build.require()
    setup = RoundSetup.make(2, 5)
    parts = scene.round_parts(load_field("simtwo2022"), setup.incoming)
    s = scene.SceneSettings(udp_port=40123, bridge_host="10.1.2.3", bridge_port=40124, parts=parts,
                            extra_ini={"config_Params.ini": {"EditTargetFPS_Text": "50"}})
    d = scene.install(b.simtwo_dir, tmp_path / "scene", s)
    pas = (d / "control.pas").read_text(encoding="latin-1")
    assert "BRIDGE_IP = '10.1.2.3';" in pas and re.search(r"BRIDGE_PORT = 40124;", pas)
    agv = (d / "AGV.xml").read_text(encoding="latin-1")
    assert agv.count("<ID value='ranger2d'/>") == 1
    assert agv.index("<ID value='ranger2d'/>") < agv.rindex("</sensors>")
    params = (d / "config_Params.ini").read_text(encoding="latin-1")
    for line in ("CBUDPConnect_Checked=1", "EditUDPPort_Text=40123", "RGControlBlock_ItemIndex=1",
                 "EditScriptPeriod_Text=40", "EditTargetFPS_Text=50"):
        assert re.search(rf"^{re.escape(line)}\r?$", params, re.M), line
    assert "CBSendImage_Checked=1" in (d / "config_Cameras.ini").read_text()
    xml = (d / "scene.xml").read_text(encoding="latin-1")
    for i, kind in enumerate(setup.incoming, start=1):
        m = re.search(rf"<ID name='Part{i}'/>\s*<pos x='([-\d.]+)' y='([-\d.]+)'.*?<rot_deg x='0' y='0' "
                      rf"z='([-\d.]+)'/>\s*<body file='(\w+)\.xml'/>", xml, re.S)
        assert m, i
        if kind is not None:
            assert m.group(4) == {"R": "PartRed", "G": "PartGreen", "B": "PartBlue"}[kind.letter]
            assert (float(m.group(1)), float(m.group(2))) == pytest.approx(load_field("simtwo2022").slot(
                "incoming", i).xy)
            assert float(m.group(3)) == pytest.approx(0.0, abs=1e-3)  # facing -90 deg: the scene's own 0
    # a second install of the lidar changes nothing
    scene.install_lidar(d / "AGV.xml")
    assert (d / "AGV.xml").read_text(encoding="latin-1") == agv


def test_script_with_half_its_constants_is_refused_and_one_without_is_left_alone():
    with pytest.raises(scene.SceneError, match="BRIDGE_PORT"):
        scene.configure_script("const\n  BRIDGE_IP = '1.2.3.4';\n", scene.SceneSettings())
    other = "const\n  K = 1;\nprocedure Control;\nbegin\nend;\n"
    assert scene.configure_script(other, scene.SceneSettings()) == other


def test_hot_cpu_only_with_the_camera():
    """SimTwo's Hot CPU is on with the camera open (the GUI loop never idles then) and off without it (it would
    spin a core); a run's own ini lines come after it."""
    from robotatfactory.simtwo_linux.run import SimTwoRun

    assert SimTwoRun(None).scene_ini() == {"config_Params.ini": {"CBHotCPU_Checked": "1"}}
    assert SimTwoRun(None, camera=False).scene_ini() == {}
    mine = {"config_Params.ini": {"CBHotCPU_Checked": "0", "EditTargetFPS_Text": "50"}}
    assert SimTwoRun(None, extra_ini=mine).scene_ini() == mine
    assert scene.VIEWER_WINDOW == {"FViewer_Width": "32", "FViewer_Height": "24"}


def test_set_ini_keeps_other_lines_and_adds_missing_keys(tmp_path):
    p = tmp_path / "x.ini"
    p.write_bytes(b"[Config]\r\nA=1\r\nB=2\r\n")
    scene.set_ini(p, "Config", {"B": "3", "C": "4"})
    assert p.read_bytes() == b"[Config]\r\nA=1\r\nB=3\r\nC=4\r\n"


@pytest.mark.simtwo
def test_a_script_compile_error_is_in_the_error(tmp_path):
    """SimTwo's own message (patch 11 puts the editor's messages on its standard output) ends the wait at once
    and is in the error, not a time-out."""
    from robotatfactory.simtwo_linux.run import Ports, SimTwoError, SimTwoRun

    bad = tmp_path / "control.pas"
    text = (ROOT / "simtwo" / "control.pas").read_text(encoding="latin-1")
    bad.write_text(text.replace("FrameSeq := FrameSeq + 1;", "FrameSeq := FrameSeq + undeclared_thing;", 1),
                   encoding="latin-1")
    run = SimTwoRun(build.require(), Ports.free(), camera=False, script=bad)
    with pytest.raises(SimTwoError) as e:
        run.start(timeout=90)
    assert "undeclared_thing" in str(e.value).lower() and "[Error]" in str(e.value)
    assert not run.alive


@pytest.mark.simtwo
def test_ctrl_c_stops_simtwo_and_its_x_server(tmp_path):
    """raf simtwo run, stopped with SIGINT once it runs: no SimTwo and no Xvfb of it left, its folder gone."""
    import os
    import signal
    import subprocess
    import sys
    import time

    log = tmp_path / "run.log"
    with open(log, "wb") as out:
        # SIGINT's default disposition in the child, as a terminal's Ctrl-C finds it: an ignored SIGINT (a suite
        # started in the background by a non-interactive shell) stays ignored in every child
        p = subprocess.Popen([sys.executable, "-m", "robotatfactory", "simtwo", "run", "--free-ports",
                              "--no-camera"], stdout=out, stderr=subprocess.STDOUT, start_new_session=True,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        end = time.monotonic() + 120
        while b"[simtwo] running (pid " not in log.read_bytes():
            assert p.poll() is None and time.monotonic() < end, log.read_text()
            time.sleep(0.2)
        text = log.read_text()
        pid = int(re.search(r"running \(pid (\d+), display :(\d+)\)", text).group(1))
        cwd = Path(os.readlink(f"/proc/{pid}/cwd"))  # SimTwo changes into its scene
        cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        workdir = Path(cmdline[1].decode()).parent
        assert workdir.name.startswith("raf-simtwo-") and cwd == workdir / "scene"
        xpid = int(subprocess.run(["pgrep", "-P", str(p.pid), "-x", "Xvfb"], capture_output=True,
                                  text=True).stdout.split()[0])  # the run's own X server, a child of raf
        assert "-displayfd" in Path(f"/proc/{xpid}/cmdline").read_text()
        os.killpg(p.pid, signal.SIGINT)
        assert p.wait(30) == 130
    finally:
        if p.poll() is None:
            p.kill()
    assert not Path(f"/proc/{pid}").exists(), "SimTwo still running"
    assert not Path(f"/proc/{xpid}").exists(), "its Xvfb still running"
    assert not workdir.exists(), "the run's folder was not removed"


@pytest.mark.simtwo
def test_script_api_calling_convention_on_linux():
    """simtwo/linux/abi_check.pas in the real SimTwo: every native function of the script API that takes or
    returns a record by value (and the Extended maths) gives the known result. Before patches 12-14, 18 of
    these failed on Linux (Power(2, 10) = 0, RandG garbage, colours as list indices, ...)."""
    import time

    from robotatfactory.simtwo_linux.run import Ports, SimTwoRun

    run = SimTwoRun(build.require(), Ports.free(), camera=True, script=ROOT / "simtwo" / "linux" / "abi_check.pas",
                    ready_line="script: ABI ")
    try:
        run.start(timeout=90)  # ready at its first check's line; then the camera is opened for GetCameraPixel
        end = time.monotonic() + 60
        while not any(m.startswith("script: ABI done") for m in run.messages()):
            run.check()
            assert time.monotonic() < end, "\n".join(run.messages()[-30:])
            time.sleep(0.5)
        lines = [m[len("script: "):] for m in run.messages() if m.startswith("script: ABI ")]
    finally:
        run.stop()
    fails = [x for x in lines if " FAIL " in x]
    done = re.match(r"ABI done (\d+) (\d+)", lines[-1])
    assert not fails, "\n".join(fails)
    assert done and int(done.group(2)) == 0 and int(done.group(1)) >= 90, lines[-1]
    for name in ("GetSensorValues", "Power", "RandG", "GetSolidColor", "SetMotorPars", "BiLinInterp",
                 "GetCameraPixel", "GetRobotPos2D"):
        assert f"ABI {name} ok" in lines, name


@pytest.mark.simtwo
def test_bench_simtwo_one_run():
    """raf bench simtwo's run (no ROS): SimTwo's rates, the replies it applied, its camera, and odometry against
    its ground truth per segment (straight driving matches; the turn on the spot is where they differ)."""
    from robotatfactory.bench.simtwo import one_run

    r = one_run(camera=True)
    print({k: round(v, 4) for k, v in r.items()})
    assert r["frames_per_s_sim"] == pytest.approx(25.0, abs=0.3)
    assert 0.9 <= r["sim_time_per_wall_time"] <= 1.1  # SimTwo runs in real time
    # patch 15: a reply is applied in (nearly) every cycle (before it: 58-61 %)
    assert 0.95 <= r["replies_applied_share"] <= 1.0 and r["replies_ignored"] == 0
    # SimTwo renders in software (llvmpipe): 6.7-7.3 frames/s on the machines of docs/simtwo.md, 3.6 on a slower
    # one quiet and 1.8-2.3 there in the suite (2026-11-26), 0.9 in the suite on another (2026-11-29): the bound
    # says the camera streams (three frames or more), not how fast (raf bench simtwo measures that)
    assert r["camera_frames_per_s"] * r["streaming_s"] >= 3 and 0 < r["camera_after_sensorframe_ms"] <= 60
    assert r["straight_odom_over_truth"] == pytest.approx(1.0, abs=0.01)
    # 184-186 on the earlier hosts; 190.7 once in CI on a host that renders at half speed (its loop stalls)
    assert r["spin_truth_turn_deg"] == pytest.approx(180, abs=15)
    assert abs(r["spin_odom_minus_truth_turn_deg"]) < 8  # measured: 3.7-4.4 deg short (docs/simtwo.md)


def test_raf_up_plan_with_simtwo():
    """raf up --simulator simtwo: the bridge first (it holds its free port at once), SimTwo before the factory
    server and the agent (the round starts once SimTwo streams), the field of SimTwo's
    scene, no control channel (the sim/* services go through the teleport labels), the referee (factory-state
    server, machines, score from SimTwo's part positions) before the agent; --lockstep refused."""
    import argparse

    from robotatfactory.commands import up
    from robotatfactory.errors import ConfigError

    parser = argparse.ArgumentParser()
    parser.add_argument("--field", default="rules2026")
    up.add_arguments(parser)
    ports = {"sim": 1, "bridge": 2, "control": 3, "camera": 4, "server": 5}
    steps = up.plan(parser.parse_args(["--simulator", "simtwo", "--agent", "--round", "2", "--seed", "7"]), "ros1",
                    ports)
    assert [name for name, _, _ in steps] == ["bridge", "localize", "sim", "referee", "agent"]
    args = {name: a for name, a, _ in steps}
    assert args["sim"][:4] == ["--field", "simtwo2022", "simtwo", "run"]
    assert args["sim"][args["sim"].index("--bridge") + 1] == "127.0.0.1:2"
    assert args["sim"][args["sim"].index("--round") + 1] == "2" and "7" in args["sim"]
    assert all(a[1] == "simtwo2022" for a in args.values())
    assert not any("simulator/control" in x for x in args["bridge"])
    assert args["referee"][2:5] == ["referee", "--round", "2"] and "7" in args["referee"]
    assert args["referee"][args["referee"].index("--server-port") + 1] == "5"
    assert args["agent"][args["agent"].index("--server-port") + 1] == "5"
    standin = up.plan(parser.parse_args([]), "ros1", ports)
    assert [name for name, _, _ in standin] == ["bridge", "localize", "sim"] and standin[0][1][1] == "rules2026"
    with pytest.raises(ConfigError, match="real time"):
        up.plan(parser.parse_args(["--simulator", "simtwo", "--lockstep"]), "ros1", ports)


@pytest.mark.simtwo
@pytest.mark.ros
def test_roslaunch_simtwo_launch(tmp_path):
    """roslaunch robotatfactory simtwo.launch (ROS 1): SimTwo, the bridge and the localization start together
    (the bridge binds its port while SimTwo starts: nothing else may hold it) and the EKF's pose is near
    SimTwo's truth; stopping roslaunch leaves no SimTwo behind."""
    import os
    import signal
    import subprocess
    import time

    from robotatfactory.proc import free_port, stop_process

    master = free_port()
    env = dict(os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{master}",
               ROS_PACKAGE_PATH=os.pathsep.join([str(ROOT), os.environ.get("ROS_PACKAGE_PATH", "")]))
    env.pop("ROS_DOMAIN_ID", None)
    import socket

    udp = lambda: free_port(socket.SOCK_DGRAM)  # noqa: E731
    log = tmp_path / "roslaunch.log"
    with open(log, "wb") as out:
        p = subprocess.Popen(["roslaunch", "-p", str(master), "robotatfactory", "simtwo.launch", f"port:={udp()}",
                              f"sim_port:={udp()}", f"camera_port:={free_port()}"], env=env, stdout=out,
                             stderr=subprocess.STDOUT, start_new_session=True)
    try:
        def echo(topic: str) -> tuple[float, float]:
            r = subprocess.run(["rostopic", "echo", "-n", "1", f"{topic}/pose/pose/position"], env=env,
                               capture_output=True, text=True, timeout=60)
            v = dict(line.split(": ") for line in r.stdout.splitlines() if ": " in line)
            return float(v["x"]), float(v["y"])

        end = time.monotonic() + 120
        while b"[simtwo] running (pid" not in log.read_bytes():
            assert p.poll() is None and time.monotonic() < end, log.read_text()[-3000:]
            time.sleep(0.5)
        pose, truth = echo("/pose"), echo("/ground_truth")
        text = log.read_text()
        assert "process has died" not in text, text[-3000:]
        pid = int(re.search(r"running \(pid (\d+),", text).group(1))
    finally:
        stop_process(p, signal.SIGINT, timeout=30)
    assert math.dist(pose, truth) < 0.03, (pose, truth)
    assert not Path(f"/proc/{pid}").exists(), "SimTwo still running after roslaunch stopped"
