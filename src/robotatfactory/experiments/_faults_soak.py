"""The soak part of ``raf experiment faults`` (see :mod:`.faults`): its processes' memory over a long run."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np


def rss_kib(pid: int) -> int | None:
    """Resident memory of a process (KiB), None when it is gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except OSError:
        return None
    return None


def children(pid: int) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if int((d / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                    out.append(int(d.name))
            except (OSError, IndexError, ValueError):
                pass
    return out


def part_soak(args, log_dir: Path, robot) -> dict:
    from .faults import Rig, circles  # faults imports this module for PARTS: imported here, not at the top

    (log_dir / "soak").mkdir(parents=True, exist_ok=True)
    sim_s = args.soak_sim_seconds if args.soak_sim_seconds is not None else args.soak_minutes * 60
    rig = Rig(args, log_dir / "soak", camera=True, localize=True, fast=True, lockstep=True).up()
    w, px = rig.watch, rig.proxy
    samples: list[tuple] = []  # (sim s, {name: rss KiB})
    lags: list[tuple] = []  # (sim s, odom lag s, image lag s)
    try:
        w.drive(circles())
        wall0 = time.monotonic()

        def procs():
            out = {}
            for n in ("sim", "bridge", "localize"):
                p = rig.procs.get(n)
                out[n] = p.pid
                if n == "bridge":
                    for c in children(p.pid):
                        out["bridge_camera"] = c
            out["roscore"] = rig.master.proc.pid
            return out

        pids = procs()
        while True:
            rig.check()
            with px.lock:
                t_sim = px.frames[-1][2] / 1000 if px.frames else 0.0
            with w.lock:  # how far behind the simulator the odom and image subscribers are (queues)
                odom_ms = w.odom[-1][1] if w.odom else 0
                img_ms = w.images[-1][1] if w.images else 0
            lags.append((t_sim, t_sim - odom_ms / 1000, t_sim - img_ms / 1000))
            samples.append((t_sim, {n: rss_kib(p) for n, p in pids.items()}))
            if t_sim >= sim_s:
                break
            time.sleep(2.0)
        wall = time.monotonic() - wall0
        w.stop_drive()
        time.sleep(1.5)
        d = w.stream_diag()
        with w.lock:
            diag = {k: dict(v) for k, v in w.diag.items()}
    finally:
        rig.down()
    out = {"soak_sim_seconds": round(samples[-1][0], 1), "soak_wall_seconds": round(wall, 1),
           "soak_samples": len(samples)}
    warm = [s for s in samples if s[0] >= 0.2 * samples[-1][0]]
    worst = 0.0
    for n in samples[0][1]:
        series = [s[1][n] for s in warm if s[1].get(n)]
        if len(series) < 3:
            continue
        k = max(1, len(series) // 10)
        start, end = float(np.median(series[:k])), float(np.median(series[-k:]))
        g = 100.0 * (end - start) / start
        out[f"soak_rss_{n}_mib"] = round(end / 1024, 1)
        out[f"soak_rss_{n}_growth_pct"] = round(g, 2)
        worst = max(worst, g)
    out["soak_rss_growth_max_pct"] = round(worst, 2)
    out["soak_rss_growth_max_target_met"] = worst < 5.0
    late = [x for x in lags if x[0] >= 0.2 * lags[-1][0]]
    if late:
        half = len(late) // 2
        for i, n in ((1, "odom"), (2, "image")):
            a = float(np.median([x[i] for x in late[:max(1, half)]]))
            b = float(np.median([x[i] for x in late[half:]]))
            out[f"soak_{n}_lag_early_s"], out[f"soak_{n}_lag_late_s"] = round(a, 3), round(b, 3)
        out["soak_queue_lag_late_s"] = max(out["soak_odom_lag_late_s"], out["soak_image_lag_late_s"])
        out["soak_queue_lag_late_target_met"] = out["soak_queue_lag_late_s"] <= 1.0
    for k in ("accepted", "lost", "duplicates", "stale", "held", "restarts", "rejected_foreign_source"):
        if k in d:
            out[f"soak_bridge_{k}"] = int(float(d[k]))
    for name, vals in diag.items():
        if "camera" in name:
            for k in ("received", "published", "skipped", "rejected_wrong_size"):
                if k in vals:
                    out[f"soak_camera_{k}"] = int(float(vals[k]))
    out["soak_frames_sent_by_sim"] = len(px.frames)
    return out
