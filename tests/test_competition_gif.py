"""The competition experiment's animated picture: the GIF writer on a tiny synthetic record."""
import math

from PIL import Image

from robotatfactory.experiments._competition_gif import pick_frames, write_gif


def _run(n: int, dt: float = 0.2) -> dict:
    frames = []
    for i in range(n):
        t = i * dt
        x, y, th = -0.5 + 0.01 * i, 0.1 * math.sin(0.1 * i), 0.05 * i
        held = 7 if 10 <= i < 20 else None
        frames.append((t, x, y, th, held, [(7, 0.3, -0.2 + 0.001 * i, 0.0), (8, -0.3, 0.4, math.pi / 2)]))
    events = [(2.0, "picked A from incoming 1", -0.4, 0.0), (4.0, "placed A at machine_A 2", -0.3, 0.05)]
    return {"round": 3, "seed": 0, "points": 1, "max_points": 8, "frames": frames, "events": events}


def test_pick_frames_thins_and_keeps_the_last():
    t = [0.2 * i for i in range(1000)]
    idx = pick_frames(len(t), t, max_frames=50, fps=10.0)
    assert len(idx) <= 50 and idx[0] == 0 and idx[-1] == 999
    assert all(b > a for a, b in zip(idx, idx[1:]))
    # fewer records than the cap, but closer than 1/fps: every other one (0.2 s apart at 0.1 s records)
    t2 = [0.05 * i for i in range(41)]
    idx2 = pick_frames(len(t2), t2, max_frames=300, fps=10.0)
    assert idx2 == list(range(0, 41, 2))


def test_write_gif_writes_an_animated_gif(tmp_path):
    run = _run(30)
    out = write_gif(run, tmp_path / "r3.gif", max_frames=300, fps=10.0)
    im = Image.open(out)
    assert im.format == "GIF"
    assert im.n_frames == 30  # 0.2 s records, at most 10 per simulated second: all kept
    assert out.stat().st_size < 3_000_000


def test_write_gif_caps_the_frame_count(tmp_path):
    out = write_gif(_run(60), tmp_path / "cap.gif", max_frames=12)
    assert Image.open(out).n_frames == 12
