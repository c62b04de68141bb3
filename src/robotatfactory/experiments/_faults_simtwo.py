"""``raf experiment faults --simulator simtwo``: the real SimTwo in the fault campaign's rig.

:mod:`.faults` imports this module (never the other way round); the processes are the rig's
:class:`..ros.processes.Procs` (numbered logs: ``sim.N.log`` for the N-th start). SimTwo runs as ``raf simtwo
run`` (the Linux build, headless, field ``simtwo2022``) and sends its SensorFrames to the proxy's port
(``--bridge 127.0.0.1:PROXY``); the proxy sends the bridge's replies back to where SimTwo's frames came from.
SimTwo's SensorFrames carry its ground truth, so the proxy's record is the truth as on the stand-in.

What the real SimTwo cannot do, and how the result says so (:data:`NOT_APPLICABLE`, :data:`DIFFERENCES`):

* no control channel: the soak (:mod:`._faults_soak`: rounds one after another, the simulation paused and
  reset to the next round and seed through ``raf sim``'s control channel) is not run; its targets are listed
  as not applicable, its keys absent;
* no start pose option: the robot is teleported through the bridge's ``sim/set_robot_pose`` (after the
  start and after the restart);
* no seed: ``--seed`` seeds the fuzz and the proxy only;
* its command timeout is control.pas's (``COMMAND_TIMEOUT_MS``, checked at the start of each 40 ms script
  cycle: ``TimeMs - LastValidMs > 400`` stops the wheels, so 440 ms after the last valid command, as ``raf
  sim`` does); the figures (``restart_bridge_stop_s``, ``restart_bridge_at_rest_s``) come from SimTwo's
  ground truth in its frames, as on the stand-in, and are judged by the same targets; the line the script writes then (``raf: no valid command for N ms: wheels
  stopped``, SimTwo's log in the kept folder) is kept as ``restart_bridge_timeout_age_logged_s``, with no
  target;
* its camera publishes only while its Cameras window is open: after a restart the images come back once
  ``raf simtwo run`` has reopened it (``restart_sim_image_back_s``);
* the fuzz, loss and restart parts use no control channel on either simulator (``raf sim --no-server``).
"""
from __future__ import annotations

import os
import re
import signal
import time
from pathlib import Path

from ._faults_soak import TARGETS as SOAK_TARGETS

MODE = "real_simtwo"  # the result's mode and the prefix of its keys (as raf experiment localization's)
PARTS = ("fuzz", "loss", "restarts")
NOT_APPLICABLE = {
    "soak": "the soak plays round after round, pausing the simulation and resetting it to the next round and "
            "seed through raf sim's control channel: SimTwo has no control channel (its sim/reset puts the robot "
            "back only; the parts and its clock run on)",
}
#: the targets of the parts SimTwo cannot run (reported as not applicable, never as met)
TARGETS_NOT_APPLICABLE = tuple(SOAK_TARGETS)
DIFFERENCES = ("start poses by teleport (sim/set_robot_pose); no simulator seed (--seed: the fuzz and the proxy "
               "only); control.pas's timeout stops the wheels in the first 40 ms cycle more than 500 ms after the "
               "last valid command (TimeMs - LastValidMs > 500: 520 ms, as raf sim; its log line is "
               "restart_bridge_timeout_age_logged_s, the figures come from the ground truth); images come back once raf simtwo run has reopened SimTwo's "
               "Cameras window; a SimTwo restart takes seconds (restart_sim_process_start_to_first_frame_s)")
HELP = ("standin: raf sim (default); simtwo: the real SimTwo (raf simtwo run, field simtwo2022, the robot "
        "teleported to each part's start; keys start with " + MODE + "). SimTwo has no control channel to "
        "reset rounds, so the soak is not run (its targets are reported as not applicable); every figure comes from "
        "the observer (SimTwo's ground truth in its frames against what the bridge published)")
TIMEOUT_RE = re.compile(r"raf: no valid command for (\d+) ms: wheels stopped")


def check_parts(parts: list[str]) -> None:
    from ..errors import ConfigError

    for p in parts:
        if p in NOT_APPLICABLE:
            raise ConfigError(f"--simulator simtwo: the part {p!r} cannot run on SimTwo ({NOT_APPLICABLE[p]}); "
                              f"choose from {', '.join(PARTS)}")


def keep_dir(procs) -> Path:
    """The folder the next ``raf simtwo run`` keeps (its scene copy and SimTwo's log): new for each start
    (``procs``: the rig's :class:`..ros.processes.Procs`)."""
    return procs.log_dir / f"simtwo.{procs.starts.get('sim', 0) + 1}"


def command(field: str, udp_port: int, proxy_port: int, camera_port: int | None, keep: Path) -> list[str]:
    from ..ros.processes import raf_cmd

    cmd = raf_cmd("--field", field, "simtwo", "run", "--port", str(udp_port), "--bridge", f"127.0.0.1:{proxy_port}",
                  "--keep", str(keep), "--ready-timeout", "150")
    return cmd + (["--camera-port", str(camera_port)] if camera_port is not None else ["--no-camera"])


def teleport(pose: str, timeout: float = 30.0, *, node) -> str:
    """The robot to ``pose`` ("x,y,theta") through the bridge's ``sim/set_robot_pose`` (the bridge waits until
    SimTwo's ground truth shows it), called by ``node`` (this process's :class:`~..ros.mw.base.Node`; the
    service must be offered within ``timeout`` s: TimeoutError); RuntimeError when it fails."""
    from ..srv import SetRobotPose

    x, y, th = (float(v) for v in pose.split(","))
    r = node.call("sim/set_robot_pose", SetRobotPose, timeout=timeout, x=x, y=y, theta=th)
    if not r.success:
        raise RuntimeError(f"SimTwo: the teleport to {pose} failed: {r.message}")
    return r.message


def _simtwo_pids(keep: Path) -> list[int]:
    """The SimTwo process(es) running the scene copy in ``keep`` (its command line names the folder)."""
    scene = str(keep / "scene")
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                argv = (d / "cmdline").read_bytes().split(b"\0")
            except OSError:
                continue
            if len(argv) > 1 and argv[1].decode(errors="replace") == scene:
                out.append(int(d.name))
    return out


def kill(procs, keep: Path) -> float:
    """SimTwo itself killed (SIGKILL, as a crash), then its ``raf simtwo run`` (which stops its X server when it
    sees SimTwo gone, or gets SIGKILL after 5 s). Returns the monotonic time of the kill."""
    pids = _simtwo_pids(keep)
    if not pids:
        raise RuntimeError(f"SimTwo's process (scene {keep / 'scene'}) not found")
    t = time.monotonic()
    for pid in pids:
        os.kill(pid, signal.SIGKILL)
    p = procs.get("sim")
    try:
        p.wait(5)
    except Exception:  # noqa: BLE001 - subprocess.TimeoutExpired: the group is killed below
        pass
    procs.kill("sim")
    end = time.monotonic() + 10
    while _simtwo_pids(keep) and time.monotonic() < end:
        time.sleep(0.1)
    return t


def timeout_ages_s(keep: Path | None) -> list[float]:
    """control.pas's command timeouts so far, from SimTwo's log: the age (s) of the last valid command when the
    script stopped the wheels."""
    try:
        text = (keep / "simtwo.log").read_text(errors="replace") if keep is not None else ""
    except OSError:
        return []
    return [int(m) / 1000 for m in TIMEOUT_RE.findall(text)]


def result(res: dict) -> dict:
    """The result of a SimTwo campaign: every key prefixed with :data:`MODE`, the mode, and what does not
    apply."""
    out = {"simulator": "simtwo", "faults_mode": MODE}
    out.update({(k if k == "notes" else f"{MODE}_{k}"): v for k, v in res.items()})
    out[f"{MODE}_not_applicable"] = "; ".join(f"{p}: {why}" for p, why in NOT_APPLICABLE.items())
    out[f"{MODE}_targets_not_applicable"] = ", ".join(TARGETS_NOT_APPLICABLE)
    out[f"{MODE}_differences"] = DIFFERENCES
    return out
