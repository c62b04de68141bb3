"""``raf experiment localization``'s figures (matplotlib, no ROS): per route the trajectories in the map
and the errors against time, from the recorded arrays and the error series of
:func:`._localization_analysis.analyse`."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ._localization_analysis import LABELS


def figures(d: dict, errs: dict, field, route_pts, out_dir: Path, t_end: float | None, prefix: str = "localization",
            title: str = "") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..field.draw import draw_field
    from ..localization.metrics import odometry_in_map, interpolate

    gt = d["gt"]
    if t_end is not None:
        gt = gt[gt[:, 0] <= t_end + 1e-9]
    fig, ax = plt.subplots(figsize=(11, 8))
    draw_field(field, ax)
    ax.plot(route_pts[:, 0], route_pts[:, 1], ":", color="0.6", lw=1, label="route (waypoints)")
    ax.plot(gt[:, 1], gt[:, 2], "k-", lw=2, label="ground truth")
    if len(d["odom"]):
        odo = d["odom"] if t_end is None else d["odom"][d["odom"][:, 0] <= t_end + 1e-9]
        start = interpolate(odo[:1, 0], gt[:, 0], gt[:, 1:4])[0]
        om = odometry_in_map(odo[:, 1:4], tuple(start))
        ax.plot(om[:, 0], om[:, 1], "-", color="tab:orange", lw=1.2, label="odometry alone")
    c = d["closest"]
    if len(c):
        ax.plot(c[:, 1], c[:, 2], ".", color="tab:red", ms=3, alpha=0.6, label="closest marker (paper)")
    p = d["planar"]
    if len(p):
        ax.plot(p[:, 1], p[:, 2], ".", color="tab:green", ms=2, alpha=0.6, label="planar fit")
    e = d["ekf"]
    if len(e):
        e = e if t_end is None else e[e[:, 0] <= t_end + 1e-9]
        ax.plot(e[:, 1], e[:, 2], "-", color="tab:blue", lw=1, label="EKF")
    ax.set_xlim(field.floor.x[0] - 0.12, field.floor.x[1] + 0.12)
    ax.set_ylim(field.floor.y[0] - 0.12, field.floor.y[1] + 0.12)
    ax.set_aspect("equal")
    ax.legend(loc="upper right", fontsize=8, framealpha=0.9)
    ax.set_title(f"raf experiment localization: trajectories in map {title}")
    fig.tight_layout()
    fig.savefig(out_dir / f"{prefix}_trajectory.png", dpi=110)
    plt.close(fig)

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(11, 7), sharex=True)
    t0 = gt[0, 0]
    styles = {"odometry": ("tab:orange", "-", None), "closest": ("tab:red", "", "."),
              "all_pnp": ("tab:purple", "", "."), "planar": ("tab:green", "", "."), "ekf": ("tab:blue", "-", None)}
    for m, (col, ls, mk) in styles.items():
        if m not in errs or not len(errs[m][0]):
            continue
        te, ep, eh = errs[m]
        kw = dict(color=col, linestyle=ls or "none", marker=mk, ms=2, lw=1, label=LABELS[m])
        a1.semilogy(te - t0, np.maximum(ep * 100, 1e-3), **kw)
        a2.semilogy(te - t0, np.maximum(np.degrees(eh), 1e-3), **kw)
    a1.axhline(1.0, color="k", lw=0.6, ls="--")
    a2.axhline(1.0, color="k", lw=0.6, ls="--")
    a1.set_ylabel("position error (cm)")
    a2.set_ylabel("heading error (deg)")
    a2.set_xlabel("simulation time (s)")
    a1.legend(fontsize=8, ncol=3)
    a1.set_title(f"errors against ground truth {title} (dashed: the 1 cm / 1 deg targets of the EKF)")
    fig.tight_layout()
    fig.savefig(out_dir / f"{prefix}_errors.png", dpi=110)
    plt.close(fig)
