"""``raf experiment competition --ray``: the runs as tasks on a Ray cluster of two nodes (one CPU each) that this
module starts on this machine in a private temporary directory with its own ports (ray.cluster_utils), and stops.

The fast bare mode (no ROS): the same runs locally and on Ray give the same results, both nodes work; a worker
killed mid-run has its run submitted again and reported; the executor carries input files, the output directory
and the environment's settings, and a run that raised in Python is a failed run, not retried. Ray is a pinned
requirement: without it these tests fail (ImportError), they are never skipped."""
from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import tempfile
import threading
import time
from pathlib import Path

import pytest
from expargs import options

from robotatfactory.experiments import _batch, competition

#: 4 runs: round 1 (the same four blue parts whatever the seed) and round 2 (the seed draws them), seeds 100-101
SPEC = dict(mode="bare_truth", rounds="1,2", first_seed=100, seeds=2)
EXECUTOR_KEYS = {"executor", "ray_address", "ray_version", "ray_nodes", "ray_cpus", "ray_cpus_per_run", "ray_workers",
                 "ray_nodes_used", "ray_runs_per_node", "ray_connect_s", "run_attempts", "runs_lost",
                 "ray_code_differs_runs", "runs_retried"}
RUN_EXECUTOR_KEYS = {"ray_node", "ray_host", "ray_pid", "ray_code_differs", "attempts", "lost_attempts", "wall_s"}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def ray_cluster():
    """A two-node Ray cluster (the :class:`ray.cluster_utils.Cluster`, its RAY_TMPDIR), one CPU a node, private
    to this module."""
    import ray
    from ray.cluster_utils import Cluster

    tmp = tempfile.mkdtemp(prefix="rafray", dir="/tmp")  # short: Ray's socket paths live under it
    old = os.environ.get("RAY_TMPDIR")
    os.environ["RAY_TMPDIR"] = tmp  # the nodes' session files, and how _busy_workers knows this cluster's workers
    c = None
    try:
        c = Cluster(initialize_head=True, head_node_args={
            "num_cpus": 1, "include_dashboard": False, "gcs_server_port": _free_port(),
            "dashboard_agent_listen_port": None})
        c.add_node(num_cpus=1, include_dashboard=False)
        c.wait_for_nodes()
        yield c, tmp
    finally:
        if ray.is_initialized():
            ray.shutdown()
        if c is not None:
            c.shutdown()
        if old is None:
            os.environ.pop("RAY_TMPDIR", None)
        else:
            os.environ["RAY_TMPDIR"] = old
        shutil.rmtree(tmp, ignore_errors=True)


@pytest.fixture
def cluster(ray_cluster):
    """(GCS address, RAY_TMPDIR) of the module's cluster, with its two nodes (a test may have removed one)."""
    c, tmp = ray_cluster
    if len(c.worker_nodes) < 1:
        c.add_node(num_cpus=1, include_dashboard=False)
        c.wait_for_nodes()
    return c.address, tmp


@pytest.fixture(scope="module")
def local(tmp_path_factory):
    """The batch on the local runner (2 spawned processes): (results, runs.json)."""
    out = tmp_path_factory.mktemp("local")
    res = competition.run(options(competition, **SPEC, jobs=2), out)
    return res, json.loads((out / "runs.json").read_text())


def _same_as_local(local, res: dict, runs: list[dict]) -> None:
    lres, lruns = local
    assert lres["executor"] == "local" and lres["runs_retried"] == 0
    assert set(res) - set(lres) <= EXECUTOR_KEYS | {k for k in res if k.endswith(("_attempts", "_lost_attempts"))}
    differ = {k: (lres[k], res.get(k)) for k in lres
              if k not in EXECUTOR_KEYS and not k.endswith("wall_s") and lres[k] != res.get(k)}
    assert not differ
    assert [(r["round"], r["seed"]) for r in runs] == [(r["round"], r["seed"]) for r in lruns]
    for a, b in zip(lruns, runs):
        assert "error" not in b, b.get("error")
        assert {k: v for k, v in a.items() if k not in RUN_EXECUTOR_KEYS} == \
            {k: v for k, v in b.items() if k not in RUN_EXECUTOR_KEYS}  # scores, times, path, events: all of it
    assert {(r["round"], r["points"], r["max_points"]) for r in runs} >= {(1, 4, 4)}
    assert len({r["last_score_s"] for r in runs}) >= 2  # the runs differ from each other (round 2's seeds)


def test_the_batch_on_two_ray_nodes_gives_the_local_results(cluster, local, tmp_path):
    address, _ = cluster
    res = competition.run(options(competition, **SPEC, ray=address), tmp_path)
    runs = json.loads((tmp_path / "runs.json").read_text())
    _same_as_local(local, res, runs)
    assert (tmp_path / "round1_seed100_bare_truth.png").stat().st_size > 0  # the driver drew the first seed's run
    assert res["executor"] == "ray" and res["ray_address"] == address
    assert res["ray_nodes"] == 2 and res["ray_workers"] == 2 and res["jobs"] == 2
    assert res["runs_retried"] == 0 and res["run_attempts"] == 4
    nodes = [r["ray_node"] for r in runs]
    assert res["ray_nodes_used"] == 2 and len(set(nodes)) == 2  # both workers did work
    assert all(r["attempts"] == 1 and "lost_attempts" not in r for r in runs)


def _busy_workers(tmp: str, parent: int | None = None) -> list[int]:
    """Pids of this cluster's Ray workers running a run now (process title ray::_remote_run), those of one node
    only with ``parent`` (its raylet's pid)."""
    pids = []
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            if not Path(f"/proc/{d}/cmdline").read_bytes().startswith(b"ray::_remote_run"):
                continue
            env = Path(f"/proc/{d}/environ").read_bytes().split(b"\0")
        except OSError:
            continue
        if f"RAY_TMPDIR={tmp}".encode() in env and (parent is None or _ppid(int(d)) == parent):
            pids.append(int(d))
    return pids


def _ppid(pid: int) -> int:
    try:
        return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
    except (OSError, IndexError, ValueError):
        return -1


def test_a_worker_killed_mid_run_has_its_run_retried_and_reported(cluster, local, tmp_path):
    address, tmp = cluster
    killed: list[int] = []
    stop = threading.Event()

    def killer():  # the first worker seen running a run for 0.5 s is killed (SIGKILL), once
        seen: dict[int, float] = {}
        while not stop.is_set() and not killed:
            now = time.monotonic()
            for pid in _busy_workers(tmp):
                if now - seen.setdefault(pid, now) >= 0.5:
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)
                    break
            time.sleep(0.05)

    t = threading.Thread(target=killer, daemon=True)
    t.start()
    try:
        res = competition.run(options(competition, **SPEC, ray=address), tmp_path)
    finally:
        stop.set()
        t.join(5)
    assert len(killed) == 1
    runs = json.loads((tmp_path / "runs.json").read_text())
    _same_as_local(local, res, runs)  # the retried run's result is the one it gives locally
    retried = [r for r in runs if r["attempts"] > 1]
    assert len(retried) == 1
    r = retried[0]
    assert r["attempts"] == 2 and r["ray_pid"] != killed[0]
    assert len(r["lost_attempts"]) == 1 and r["lost_attempts"][0].startswith("WorkerCrashedError")
    assert res["runs_retried"] == 1 and res["run_attempts"] == 5 and res["runs_lost"] == 0
    p = f"bare_truth_{competition.seed_set_of(r['seed'])}_r{r['round']}_s{r['seed']}"
    assert res[f"{p}_attempts"] == 2 and "WorkerCrashedError" in res[f"{p}_lost_attempts"]
    assert all(x["attempts"] == 1 for x in runs if x is not r)
    # the killed worker could not remove its private directory; the next run on the machine did
    assert not list(Path(tempfile.gettempdir()).glob(f"raf-batch-{killed[0]}-*"))


def test_a_node_lost_mid_run_has_its_run_retried_on_the_other(ray_cluster, cluster, local, tmp_path):
    """The second node (its raylet and workers) killed while it plays a run: the run goes to the head."""
    import ray._private.ray_constants as rc

    c, tmp = ray_cluster
    address, _ = cluster
    node = next(iter(c.worker_nodes))
    raylet = node.all_processes[rc.PROCESS_TYPE_RAYLET][0].process.pid
    removed: list[str] = []
    stop = threading.Event()

    def remover():  # as soon as the node has been playing a run for 0.5 s
        seen: dict[int, float] = {}
        while not stop.is_set() and not removed:
            now = time.monotonic()
            if any(now - seen.setdefault(pid, now) >= 0.5 for pid in _busy_workers(tmp, raylet)):
                c.remove_node(node, allow_graceful=False)
                removed.append(node.node_id)
            time.sleep(0.05)

    t = threading.Thread(target=remover, daemon=True)
    t.start()
    try:
        res = competition.run(options(competition, **SPEC, ray=address), tmp_path)
    finally:
        stop.set()
        t.join(30)
    assert removed
    runs = json.loads((tmp_path / "runs.json").read_text())
    _same_as_local(local, res, runs)
    retried = [r for r in runs if r["attempts"] > 1]
    assert len(retried) == 1 and retried[0]["attempts"] == 2
    assert retried[0]["lost_attempts"][0].split(":")[0] in ("NodeDiedError", "WorkerCrashedError")
    assert retried[0]["ray_node"] != removed[0]  # elsewhere: the node is gone
    assert res["ray_nodes"] == 2 and res["runs_retried"] == 1 and res["runs_lost"] == 0


def _failed(item, e):
    return {"round": item.get("round", 0), "seed": item.get("seed", 0), "error": f"{type(e).__name__}: {e}"}


def test_the_executor_carries_inputs_outputs_and_settings_and_does_not_retry_a_python_error(cluster, tmp_path,
                                                                                             monkeypatch):
    address, _ = cluster
    monkeypatch.setenv("RAF_MIDDLEWARE", "ros1")
    monkeypatch.setenv("RAF_ROS2_VENV", "/nowhere")  # a path of this machine's: not shipped
    src = tmp_path / "in" / "field.json"
    src.parent.mkdir()
    src.write_text("the driver's file")
    out = tmp_path / "out"
    out.mkdir()
    items = [{"round": 1, "seed": 1, "read": str(src), "write": {"r1/log.txt": "one", "r1/sub/trace": "t"},
              "child_signals": True},
             {"round": 1, "seed": 2, "write": {"r2/log.txt": "two"}, "sleep": 0.2},
             {"round": 1, "seed": 3, "raise": "a bug in the run"}]
    bars = []

    def progress(total, jobs):  # the progress line's calls, as the local runner makes them
        bars.append(Recorder(total, jobs))
        return bars[-1]

    runs, info = _batch.execute(_batch.probe, items, out_dir=out, failed=_failed, ray=address, inputs=[src],
                                progress=progress)
    a, b, c = runs
    assert a["read"] == "the driver's file"  # shipped: the worker read its own copy
    assert a["out"] == [str(out / "r1/log.txt"), str(out / "r1/sub/trace")]  # paths rewritten to the driver's
    assert (out / "r1/log.txt").read_text() == "one" and (out / "r1/sub/trace").read_text() == "t"
    assert (out / "r2/log.txt").read_text() == "two" and b["out"] == [str(out / "r2/log.txt")]
    assert a["env"] == {"RAF_MIDDLEWARE": "ros1"} == b["env"]
    # a process the run starts hears SIGINT (how the whole stack's nodes are stopped; Ray's worker blocks it)
    assert int(a["child_signals"]["SigBlk"], 16) & (1 << (signal.SIGINT - 1)) == 0
    assert c["error"] == "ValueError: a bug in the run" and c["attempts"] == 1 and "lost_attempts" not in c
    assert info["executor"] == "ray" and info["runs_retried"] == 0 and info["run_attempts"] == 3
    assert info["ray_code_differs_runs"] == 0 and not any("ray_code_differs" in r for r in runs)
    assert sorted(os.listdir(out)) == ["r1", "r2"]  # nothing else came back (the inputs stay on the worker)
    (bar,) = bars
    assert (bar.total, bar.jobs) == (3, 2) and bar.calls[-1] == "close"  # 2 runs at once: the cluster's CPUs
    ends = [c for c in bar.calls if isinstance(c, tuple) and c[1] is not None]
    assert sorted(ok for _, ok, _ in ends) == [False, True, True] and ends[-1][2] == 0  # the failed run counted
    assert max(c[2] for c in bar.calls if isinstance(c, tuple)) == 2  # never more running than the cluster runs


class Recorder:
    """A BatchProgress stand-in that records its calls."""

    def __init__(self, total, jobs):
        self.total, self.jobs, self.calls = total, jobs, []

    def start(self):
        self.calls.append("start")

    def finish(self, ok=True, running=None):
        self.calls.append(("finish", ok, running))

    def close(self):
        self.calls.append("close")


def test_a_worker_on_other_code_is_counted_and_warned_about(cluster, monkeypatch, capsys):
    address, _ = cluster
    monkeypatch.setattr(_batch, "code_fingerprint", lambda: "another-version")  # the driver's; workers hash theirs
    runs, info = _batch.execute(_batch.probe, [{"seed": 1}, {"seed": 2}], failed=_failed, ray=address)
    assert info["ray_code_differs_runs"] == 2 and all(r["ray_code_differs"] for r in runs)
    assert "2 run(s) ran code that differs" in capsys.readouterr().err


def test_bench_batch_prints_a_table_and_writes_flat_json(raf_cmd, tmp_path):
    """``raf bench batch`` at its smallest: one run locally and on a private one-CPU Ray instance."""
    import subprocess

    ray_tmp = tempfile.mkdtemp(prefix="rafray", dir="/tmp")
    out = tmp_path / "batch.json"
    try:
        p = subprocess.run(raf_cmd + ["bench", "batch", "--rounds", "2", "--seeds", "1", "--workers", "1",
                                      "--empty-tasks", "3", "--json", str(out)],
                           env={**os.environ, "RAY_TMPDIR": ray_tmp}, capture_output=True, text=True, timeout=300)
    finally:
        shutil.rmtree(ray_tmp, ignore_errors=True)
    assert p.returncode == 0, p.stderr[-3000:]
    assert "ray_w1_overhead_per_run_s" in p.stdout
    res = json.loads(out.read_text())
    assert all(not isinstance(v, (dict, list)) for v in res.values())
    assert res["runs"] == 1 and res["ray_w1_same_results"] is True
    assert res["local_w1_runs_per_min"] > 0 and res["ray_w1_runs_per_min"] > 0 and res["ray_w1_empty_task_ms"] > 0
    assert res["ray_w1_overhead_per_run_s"] == pytest.approx((res["ray_w1_wall_s"] - res["local_w1_wall_s"]), abs=0.02)
