"""The batch executor (experiments/_batch.py) without a cluster: the local runners, what travels to a Ray worker
and back (paths swapped, files packed), and the errors. On a Ray cluster: tests/test_competition_ray.py."""
from __future__ import annotations

import functools
import os
import sys
from pathlib import Path

import pytest

from robotatfactory.errors import ConfigError
from robotatfactory.experiments import _batch


class Progress:
    """A BatchProgress stand-in that records its calls."""

    made: list = []

    def __init__(self, total, jobs):
        self.total, self.jobs, self.calls = total, jobs, []
        Progress.made.append(self)

    def start(self):
        self.calls.append("start")

    def finish(self, ok=True, running=None):
        self.calls.append(("finish", ok, running))

    def close(self):
        self.calls.append("close")


@pytest.mark.parametrize("local,jobs", [("threads", 2), ("processes", 1), ("processes", 2)])
def test_local_runners_keep_the_order_and_count_every_run(local, jobs, tmp_path):
    Progress.made.clear()
    items = [{"seed": s, "sleep": 0.3 if s == 0 else 0.0, "write": {f"s{s}.txt": str(s)}} for s in range(3)]
    runs, info = _batch.execute(_batch.probe, items, jobs=jobs, local=local, out_dir=tmp_path, progress=Progress)
    assert [r["seed"] for r in runs] == [0, 1, 2]  # the items' order, though seed 0 ends last
    assert info == {"executor": "local", "runs_retried": 0}
    assert [(tmp_path / f"s{s}.txt").read_text() for s in range(3)] == ["0", "1", "2"]  # out_dir is the driver's
    pids = {r["pid"] for r in runs}
    assert (pids == {os.getpid()}) == (local == "threads" or jobs == 1)  # processes: a spawned pool
    (bar,) = Progress.made
    assert bar.total == 3 and bar.jobs == jobs and bar.calls[-1] == "close"
    assert sum(1 for c in bar.calls if isinstance(c, tuple) and c[1] is True) == 3


def test_swap_points_paths_through_partials_tuples_and_dicts():
    job = functools.partial(_batch.probe, calibration="/d/cal.yaml", other="/d/cal.yaml.bak")
    where = {"/d/cal.yaml": "/w/0_cal.yaml", "/out": "/w/out"}
    s = _batch._swap(job, where)
    assert s.func is _batch.probe and s.keywords == {"calibration": "/w/0_cal.yaml", "other": "/d/cal.yaml.bak"}
    assert _batch._swap((1, "/out/full_r1_s2/sim.log", ["/outside"], {"k": Path("/out")}), where) == \
        (1, "/w/out/full_r1_s2/sim.log", ["/outside"], {"k": Path("/w/out")})
    assert _batch._swap("/output", where) == "/output"  # a prefix only at a directory boundary


def test_pack_and_unpack_carry_a_directory_and_refuse_names_outside_it(tmp_path):
    src = tmp_path / "src"
    (src / "a" / "b").mkdir(parents=True)
    (src / "a" / "b" / "trace.jsonl").write_bytes(b"x" * 10000)
    (src / "top.log").write_text("log")
    (src / "link").symlink_to(src / "top.log")
    files = _batch._pack(src)
    assert sorted(files) == ["a/b/trace.jsonl", "top.log"]  # regular files only
    assert len(files["a/b/trace.jsonl"]) < 1000  # compressed
    _batch._unpack(files, tmp_path / "dst")
    assert (tmp_path / "dst" / "a" / "b" / "trace.jsonl").read_bytes() == b"x" * 10000
    for bad in ("../escape", "/etc/x", "a/../../x"):
        with pytest.raises(ValueError, match="outside"):
            _batch._unpack({bad: files["top.log"]}, tmp_path / "dst")
    assert not (tmp_path / "escape").exists()


def test_without_ray_the_option_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray: ImportError
    with pytest.raises(ConfigError, match="Ray is not installed.*requirements.txt"):
        _batch.execute(_batch.probe, [{}], ray="auto", failed=lambda i, e: {})


def test_ray_is_imported_only_for_ray(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)
    runs, info = _batch.execute(_batch.probe, [{"seed": 4}], jobs=1, progress=Progress)
    assert runs[0]["seed"] == 4 and info["executor"] == "local"


def test_competition_refuses_ray_where_it_does_not_apply(tmp_path):
    from expargs import options

    from robotatfactory.experiments import competition

    with pytest.raises(ConfigError, match="--analyse .*--ray"):
        competition.run(options(competition, mode="full_stack", analyse=str(tmp_path), rounds="1", seeds=1,
                                ray="auto"), None)


def test_the_code_fingerprint_is_stable_and_names_the_checkout():
    a = _batch.code_fingerprint()
    assert _batch.code_fingerprint() == a and len(a) == 16


def test_a_dead_worker_s_directory_is_swept(tmp_path, monkeypatch):
    import subprocess
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    dead = tmp_path / f"raf-batch-{p.pid}-abc"
    live = tmp_path / f"raf-batch-{os.getppid()}-abc"
    for d in (dead, live):
        d.mkdir()
    _batch._sweep()
    assert not dead.exists() and live.exists()
