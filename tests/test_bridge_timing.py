"""Camera stamping and the simulation clock (robotatfactory.simtwo.timing): pure, simulated streams."""
from __future__ import annotations

import random
from fractions import Fraction

import pytest

from robotatfactory.simtwo.timing import CameraStamper, Pending, SimClock

P = 40  # ms


def simulate(n_cycles=300, phase=0, fps=60, dec=4, cam_latency=(0.0005, 0.003), realtime=True,
             physics=0.002, render_cost=0.004, drop=0.0, on_grid=True, seed=1):
    """Events (kind, arrival, payload) of a simulator that renders during each cycle and sends the cycle's
    SensorFrame right after; camera frames are delivered with a random latency (they may be overtaken).

    realtime: each cycle starts on the wall clock's 40 ms beat; else (fast lockstep) right after the reply.
    """
    rng = random.Random(seed)
    events = []
    k = phase
    w = 1000.0
    for j in range(n_cycles):
        t_start, t_end = Fraction(P * j, 1000), Fraction(P * (j + 1), 1000)
        if realtime:
            w = max(w, 1000.0 + j * P / 1000)
        while Fraction(k, fps) <= t_start:
            k += dec
        renders = []
        if on_grid:
            while Fraction(k, fps) <= t_end:
                renders.append(Fraction(k, fps))
                k += dec
        elif rng.random() < 0.4:
            renders.append(t_start + Fraction(rng.randint(1, P), 1000))
        w += physics / 2
        for tr in renders:
            w += render_cost
            kind = "cam" if rng.random() >= drop else "lost"  # lost: received, but not stamped (or never seen)
            events.append((kind, w + rng.uniform(*cam_latency), float(tr)))
        w += physics / 2
        events.append(("udp", w + 0.00005, P * (j + 1)))
        w += 0.0003  # the bridge's reply
    events.sort(key=lambda e: e[1])
    return events


def run(stamper, events, count_lost=False):
    """Feed events in arrival order as the bridge would; a camera frame whose stamp is Pending is asked again
    when the next SensorFrame arrives or at its deadline, whichever comes first.

    Lost frames are passed on as ``skipped`` with the next frame when ``count_lost`` (the receiver got them and
    kept only a newer one), else the receiver never saw them.
    """
    out = []
    lost = 0
    pending: list[tuple[float, float, float, int]] = []  # (arrival, truth, deadline, skipped)

    def resolve(now):
        still = []
        for a, truth, dl, skipped in pending:
            est = stamper.stamp(a, now=max(now, a), skipped=skipped)
            if isinstance(est, Pending):
                still.append((a, truth, est.deadline, skipped))
            else:
                out.append((truth, est))
        pending[:] = still

    for kind, a, payload in events:
        # deadlines that passed before this event
        while pending and min(p[2] for p in pending) <= a:
            resolve(min(p[2] for p in pending))
        if kind == "udp":
            stamper.on_sensor_frame(payload, a)
            resolve(a)
        elif kind == "lost":
            lost += count_lost
        else:
            skipped, lost = lost, 0
            est = stamper.stamp(a, now=a, skipped=skipped)
            if isinstance(est, Pending):
                pending.append((a, payload, est.deadline, skipped))
            else:
                out.append((payload, est))
    resolve(float("inf"))
    return out


@pytest.mark.parametrize("phase", [0, 1, 2, 3])
def test_realtime_stream_stamps_are_exact_once_the_phase_is_learned(phase):
    st = CameraStamper(P, 60, 4)
    res = run(st, simulate(phase=phase))
    assert len(res) > 150
    learned = [(t, e) for t, e in res[10:]]
    assert all(e.method == "grid" for _, e in learned), {e.method for _, e in learned}
    assert all(e.stamp == pytest.approx(t, abs=1e-9) for t, e in learned)
    assert st.locked_phase == phase
    # before the lock, every estimate still brackets the truth within its bound
    for t, e in res:
        assert e.lo < t + 1e-9 and t <= e.hi + 1e-9
        assert abs(e.stamp - t) <= e.error_bound + 1e-9


def test_overtaken_frames_are_assigned_to_the_cycle_that_overtook_them():
    # every camera frame arrives 2-4 ms after the SensorFrame that was sent after it
    ev = simulate(cam_latency=(0.0025, 0.0045))
    st = CameraStamper(P, 60, 4)
    res = run(st, ev)
    assert st.counters.overtaken == len(res)
    assert all(e.stamp == pytest.approx(t) for t, e in res[10:])


def test_lockstep_fast_stream_with_short_cycles_and_render_cost():
    # fast lockstep: 2 ms of physics per cycle, 4 ms per render, camera delivered in 0.3-1.1 ms (under half the
    # shortest wall time between SensorFrames); a frame is often overtaken by the SensorFrame sent 1 ms after it
    ev = simulate(realtime=False, physics=0.002, render_cost=0.004, cam_latency=(0.0003, 0.0011), n_cycles=300)
    st = CameraStamper(P, 60, 4)
    res = run(st, ev)
    exact = sum(e.method == "grid" and e.stamp == pytest.approx(t) for t, e in res[10:])
    assert exact == len(res) - 10


def test_slow_camera_delivery_in_a_fast_run_degrades_gracefully():
    """Camera delivery (0.5-2.5 ms) longer than half the wall time between SensorFrames (2.3 ms in cycles
    without a render): brackets are often wrong. The grid still puts most frames right; no stamp is off by
    more than one render-grid step (66.7 ms) and every interval stamp claims its 20 ms bound honestly only
    when its bracket is right, so check what is promised: increasing stamps near the truth."""
    ev = simulate(realtime=False, physics=0.002, render_cost=0.004, cam_latency=(0.0005, 0.0025), n_cycles=600)
    st = CameraStamper(P, 60, 4)
    res = run(st, ev)
    err = np.array([abs(e.stamp - t) for t, e in res])
    stamps = [e.stamp for _, e in res]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
    assert np.all(err <= 0.0667 + 1e-6)
    assert np.mean(err < 1e-9) > 0.5


def delayed(events, share, delay, seed=4):
    """Delay a share of the camera frames by ``delay`` (s, a range) on the wall clock, as a loaded machine
    does; frames stay in order (one TCP stream) so a delayed frame holds back the ones behind it."""
    rng = random.Random(seed)
    out, last_cam = [], 0.0
    for kind, a, p in events:
        if kind == "cam":
            a = max(a + (rng.uniform(*delay) if rng.random() < share else 0.0), last_cam)
            last_cam = a
        out.append((kind, a, p))
    return sorted(out, key=lambda e: e[1])


def test_frames_delayed_by_load_keep_their_exact_stamps():
    """One frame in eight delivered 25-75 ms late (a whole cycle: its bracket is wrong): counting frames
    from the previous tick still puts every one on its tick."""
    st = CameraStamper(P, 60, 4)
    res = run(st, delayed(simulate(n_cycles=600, seed=3), 0.125, (0.025, 0.075)))
    assert all(e.method == "grid" and e.stamp == pytest.approx(t) for t, e in res[10:])
    assert st.counters.sequenced > 0.9 * len(res) and st.counters.rebracketed > 10


def test_frames_the_receiver_skipped_are_counted_and_do_not_disturb_the_stamps():
    st = CameraStamper(P, 60, 4)
    res = run(st, simulate(drop=0.5, n_cycles=600, seed=3), count_lost=True)
    assert all(e.stamp == pytest.approx(t) for t, e in res[10:])
    stamps = [e.stamp for _, e in res]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
    assert st.counters.resyncs == 0


@pytest.mark.parametrize("drop", [0.03, 0.5])
def test_frames_lost_unseen_are_noticed_within_a_few_frames(drop):
    """Frames the receiver never saw (a render the simulator skipped) shift the count one grid step early each:
    the stamper notices within ``max_disagree`` frames or ``max_delay`` (wall, here real time), so each loss
    costs at most ``max_disagree - 1`` wrong stamps, none off by more than ``max_delay``. (The bridge's own
    receiver counts what it skips, so this needs a simulator that skips renders.)"""
    ev = simulate(drop=drop, n_cycles=1200, seed=3)
    st = CameraStamper(P, 60, 4)
    res = run(st, ev)
    truth = [t for t, _ in res]
    lost = [p for kind, _, p in ev if kind == "lost" and p > truth[10]]
    wrong = [(t, e.stamp) for t, e in res[10:] if e.stamp != pytest.approx(t)]
    assert 0 < len(wrong) <= (st.max_disagree - 1) * len(lost)
    assert all(abs(s - t) <= st.max_delay + 1e-9 for t, s in wrong)
    assert st.counters.resyncs > 0
    stamps = [e.stamp for _, e in res]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))


def test_render_clock_off_the_grid_without_the_grid_stays_within_half_a_period():
    st = CameraStamper(P, 60, 4, use_grid=False)
    res = run(st, simulate(on_grid=False, n_cycles=600, seed=5))
    assert len(res) > 100
    assert all(e.method == "interval" for _, e in res)
    for t, e in res:
        assert abs(e.stamp - t) <= e.error_bound + 1e-9
        assert e.error_bound == pytest.approx(0.020)


def test_render_clock_off_the_grid_is_mostly_detected_by_the_consistency_test():
    st = CameraStamper(P, 60, 4)
    res = run(st, simulate(on_grid=False, n_cycles=1500, seed=5))
    interval = sum(e.method == "interval" for _, e in res)
    assert interval > 0.8 * len(res)
    # a chance lock on a free-running clock (use_grid should be off for such a simulator) counts frames from a
    # tick until the arrival times contradict it: never later than the bracket, never more than max_delay
    # (wall, here real time) plus one cycle early
    assert all(abs(e.stamp - t) <= st.max_delay + P / 1000 for t, e in res)


def test_one_wrong_bracket_does_not_unlock_the_phase():
    st = CameraStamper(P, 60, 4)
    ev = simulate(n_cycles=200)
    run(st, ev[:200])
    assert st.locked_phase == 0
    # a frame arriving 30 ms after a SensorFrame although it was rendered in that SensorFrame's cycle
    last_udp = max((e for e in ev[:200] if e[0] == "udp"), key=lambda e: e[1])
    est = st.stamp(last_udp[1] + 0.030, now=last_udp[1] + 0.1)
    assert st.locked_phase == 0
    assert est is not None and est.method in ("interval", "grid")
    res2 = run(st, ev[200:])
    assert all(e.stamp == pytest.approx(t) for t, e in res2[2:])


def test_no_stamp_before_the_first_sensor_frame_and_reset_forgets_everything():
    st = CameraStamper(P, 60, 4)
    assert isinstance(st.stamp(5.0, now=5.0), Pending)  # a SensorFrame may still come
    assert st.stamp(5.0, now=5.1) is None
    assert st.counters.no_clock == 1
    run(st, simulate(n_cycles=100))
    assert st.locked_phase == 0
    st.reset()
    assert st.locked_phase is None
    assert st.stamp(1e6, now=1e6 + 1) is None
    # after the reset the clock restarts from 0 and the stamps follow the new stream
    res = run(st, [(k, a + 5000, p) for k, a, p in simulate(n_cycles=100, phase=2)])
    assert all(e.stamp == pytest.approx(t) for t, e in res[10:])


def test_every_render_tick_published_gives_partial_grid_estimates():
    st = CameraStamper(P, 60, 1)
    res = run(st, simulate(dec=1, n_cycles=50))
    # several frames share a bracket: stamps are nudged to stay increasing and counted
    assert all(e.method == "grid-partial" for _, e in res[10:])
    assert res[0][1].hi == pytest.approx(0.040)  # rendered before the first SensorFrame: its cycle
    stamps = [e.stamp for _, e in res]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
    assert st.counters.conflicts > 0


def test_tick_enumeration_is_exact_at_bracket_edges():
    st = CameraStamper(P, 60, 4)
    # 1/15 s = 66.666.. ms: ticks 0, 4 at 0 and 66.67 ms; bracket (40, 80] holds 66.67 (k=4) only for phase 0
    assert st._ticks(40, 80) == [3, 4]  # 50 ms, 66.67 ms
    assert st._ticks(0, 40) == [1, 2]  # 0 excluded, 40 ms = 2.4 ticks
    assert st._ticks(80, 120) == [5, 6, 7]  # 120 ms is tick 7.2 -> 7 = 116.67; 100 ms = tick 6 included


def test_following_rule_for_a_simulator_rendering_between_cycles():
    """rule="following": frames rendered after a SensorFrame at arbitrary moments (not locked to the cycle)
    are bracketed by the cycle after it, immediately (no waiting), within half a period of the truth."""
    rng = random.Random(2)
    st = CameraStamper(P, 60, 4, use_grid=False, rule="following")
    errs = []
    for j in range(200):
        st.on_sensor_frame(P * (j + 1), 100.0 + 0.04 * j)
        if j % 2:
            frac = rng.uniform(0.05, 0.95)  # rendered part-way through the next cycle, published at once
            truth = (P * (j + 1) + frac * P) / 1000
            est = st.stamp(100.0 + 0.04 * j + frac * 0.04 + 0.002, now=100.0 + 0.04 * j + frac * 0.04 + 0.002)
            assert not isinstance(est, Pending)
            errs.append(abs(est.stamp - truth))
            assert est.error_bound == pytest.approx(0.020)
    assert max(errs) <= 0.020 + 1e-9


def test_bad_settings_are_rejected():
    with pytest.raises(ValueError):
        CameraStamper(0, 60, 4)
    with pytest.raises(ValueError):
        CameraStamper(40, 60, 0)
    with pytest.raises(ValueError):
        CameraStamper(40, 60, 4, max_wait=-1)
    with pytest.raises(ValueError):
        CameraStamper(40, 60, 4, rule="closest")
    with pytest.raises(ValueError):
        CameraStamper(40, 60, 4, max_disagree=0)
    with pytest.raises(ValueError):
        CameraStamper(40, 60, 4, max_delay=0)


def test_sim_clock_real_time_factor():
    c = SimClock()
    for j in range(50):
        c.on_sensor_frame(40 * j, 100.0 + 0.01 * j)  # 40 ms sim per 10 ms wall: 4x
    assert c.time_ms == 40 * 49
    assert c.real_time_factor(now=100.49) == pytest.approx(4.0, rel=0.05)
    c.reset()
    assert c.time_ms is None and c.real_time_factor() == 0.0


# ---- LIDAR sweeps -------------------------------------------------------------------------------------

import numpy as np  # noqa: E402

from robotatfactory.simtwo.scan import PerRayAssembler as SweepAssembler  # noqa: E402


class Ranger:
    """SimTwo's ranger2d schedule, as the stand-in simulator runs it: ray value = its global counter."""

    def __init__(self, n=360, period=0.2, dt=0.001):
        self.n, self.period_ns, self.dt_ns = n, int(period * 1e9), int(dt * 1e9)
        self.arr = np.full(n, -1.0)
        self.step = 0
        self.measured_at = {}  # global ray counter -> step

    def cycle(self, steps=40):
        for _ in range(steps):
            prev = (self.step * self.n * self.dt_ns) // self.period_ns
            self.step += 1
            c = (self.step * self.n * self.dt_ns) // self.period_ns
            for g in range(prev, c):
                self.arr[g % self.n] = g
                self.measured_at[g] = self.step
        return self.step, self.arr.copy()


def test_sweeps_are_reassembled_in_time_order():
    rg = Ranger()
    sa = SweepAssembler(360, 0.2, 0.001)
    sweeps = []
    for _ in range(26):  # 1.04 s
        step, arr = rg.cycle()
        sweeps += sa.add(step, arr)
    assert [s.index for s in sweeps] == [0, 1, 2, 3, 4]
    for s in sweeps:
        assert s.missing == 0
        assert np.array_equal(s.ranges, s.index * 360 + np.arange(360))  # every ray of that sweep, in order
        assert s.t0 == pytest.approx(s.index * 0.2 + 0.001)
        assert s.time_increment == pytest.approx(0.2 / 360, rel=0.01)
        # ray i measured within one physics step of t0 + i * increment
        i = np.arange(360)
        truth = np.array([rg.measured_at[s.index * 360 + k] * 0.001 for k in i])
        assert np.allclose(truth, [sa.ray_time(s.index * 360 + k) for k in i])
        assert np.max(np.abs(truth - (s.t0 + i * s.time_increment))) <= 0.001 + 1e-12


def test_lost_frames_leave_nan_rays_and_a_long_gap_skips_sweeps():
    rg = Ranger()
    sa = SweepAssembler(360, 0.2, 0.001)
    got = []
    for j in range(40):
        step, arr = rg.cycle()
        if j in (7, 20, 21, 22, 23, 24, 25, 26, 27):  # lose one frame, then eight in a row
            continue
        got += sa.add(step, arr)
    # losing one 40 ms frame loses nothing (its rays are still in the next array, until overwritten a sweep later)
    by = {s.index: s for s in got}
    assert by[1].missing == 0
    assert sum(s.missing for s in got) > 0  # the long gap
    for s in got:
        ok = ~np.isnan(s.ranges)
        assert np.array_equal(s.ranges[ok], (s.index * 360 + np.arange(360))[ok])
    idx = [s.index for s in got]
    assert idx == sorted(set(idx))


def test_joining_mid_sweep_publishes_only_complete_sweeps():
    rg = Ranger()
    for _ in range(7):
        rg.cycle()
    sa = SweepAssembler(360, 0.2, 0.001)
    got = []
    for _ in range(12):
        got += sa.add(*rg.cycle())
    assert got and all(s.missing == 0 for s in got)
    assert got[0].index == 1


def test_a_simulator_catching_up_in_bursts_is_stamped_by_the_grid():
    """A real-time simulator that fell behind runs cycles back to back: the next cycle's camera frame then
    arrives within the overtake window after a SensorFrame. The grid (ticks already used) still gets it right."""
    ev = simulate(n_cycles=300, realtime=True)
    # make cycles 100-160 a burst: 1 ms apart on the wall clock (shift every event of those cycles)
    burst = []
    for kind, a, p in ev:
        burst.append((kind, a, p))
    t_burst = 1000.0 + 100 * 0.040
    out = []
    for kind, a, p in burst:
        if a >= t_burst:
            cyc = (a - 1000.0) / 0.040
            if cyc < 160:
                a = t_burst + (cyc - 100) * 0.004  # 4 ms per cycle instead of 40
            else:
                a = a - 60 * 0.036
        out.append((kind, a, p))
    out.sort(key=lambda e: e[1])
    st = CameraStamper(P, 60, 4)
    res = run(st, out)
    assert all(e.stamp == pytest.approx(t) for t, e in res[10:])


# ---- SimTwo's timing: renders in the GUI loop, no grid of simulation time (the bridge's defaults) -----------

def simtwo_events(seed, seconds=20.0, frame_latency=(0.001, 0.004), load=None, gui=None):
    """Events of a SimTwo-like stream from the stand-in's model of SimTwo's GUI loop (sim/camera.py
    RenderCadence): each GUI turn runs its 17 ms physics chunks at once -- the script's SensorFrame leaves when
    the chunk reaches its 40 ms step -- then renders; every 4th render leaves over ZMQ right after. Camera
    frames take ``frame_latency`` (plus, with ``load = (p, d)``, an extra delay up to ``d`` with probability
    ``p``: a loaded receiver); SensorFrames 0.05-0.3 ms. Payload of a frame: (true render time ms, extra ms)."""
    from robotatfactory.sim.camera import RenderCadence

    c = RenderCadence("simtwo", 0.001, 60, 4, seed, gui)
    rng = random.Random(seed + 100)
    events = []
    for it in c.iterations():
        if it.first_step > seconds * 1000:
            break
        for k in range(-(-it.first_step // P), (it.first_step + it.steps - 1) // P + 1):
            if k > 0:  # the script at Tms = 40 k runs before the physics step after it
                sent = it.start + (P * k - it.first_step) * c.gui.physics_per_step
                events.append(("udp", sent + rng.uniform(5e-5, 3e-4), P * k))
        if it.frame is not None:
            extra = rng.uniform(0, load[1]) if load and rng.random() < load[0] else 0.0
            events.append(("cam", it.sent + rng.uniform(*frame_latency) + extra, (it.frame.step, extra * 1000)))
    events.sort(key=lambda e: e[1])
    return events


def rafsim_events(seed, seconds=20.0, paced=True, compute=(0.004, 0.015), frame_latency=(0.0005, 0.003)):
    """Events of ``raf sim`` with its default (SimTwo-like) camera timing. ``paced`` (realtime): the cycle is
    computed from the previous SensorFrame's time on, then each frame and the SensorFrame leave when their
    simulation time has come (sim/runner.py); else (fast) all of the cycle's frames leave in a burst just
    before its SensorFrame, at 10x real time (frames may be overtaken by it)."""
    from robotatfactory.sim.camera import RenderCadence

    frames = RenderCadence("simtwo", 0.001, 60, 4, seed).frames()
    f = next(frames)
    rng = random.Random(seed + 200)
    events = []
    scale = 1.0 if paced else 0.1
    for k in range(1, int(seconds * 1000 / P)):
        T = P * k
        done = ((T - P) / 1000 + rng.uniform(*compute)) * scale
        while f.step <= T:
            sent = max(done, f.step / 1000 * scale) if paced else done
            events.append(("cam", sent + rng.uniform(*frame_latency), (f.step, 0.0)))
            f = next(frames)
            done += 2e-5
        sent = max(done, T / 1000 * scale) if paced else done + 1e-4
        events.append(("udp", sent + rng.uniform(5e-5, 3e-4), T))
    events.sort(key=lambda e: e[1])
    return events


def bridge_stamper(**overrides):
    """A stamper built as ``raf bridge``'s camera node builds it, from its default parameters (+ overrides)."""
    from robotatfactory.ros.camera_node import camera_stamper
    from robotatfactory.ros.config import load_config

    return camera_stamper(load_config({"camera": overrides} if overrides else None))


OLD_DEFAULTS = {"bracket": "nearest", "use_grid": True}  # raf bridge's camera stamping before issue 9


def errors_ms(stamper, events):
    """(stamp - true render time) in ms for every stamped frame, and each frame's extra delay (ms)."""
    res = run(stamper, [(k, a, p[0] if k == "cam" else p) for k, a, p in events])
    extra = {p[0]: p[1] for k, _, p in events if k == "cam"}
    return [(est.stamp * 1000 - truth, extra[truth]) for truth, est in res]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_default_stamps_are_within_a_cycle_on_simtwos_gui_timing(seed):
    """SimTwo-like timing: every default stamp within one control cycle (40 ms) of the true render time,
    most much closer; raf bridge's old defaults (nearest SensorFrame, render grid) put frames a cycle or
    more off: they take the SensorFrame that left just before the frame for the end of its cycle."""
    ev = simtwo_events(seed)
    new = errors_ms(bridge_stamper(), ev)
    assert len(new) > 250
    assert max(abs(e) for e, _ in new) <= P
    assert sorted(abs(e) for e, _ in new)[int(0.9 * len(new))] <= 20
    old = errors_ms(bridge_stamper(**OLD_DEFAULTS), ev)
    assert sum(abs(e) > P for e, _ in old) > 0.1 * len(old)


@pytest.mark.parametrize("paced", [True, False])
def test_default_stamps_are_within_a_cycle_on_raf_sims_timing(paced):
    """raf sim's default: realtime (frames leave when their time has come) and fast (a burst before the
    SensorFrame, sometimes overtaken by it): within a cycle either way; the old defaults are not."""
    ev = rafsim_events(4, paced=paced)
    new = errors_ms(bridge_stamper(), ev)
    st = bridge_stamper()
    run(st, [(k, a, p[0] if k == "cam" else p) for k, a, p in ev])
    assert len(new) > 250 and max(abs(e) for e, _ in new) <= P
    if paced:  # the wall clock tells where in the cycle the frame was rendered
        assert sorted(abs(e) for e, _ in new)[int(0.9 * len(new))] <= 5
    else:
        assert st.rate() == pytest.approx(10, rel=0.1)
    old = errors_ms(bridge_stamper(**OLD_DEFAULTS), ev)
    assert max(abs(e) for e, _ in old) > P


def test_default_stamps_under_load_are_late_by_no_more_than_the_delay():
    """A loaded receiver (one frame in five read up to 60 ms late): a stamp is never early by more than a
    cycle and never late by more than a cycle plus that frame's own delay; frames not delayed stay within a
    cycle."""
    ev = simtwo_events(5, load=(0.2, 0.06))
    res = errors_ms(bridge_stamper(), ev)
    assert sum(d > 20 for _, d in res) > 20
    for e, d in res:
        assert -P <= e <= P + d, (e, d)
    assert all(abs(e) <= P for e, d in res if d == 0.0)


def test_elapsed_rule_follows_the_stream_rate_and_clamps_to_the_cycle():
    st = CameraStamper(P, 60, 4, use_grid=False, rule="elapsed", latency=0.0)
    assert st.stamp(1.0, now=1.0) is None and st.counters.no_clock == 1
    for j in range(30):  # half real time: 40 ms of simulation every 80 ms of wall time
        st.on_sensor_frame(P * (j + 1), 1.0 + 0.08 * j)
    assert st.rate() == pytest.approx(0.5)
    a_last = 1.0 + 0.08 * 29
    est = st.stamp(a_last + 0.04, now=a_last + 0.04)
    assert est.method == "elapsed" and est.stamp == pytest.approx((P * 30 + 20) / 1000)
    assert (est.lo, est.hi) == pytest.approx((P * 30 / 1000, P * 31 / 1000))
    # long after: the next SensorFrame is overdue, so first wait for it (up to wait_overdue); none came:
    # clamped to the cycle's end
    wait = st.stamp(a_last + 0.5, now=a_last + 0.5)
    assert isinstance(wait, Pending) and wait.deadline == pytest.approx(a_last + 0.5 + st.wait_overdue)
    late = st.stamp(a_last + 0.5, now=wait.deadline)
    assert late.stamp == pytest.approx(P * 31 / 1000) and st.counters.clamped == 1 and st.counters.waited == 1
    again = st.stamp(a_last + 0.6, now=a_last + 0.6 + st.wait_overdue)  # the same bound: nudged, increasing
    assert again.stamp == pytest.approx(P * 31 / 1000 + 0.001) and st.counters.conflicts == 1
    with pytest.raises(ValueError):
        CameraStamper(P, 60, 4, rule="grid")


@pytest.mark.render
def test_default_stamps_against_the_stand_in_simulator(field, robot):
    """The stand-in's frames (SimConfig default camera_timing "simtwo", their true render times) sent as
    SimTwo's GUI would send them (the same seeded GUI model gives the SensorFrames' send times): the
    bridge's default stamps are within a cycle of every frame's simulation time, the old defaults are not."""
    from robotatfactory.sim import SimConfig, Simulator
    from robotatfactory.sim.camera import RenderCadence
    from robotatfactory.simtwo import Command

    s = Simulator(field, robot, SimConfig(seed=9, competition=False, lidar=False))
    frames = []
    for _ in range(75):  # 3 s
        s.step_cycle(Command(0.2, 0.4, False))
        frames.extend(s.take_frames())
    s.close()
    c = RenderCadence("simtwo", s.dt, 60, 4, 9)
    events = [("cam", fr.wall + 0.002, (round(fr.time * 1000), 0.0)) for fr in frames]
    for it in c.iterations():
        if it.first_step > 3000:
            break
        for k in range(max(1, -(-it.first_step // P)), (it.first_step + it.steps - 1) // P + 1):
            events.append(("udp", it.start + (P * k - it.first_step) * c.gui.physics_per_step + 1e-4, P * k))
    events.sort(key=lambda e: e[1])
    assert 38 <= len(frames) <= 44 and all(round(fr.time * 1000) % 17 == 0 for fr in frames)
    new = errors_ms(bridge_stamper(), events)
    assert len(new) == len(frames) and max(abs(e) for e, _ in new) <= P
    old = errors_ms(bridge_stamper(**OLD_DEFAULTS), events)
    assert max(abs(e) for e, _ in old) > P


def test_elapsed_rule_waits_for_an_overdue_sensor_frame():
    """A loaded bridge process passes a SensorFrame's timing on late: a frame arriving more than 1.5 cycles
    after the last SensorFrame known waits for it (never longer than wait_overdue) and is then stamped after
    it, not a cycle early; frames in the normal rhythm never wait."""
    st = CameraStamper(P, 60, 4, use_grid=False, rule="elapsed", latency=0.0)
    for j in range(10):
        st.on_sensor_frame(P * (j + 1), 1.0 + 0.04 * j)
    a9 = 1.0 + 0.04 * 9
    on_time = st.stamp(a9 + 0.03, now=a9 + 0.03)
    assert on_time.stamp == pytest.approx((P * 10 + 30) / 1000) and st.counters.waited == 0
    # the frame rendered after Tms 440 arrives at a9 + 0.085; the SensorFrame of Tms 440 (kernel arrival
    # a9 + 0.08) reaches the stamper only at a9 + 0.1
    early = st.stamp(a9 + 0.085, now=a9 + 0.085)
    assert isinstance(early, Pending)
    st.on_sensor_frame(P * 11, a9 + 0.08)
    est = st.stamp(a9 + 0.085, now=a9 + 0.1)
    assert est.stamp == pytest.approx((P * 11 + 5) / 1000, abs=1e-3) and st.counters.waited == 1  # after 440
