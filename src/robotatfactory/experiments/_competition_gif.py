"""Animated top view (GIF) of one competition run, from the record ``play_round(record_path=True)`` keeps.

The record's ``frames`` are ``(t s, x m, y m, theta rad, held part id or None, [(part id, x, y, yaw)])`` in the
world frame (ground truth, every 5 control cycles = 0.2 s); ``events`` are ``(t, text, x, y)``. The picture shows
the field (walls/ribs, slots), the parts (the held one in orange), the robot's base outline and heading, the path
so far, the pick/place events that have happened and the simulation time in the corner. Frames are thinned so
the GIF has at most ``max_frames`` frames and at most ``fps`` frames per simulated second.
"""
from __future__ import annotations

import math
from pathlib import Path


def pick_frames(n: int, t: list[float], max_frames: int, fps: float) -> list[int]:
    """Indices into a record of ``n`` frames at times ``t`` (s): records at least 1/fps s apart, then evenly
    thinned to at most ``max_frames``; the first and the last record always in."""
    if n == 0 or max_frames < 1:
        return []
    cand, next_t = [], -math.inf
    for i in range(n):
        if t[i] >= next_t - 1e-9:
            cand.append(i)
            next_t = t[i] + 1.0 / fps
    if cand[-1] != n - 1:
        cand.append(n - 1)
    if len(cand) <= max_frames:
        return cand
    if max_frames == 1:
        return [n - 1]
    k = len(cand) - 1
    return [cand[round(j * k / (max_frames - 1))] for j in range(max_frames)]


def write_gif(run: dict, path: Path, mode: str = "bare_truth", field_name: str | None = None,
              max_frames: int = 300, fps: float = 10.0, dpi: int = 60) -> Path:
    """Write the animated top view of ``run`` to ``path`` (a .gif, matplotlib's PillowWriter); the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from PIL import Image
    from matplotlib.patches import Polygon, Rectangle
    from matplotlib.transforms import Affine2D

    from ..field import load_field
    from ..robot import load_robot

    field = load_field(field_name) if field_name else load_field()
    robot = load_robot()
    frames = run.get("frames") or []
    if not frames:
        raise ValueError("the run has no frames (play_round(record_path=True) records them)")
    idx = pick_frames(len(frames), [f[0] for f in frames], max_frames, fps)
    bx, by = float(robot.base["size"][0]), float(robot.base["size"][1])
    pw, pd = float(field.part.width), float(field.part.depth)

    fig, ax = plt.subplots(figsize=(7.5, 5.5))
    for b in field.boxes:
        cx, cy, sx, sy = b.center[0], b.center[1], b.size[0], b.size[1]
        rect = Rectangle((cx - sx / 2, cy - sy / 2), sx, sy, color="0.55")
        rect.set_transform(Affine2D().rotate_around(cx, cy, b.yaw) + ax.transData)
        ax.add_patch(rect)
    for s in field.slots:
        ax.plot(*s.xy, marker="s", ms=3, color="0.8", zorder=1)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"round {run.get('round', '?')} seed {run.get('seed', '?')} ({mode}): "
                 f"{run.get('points', '?')}/{run.get('max_points', '?')} points", fontsize=10)
    fig.tight_layout()
    # what moves is drawn on top of a still background each frame (blitting), not the whole figure again
    (trail,) = ax.plot([], [], lw=0.8, color="tab:blue", zorder=2, animated=True)
    body = Polygon([[0, 0]] * 4, closed=True, fc="tab:blue", ec="k", alpha=0.6, zorder=4, animated=True)
    ax.add_patch(body)
    (nose,) = ax.plot([], [], lw=2, color="k", zorder=5, animated=True)
    parts: dict = {}
    picks = ax.scatter([], [], marker="^", s=40, color="tab:green", zorder=6, label="picked", animated=True)
    places = ax.scatter([], [], marker="v", s=40, color="tab:red", zorder=6, label="placed", animated=True)
    ax.legend(loc="upper right", fontsize=7)
    clock = ax.text(0.01, 0.98, "", transform=ax.transAxes, va="top", fontsize=10, family="monospace",
                    bbox=dict(fc="white", ec="0.7", alpha=0.8), animated=True)
    events = run.get("events") or []
    xs = [f[1] for f in frames]
    ys = [f[2] for f in frames]

    def box(x, y, th, lx, ly):
        c, s = math.cos(th), math.sin(th)
        return [(x + c * u - s * v, y + s * u + c * v) for u, v in
                ((-lx / 2, -ly / 2), (lx / 2, -ly / 2), (lx / 2, ly / 2), (-lx / 2, ly / 2))]

    path = Path(path)
    fig.set_dpi(dpi)
    canvas = fig.canvas
    canvas.draw()
    background = canvas.copy_from_bbox(fig.bbox)
    images = []
    for i in idx:
        t, x, y, th, held, plist = frames[i]
        trail.set_data(xs[: i + 1], ys[: i + 1])
        body.set_xy(box(x, y, th, bx, by))
        nose.set_data([x, x + 0.12 * math.cos(th)], [y, y + 0.12 * math.sin(th)])
        for pid, px, py, pyaw in plist:
            if pid not in parts:
                parts[pid] = Polygon([[0, 0]] * 4, closed=True, fc="tab:purple", ec="k", lw=0.5, zorder=3,
                                     animated=True)
                ax.add_patch(parts[pid])
            parts[pid].set_xy(box(px, py, pyaw, pd, pw))
            parts[pid].set_facecolor("tab:orange" if pid == held else "tab:purple")
        done = [e for e in events if e[0] <= t]
        for sc, kind in ((picks, "picked"), (places, "placed")):
            pts = [(e[2], e[3]) for e in done if str(e[1]).startswith(kind)]
            sc.set_offsets(pts if pts else [[math.nan, math.nan]])
        clock.set_text(f"t = {t:6.1f} s")
        canvas.restore_region(background)
        for a in sorted([trail, *parts.values(), body, nose, picks, places, clock], key=lambda a: a.get_zorder()):
            ax.draw_artist(a)
        images.append(Image.fromarray(np.asarray(canvas.buffer_rgba())[..., :3].copy()))
    # one palette for the whole film, taken from its last frame (it has every colour the others have)
    palette = images[-1].quantize(colors=64)
    film = [im.quantize(palette=palette, dither=Image.Dither.NONE) for im in images]
    film[0].save(path, save_all=True, append_images=film[1:], duration=round(1000 / min(fps, 10.0)), loop=0)
    plt.close(fig)
    return path
