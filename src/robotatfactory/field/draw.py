"""Top view of the field with matplotlib: floor markers with IDs, wall markers with their facing
direction, walls and ribs, part slots, start area, team areas and beacons."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .model import Field

ZONE_COLOURS = {"incoming": "#d62728", "outgoing": "#1f77b4", "machine_A": "#ff7f0e", "machine_B": "#2ca02c"}


def draw_field(field: Field, ax=None, show_slots: bool = True, show_team_areas: bool = True):
    """Draw ``field`` onto a matplotlib axes (a new figure when ``ax`` is None); returns the axes."""
    import matplotlib

    if ax is None:
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(12, 8.8))
    from matplotlib.patches import Circle, Polygon, Rectangle

    fx, fy = field.floor.x, field.floor.y
    ax.add_patch(Rectangle((fx[0], fy[0]), fx[1] - fx[0], fy[1] - fy[0], fc="#f4f1ea", ec="k", lw=1.2))
    sa = field.start_area
    ax.add_patch(Rectangle((sa.x[0], sa.y[0]), sa.x[1] - sa.x[0], sa.y[1] - sa.y[0], fc="#fff3b0",
                           ec="#b59b00", lw=1, ls="--"))
    ax.text(sa.center[0], sa.y[0] + 0.015, "start area", ha="center", va="bottom", fontsize=8, color="#8a7500")
    sp = field.start_pose
    ax.annotate("", xy=(sp.x + 0.08 * np.cos(sp.theta), sp.y + 0.08 * np.sin(sp.theta)), xytext=(sp.x, sp.y),
                arrowprops=dict(arrowstyle="->", color="#8a7500", lw=1.5))
    if show_team_areas:
        for t in field.team_areas:
            ax.add_patch(Rectangle((t.x[0], t.y[0]), t.x[1] - t.x[0], t.y[1] - t.y[0], fc="none",
                                   ec="#9467bd", lw=1, ls=":"))
        for (bx, by) in field.beacons:
            ax.add_patch(Circle((bx, by), field.beacon_diameter / 2, fc="#c5b0d5", ec="#9467bd", lw=0.8))
    for b in field.boxes:
        ax.add_patch(Polygon(b.footprint(), closed=True, fc="#7f7f7f", ec="#404040", lw=0.6))
    if show_slots:
        p = field.part
        for s in field.slots:
            c, sn = np.cos(s.facing), np.sin(s.facing)
            # part footprint: depth along the facing direction, width across it
            hx, hy = p.depth / 2, p.width / 2
            local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
            poly = local @ np.array([[c, sn], [-sn, c]]) + np.asarray(s.xy)
            col = ZONE_COLOURS[s.zone]
            ax.add_patch(Polygon(poly, closed=True, fc=col, alpha=0.18, ec=col, lw=1, ls="--"))
            plate = np.asarray(s.xy) + np.array([c, sn]) * hx
            ax.plot(*zip(plate - np.array([-sn, c]) * p.plate[0] / 2, plate + np.array([-sn, c]) * p.plate[0] / 2),
                    color=col, lw=2.5, solid_capstyle="butt")
            label = {"store": "", "input": " in", "output": " out"}[s.role]
            ax.text(s.xy[0] - c * 0.006, s.xy[1] - sn * 0.006, f"{s.number}{label}", ha="center", va="center",
                    fontsize=6.5, color=col, fontweight="bold", rotation=90 if abs(c) > 0.5 else 0)
    for m in field.floor_markers():
        cs = m.corners[:, :2]
        ax.add_patch(Polygon(cs, closed=True, fc="black", ec="black"))
        ax.text(*m.position[:2], str(m.id), color="white", ha="center", va="center", fontsize=7, fontweight="bold")
    for m in field.wall_markers():
        pos, n = m.position[:2], m.normal[:2]
        across = np.array([-n[1], n[0]]) * m.size / 2
        ax.plot(*zip(pos - across, pos + across), color="black", lw=4, solid_capstyle="butt")
        # ID and facing arrow drawn beside the marker (along the wall) so that slot labels stay readable
        side = np.array([-n[1], n[0]]) * (m.size / 2 + 0.022)
        ax.annotate("", xy=pos + side + n * 0.035, xytext=pos + side, arrowprops=dict(arrowstyle="-|>", color="#d62728", lw=0.9))
        ax.text(*(pos + side + n * 0.05), str(m.id), color="#d62728", ha="center", va="center", fontsize=7,
                fontweight="bold")
    for zone, (x, y) in {"incoming warehouse": (-0.47, 0.47), "outgoing warehouse": (0.47, -0.47),
                         "machine A": (-0.3475, 0.135), "machine B": (0.3475, -0.135)}.items():
        ax.text(x, y, zone, ha="center", va="center", fontsize=8, style="italic", color="#404040")
    ax.annotate("", xy=(0.1, 0), xytext=(0, 0), arrowprops=dict(arrowstyle="->", color="#d62728", lw=1.5))
    ax.annotate("", xy=(0, 0.1), xytext=(0, 0), arrowprops=dict(arrowstyle="->", color="#2ca02c", lw=1.5))
    ax.set_xlim(fx[0] - 0.12, fx[1] + 0.12)
    ax.set_ylim(fy[0] - 0.1, fy[1] + 0.1)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"RobotAtFactory 4.0 field '{field.name}': floor markers (black, IDs), wall markers "
                 "(red arrows: facing), slots, start area", fontsize=9)
    ax.grid(True, lw=0.3, alpha=0.5)
    return ax


def save_field_png(field: Field, path: str | Path, dpi: int = 110) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(12, 8.8))
    draw_field(field, ax)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
