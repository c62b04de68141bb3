"""``raf bench batch``: how many competition runs a minute the batch runner gets through, locally and on Ray.

The same specs (``raf experiment competition --mode bare_truth``: the agent around the in-process stand-in,
ground truth as its pose, no ROS; default rounds 1 and 2, seeds 100-101) are run by the local runner with 1 and
2 workers (``--jobs``: in this process serially at 1, spawned processes at 2) and by the Ray executor
(experiments/_batch.py) on a private one-machine Ray instance of 1 and 2 CPUs started for it (or on the cluster
``--ray ADDRESS`` names, at its own size). Reported: runs per minute each way, the wall time Ray adds per run
against the local runner at the same number of workers (``(ray wall - local wall) x workers / runs``), the Ray
instance's start (not in the batch's wall) and what a task that plays no round costs on Ray (the executor's
own overhead). Every run's result is checked equal between the two (scores and delivery times). One untimed
run first warms this process (imports, disk cache), as a long batch would be; a Ray worker imports the package
on its first run, which is part of what Ray adds. The load average before and after says how busy the machine
was with other work.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import logging
import os
import re
import statistics
import time

NAME = "batch"
HELP = ("runs per minute of raf experiment competition's batch runner (bare_truth) locally at 1 and 2 workers "
        "and on Ray, and the per-run overhead Ray adds")
TARGETS: dict = {}


def add_arguments(parser) -> None:
    parser.add_argument("--rounds", default="1,2", help="rounds (default 1,2)")
    parser.add_argument("--seeds", type=int, default=2, help="seeds 100..100+N-1 (default 2)")
    parser.add_argument("--workers", default="1,2", help="worker counts, comma-separated (default 1,2)")
    parser.add_argument("--ray", metavar="ADDRESS", default=None,
                        help="measure Ray on this cluster (at its own size) instead of private local instances")
    parser.add_argument("--empty-tasks", type=int, default=20,
                        help="tasks that play no round, to time the executor's own overhead on Ray (default 20)")


def _competition_args(bench_args, **kw) -> argparse.Namespace:
    from ..experiments import competition

    p = argparse.ArgumentParser()
    competition.add_arguments(p)
    a = p.parse_args([])
    a.field = getattr(bench_args, "field", None)
    a.mode, a.rounds, a.first_seed, a.seeds = "bare_truth", bench_args.rounds, 100, bench_args.seeds
    for k, v in kw.items():
        setattr(a, k, v)
    return a


def _batch(args, **kw) -> tuple[float, dict, list]:
    """One batch: (wall s, results, the runs' (round, seed, points, last score s))."""
    from ..experiments import competition

    quiet = io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(quiet):
        res = competition.run(_competition_args(args, **kw), None)
    wall = time.perf_counter() - t0
    keys = sorted(k for k in res if k.endswith(("_points", "_last_score_s", "_error")))
    return wall, res, [(k, res[k]) for k in keys]


def _empty_tasks(n: int, address: str) -> float:
    """Wall seconds for ``n`` tasks that play no round."""
    from ..experiments._batch import execute, probe

    t0 = time.perf_counter()
    runs, _ = execute(probe, [{"seed": i} for i in range(n)], failed=lambda item, e: {"error": str(e)}, ray=address,
                      progress=_Silent)
    assert not any("error" in r for r in runs), runs
    return time.perf_counter() - t0


class _Silent:
    def __init__(self, *a):
        pass

    def start(self):
        pass

    def finish(self, *a, **k):
        pass

    def close(self):
        pass


def run(args) -> dict:
    from ..experiments._batch import import_ray

    ray = import_ray()
    workers = [int(x) for x in str(args.workers).split(",") if x.strip()]
    n = len([r for r in str(args.rounds).split(",") if r.strip()]) * args.seeds
    out: dict = {"mode": "bare_truth (stand-in in process, ground-truth pose, no ROS)", "rounds": args.rounds,
                 "seeds": f"100-{99 + args.seeds}", "runs": n, "ray_version": ray.__version__}
    out["load_avg_1min_at_start"] = round(os.getloadavg()[0], 2)  # other work on the machine skews the figures
    _batch(args, jobs=1, rounds="1", seeds=1)  # warm-up, not timed: this process's imports and the disk cache
    run_walls = []
    for w in workers:
        wall, res, figures = _batch(args, jobs=w)
        out[f"local_w{w}_wall_s"] = round(wall, 2)
        out[f"local_w{w}_runs_per_min"] = round(60 * n / wall, 2)
        run_walls += [v for k, v in res.items() if re.search(r"_r\d+_s\d+_wall_s$", k)]  # each run's own
        if args.ray:
            continue
        t0 = time.perf_counter()
        ray.init(address="local", num_cpus=w, include_dashboard=False, log_to_driver=False,
                 logging_level=logging.WARNING)
        out[f"ray_w{w}_start_s"] = round(time.perf_counter() - t0, 2)
        try:
            rwall, rres, rfigures = _batch(args, ray="local")  # this process's instance (already connected)
            assert rres["executor"] == "ray" and rres["ray_workers"] == w, rres
            if args.empty_tasks:
                e = _empty_tasks(args.empty_tasks, "local")
                out[f"ray_w{w}_empty_task_ms"] = round(1000 * e * w / args.empty_tasks, 1)
        finally:
            ray.shutdown()
        out[f"ray_w{w}_wall_s"] = round(rwall, 2)
        out[f"ray_w{w}_runs_per_min"] = round(60 * n / rwall, 2)
        out[f"ray_w{w}_overhead_per_run_s"] = round((rwall - wall) * w / n, 2)
        out[f"ray_w{w}_same_results"] = rfigures == figures
    if args.ray:
        rwall, rres, rfigures = _batch(args, ray=args.ray)
        w = rres["ray_workers"]
        out.update({"ray_cluster": args.ray, "ray_cluster_nodes": rres["ray_nodes"], "ray_cluster_workers": w,
                    "ray_cluster_wall_s": round(rwall, 2), "ray_cluster_runs_per_min": round(60 * n / rwall, 2),
                    "ray_cluster_same_results": rfigures == figures})
        if args.empty_tasks:
            e = _empty_tasks(args.empty_tasks, args.ray)
            out["ray_cluster_empty_task_ms"] = round(1000 * e * w / args.empty_tasks, 1)
    if run_walls:
        out["run_wall_s_median"] = round(statistics.median(run_walls), 2)
    out["load_avg_1min_at_end"] = round(os.getloadavg()[0], 2)
    return out
