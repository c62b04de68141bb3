"""The fault campaign's observer (experiments/_faults_observe.py) on synthetic truth and messages: a correct
bridge passes, each kind of poisoned message is caught, whatever its stamp."""
from __future__ import annotations

import math

import numpy as np
import pytest

from robotatfactory.experiments import _faults_observe as ob
from robotatfactory.localization.odometry import DiffDriveOdometry

GEO = ob.Geometry(wheel_radius=0.035, track=0.2, ticks_per_rev=1000)
RAYS = 8


def truth(n=60, t0_wall=10.0, seq0=0, tms0=40, start_totals=(0, 0), v_l=20, v_r=30, wall_step=0.04):
    """n frames of a robot turning left (ticks per cycle v_l, v_r, changing a little), one per 40 ms."""
    rows, ranges = [], []
    left, right = start_totals
    for i in range(n):
        left += v_l + (i % 3)
        right += v_r + (i % 5)
        rows.append((t0_wall + i * wall_step, seq0 + i, tms0 + 40 * i, left, right, 0.01 * i, 0.0, 0.02 * i))
        ranges.append(1.0 + 0.01 * i + 0.1 * np.arange(RAYS))
    return np.array(rows, dtype=float), np.array(ranges)


def bridge(tr, idx=None, from_zero=True, lag=0.002, forge=None):
    """What a correct bridge publishes for frames ``idx`` of ``tr`` (``forge``: {index: totals} it took
    instead of the genuine ones)."""
    idx = range(len(tr)) if idx is None else idx
    odo = DiffDriveOdometry(wheel_radius=GEO.wheel_radius, track=GEO.track, ticks_per_rev=GEO.ticks_per_rev)
    odo.reset(baseline=(0, 0), t=0.0) if from_zero else odo.reset()
    p = ob.Published()
    for i in idx:
        w, _, tms, left, right = tr[i, :5]
        if forge and i in forge:
            left, right = forge[i]
        s = odo.update(int(left), int(right), tms / 1000)
        p.odom.append((w + lag, int(tms), s.x, s.y, s.theta))
        p.tf.append((w + lag, int(tms), s.x, s.y, s.theta))
        p.clock.append((w + lag, int(tms)))
        p.joints.append((w + lag, int(tms), s.left_angle, s.right_angle))
    return p


def seen_after(p, wall):
    """The part of ``p`` a watcher sees when it connects at ``wall`` (the messages that arrive after it)."""
    return ob.Published(*[[m for m in x if m[0] > wall] for x in (p.odom, p.clock, p.joints, p.tf, p.scans)])


def test_a_correct_bridge_is_not_poisoned():
    tr, rg = truth()
    o = ob.Observer(tr, bridge(tr), GEO, bridge_starts=[0.0], ranges=rg)
    assert o.poisoned == []
    assert o.counts()["odom"] == len(tr)
    errs = o.odometry_errors()
    assert len(errs) == len(tr) and errs[:, 2].max() < 1e-9
    assert o.joint_errors_ticks().max() == 0


def test_a_pose_from_forged_ticks_with_a_genuine_stamp_is_caught():
    """The frame at index 20 forged with impossible wheel counts but the genuine Seq and Tms: its stamp
    passes, its pose (and every pose after it, integrated from there) does not."""
    tr, _ = truth()
    forged = {20: (int(tr[20, 3]) + 4000, int(tr[20, 4]) - 4000)}
    o = ob.Observer(tr, bridge(tr, forge=forged), GEO)
    odom_bad = [x for x in o.poisoned if x.topic == "odom"]
    assert odom_bad and odom_bad[0].stamp_ms == tr[20, 2]
    assert all(x.why == "pose of no genuine odometry" for x in odom_bad)
    assert any(x.topic == "joints" and x.stamp_ms == tr[20, 2] for x in o.poisoned)
    assert any(x.topic == "tf" for x in o.poisoned)


def test_stamps_no_genuine_frame_supports_are_caught():
    tr, _ = truth()
    p = bridge(tr)
    p.odom.append((tr[-1, 0] + 0.01, int(tr[-1, 2]) + 10_000_000, 0.0, 0.0, 0.0))  # far-ahead Tms
    p.clock.append((tr[5, 0] - 0.5, int(tr[5, 2])))  # a genuine Tms, but before the simulator sent it
    o = ob.Observer(tr, p, GEO)
    whys = {(x.topic, x.why) for x in o.poisoned}
    assert ("odom", "stamp of no frame the simulator had sent") in whys
    assert ("clock", "stamp of no frame the simulator had sent") in whys


def test_the_clock_goes_back_only_at_a_genuine_restart():
    a, _ = truth(n=30)
    b, _ = truth(n=30, t0_wall=a[-1, 0] + 2.0)  # a restarted simulator: Seq and Tms from the start again
    tr = np.vstack([a, b])
    p = ob.Published(clock=[(r[0] + 0.002, int(r[2])) for r in tr])
    assert ob.Observer(tr, p, GEO).poisoned == []
    # a clock that goes back within one run (a forged "clock going back" frame with an old genuine Tms)
    p.clock.insert(20, (a[19, 0] + 0.003, int(a[3, 2])))
    bad = ob.Observer(tr, p, GEO).poisoned
    assert [x.why for x in bad] == ["clock back or repeated without a simulator restart"]


def test_odometry_from_zero_after_a_restart_and_from_its_first_frame_after_a_bridge_restart():
    a, _ = truth(n=30)
    b, _ = truth(n=40, t0_wall=a[-1, 0] + 2.0)
    tr = np.vstack([a, b])
    p1 = bridge(a)
    p2 = bridge(b)  # the same bridge saw the new run start at Seq 0: from zero
    # the bridge killed after b[14], restarted before b[15]: its baseline is the first frame it got
    restart_wall = b[15, 0] - 0.01
    p3 = bridge(tr, idx=range(len(a) + 15, len(tr)), from_zero=False)
    p = ob.Published(*[x + y + [m for m in z if m[0] > restart_wall]
                       for x, y, z in zip((p1.odom, p1.clock, p1.joints, p1.tf, p1.scans),
                                          (p2.odom[:15], p2.clock[:15], p2.joints[:15], p2.tf[:15], []),
                                          (p3.odom, p3.clock, p3.joints, p3.tf, p3.scans))])
    o = ob.Observer(tr, p, GEO, bridge_starts=[0.0, restart_wall])
    assert o.poisoned == []
    assert o.resets() == 1
    assert o.first_valid("odom", b[0, 0], epoch=1) == pytest.approx(b[0, 0] + 0.002)
    # a restarted bridge that kept its old pose instead of starting at its first frame is caught
    shifted = [(m[0], m[1], m[2] + 0.05, m[3], m[4]) for m in p3.odom]
    p.odom = p1.odom + p2.odom[:15] + shifted
    assert {x.topic for x in ob.Observer(tr, p, GEO, bridge_starts=[0.0, restart_wall]).poisoned} == {"odom"}


def test_a_restarted_bridge_whose_first_messages_the_observer_missed_while_the_robot_moved():
    """CI's failure: the restarted bridge took its baseline at its first frame, the watcher's subscription
    connected six frames later, the robot turning meanwhile. The baseline is recovered from the first
    joint_states seen (the genuine frame with those totals), not taken as the first frame seen; a baseline
    no genuine frame after the bridge's start has is still caught."""
    tr, _ = truth(n=60)
    restart_wall = tr[20, 0] - 0.01
    first_seen = 26
    p_all = bridge(tr, idx=range(20, len(tr)), from_zero=False)  # the bridge's baseline: frame 20
    p = seen_after(p_all, tr[first_seen, 0])
    o = ob.Observer(tr, p, GEO, bridge_starts=[0.0, restart_wall])
    assert o.poisoned == []
    assert o.tracks()[(1, 0)]["baseline_frame"] == 20
    # what the experiment reports: the six frames (20-25) published before the watcher's first message
    assert o.tracks()[(1, 0)]["unseen"] == list(range(20, 26))
    assert o.unseen_at_join(1) == (6, pytest.approx(tr[26, 0] - tr[20, 0]))
    assert o.unseen_at_join(0) == (0, 0.0)
    assert o.odometry_errors()[:, 2].max() < 1e-9
    # the same messages from a bridge whose baseline was a frame sent before it started: no genuine frame
    # after its start explains them
    p_old = bridge(tr, idx=range(15, len(tr)), from_zero=False)
    p = seen_after(p_old, tr[first_seen, 0])
    bad = ob.Observer(tr, p, GEO, bridge_starts=[0.0, restart_wall]).poisoned
    assert {x.topic for x in bad} == {"odom", "tf", "joints"}


def test_a_lossy_bridge_is_not_poisoned_and_stays_within_the_chord_bound():
    tr, _ = truth(n=80)
    rng = np.random.default_rng(1)
    fates = np.where(rng.random(len(tr)) < 0.2, ob.DROPPED, ob.FORWARDED)
    fates[0] = ob.FORWARDED
    kept = [i for i in range(len(tr)) if fates[i] == ob.FORWARDED]
    o = ob.Observer(tr, bridge(tr, idx=kept), GEO)
    assert o.poisoned == []
    b = ob.chord_bound(tr, fates, GEO)
    errs = o.odometry_errors()
    assert b["runs"] > 5 and b["worst_m"] > 0
    assert 0 < errs[:, 2].max() <= b["bound_m"]
    assert errs[:, 3].max() < 1e-9  # the heading stays exact: the totals are cumulative


def test_chord_error_is_zero_on_a_constant_arc_and_not_when_the_curvature_changes():
    const = np.array([[0, 0], [10, 20], [20, 40], [30, 60]], dtype=float)
    assert ob.chord_error(const, GEO) < 1e-12
    bent = np.array([[0, 0], [10, 30], [40, 40]], dtype=float)
    assert ob.chord_error(bent, GEO) > 1e-5
    assert ob.missing_runs(np.array([0, 1, 1, 0, 2, 0, 3, 1])) == [(1, 2), (4, 4), (7, 7)]


def test_scan_ranges_must_be_rays_of_genuine_frames_in_the_sweep_window():
    tr, rg = truth()
    good = (tr[30, 0] + 0.01, float(tr[25, 2]) + 1.0, rg[30].astype(np.float32))
    nan_and_inf = rg[31].copy()
    nan_and_inf[0], nan_and_inf[1] = np.nan, np.inf  # self-hits and no return are not values
    forged = rg[30].copy()
    forged[3] = 7.5
    old = (tr[55, 0], float(tr[55, 2]), rg[2])  # genuine rays, but from a frame far outside the window
    p = ob.Published(scans=[good, (tr[31, 0] + 0.01, float(tr[26, 2]), nan_and_inf),
                            (tr[30, 0] + 0.01, float(tr[25, 2]), forged), old])
    o = ob.Observer(tr, p, GEO, ranges=rg)
    assert o.scans_checked == 4
    assert [x.stamp_ms for x in o.poisoned] == [float(tr[25, 2]), float(tr[55, 2])]
    assert ob.Observer(tr, p, GEO).scans_checked == 0  # no ranges recorded: nothing checked, nothing claimed


def test_unreadable_messages_are_poisoned_not_a_crash():
    tr, rg = truth()
    p = bridge(tr)
    p.odom += [(tr[-1, 0] + 1, None, 0, 0, 0), (float("nan"), 40, 0, 0, 0), (tr[-1, 0] + 1, int(tr[-1, 2]), "x", 0, 0)]
    p.joints.append((tr[-1, 0] + 1, int(tr[-1, 2]), None, 0.0))
    p.scans.append((tr[-1, 0] + 1, float("inf"), [1.0]))
    p.scans.append((tr[-1, 0] + 1, float(tr[10, 2]), [1.0, 2.0]))  # the wrong number of rays
    o = ob.Observer(tr, p, GEO, ranges=rg)
    assert len(o.poisoned) >= 6
    assert ob.Observer(np.zeros((0, 8)), p, GEO).poisoned  # no truth at all: everything is unsupported


def test_poisoned_messages_are_attributed_to_the_segment_they_follow():
    tr, _ = truth()
    p = bridge(tr)
    p.clock.append((tr[40, 0] + 0.01, 999_999))
    p.clock.append((tr[5, 0] + 0.01, 999_998))
    o = ob.Observer(tr, p, GEO)
    segs = [("a", tr[10, 0], tr[20, 0]), ("b", tr[30, 0], tr[35, 0])]
    assert o.by_segment(segs) == {"a": 0, "b": 1, "outside": 1}
    assert len(o.poisoned_in(tr[30, 0], math.inf)) == 1


def test_at_rest_is_judged_from_the_ground_truth_above_a_resting_robots_jitter():
    """faults.at_rest on synthetic frames: a robot turning at 0.5 rad/s gets its last command applied at frame
    10; the stop decision comes 0.44 s later (the timeout plus a cycle), the motion decays over two cycles, and
    then the body jitters by up to 2.2 mrad a cycle with a creeping tick now and then, as SimTwo's does: at rest
    two cycles after the stop, not at the last jitter sample; and a robot still turning at the end is never at
    rest."""
    from robotatfactory.experiments.faults import at_rest

    rows, th, left, right = [], 0.0, 0, 0
    jitter = [0.0022, -0.0015, 0.0013, -0.0022, 0.0009, 0.0021, -0.0019, 0.001]
    for i in range(60):
        t_rel = (i - 11) * 0.04  # the start of the cycle frame i reports, after the last command's frame
        if t_rel < 0.44:
            dth, dl, dr = 0.02, -3, 3
        elif t_rel < 0.52:
            dth, dl, dr = (0.008 if t_rel < 0.48 else 0.005), -1, 1
        else:
            dth, dl, dr = jitter[i % len(jitter)], 0, (1 if i % 7 == 0 else 0)
        th += dth
        left, right = left + dl, right + dr
        rows.append((100.0 + 0.04 * i, i, 40 * (i + 1), left, right, 0.0, 0.0, th))
    tr = np.array(rows, dtype=float)
    replies = [(100.0 + 0.04 * 9 + 0.01, 9)]  # the last reply answers frame 9: applied from frame 10
    r = at_rest(tr, replies, t_kill=100.0 + 0.04 * 9 + 0.005, until=200.0)
    assert r["restart_bridge_stop_s"] == pytest.approx(0.44)
    assert r["restart_bridge_at_rest_s"] == pytest.approx(0.52)
    assert r["restart_bridge_at_rest_after_death_s"] == pytest.approx(0.04 * 23 - 0.04 * 9 - 0.005, abs=1e-6)
    still_turning = tr.copy()
    still_turning[30:, 7] += 0.01 * np.arange(30)  # 0.25 rad/s to the end
    assert math.isnan(at_rest(still_turning, replies, 100.0, 200.0)["restart_bridge_at_rest_s"])


def test_the_proxy_records_a_frame_before_the_bridge_can_have_it(monkeypatch):
    """The observer matches each published message to a frame on the proxy's record, so a frame must be on it
    before it goes out: here the proxy's thread stalls 0.2 s after each send (as a preempted thread may), and
    the bridge's side finds every frame it receives already recorded."""
    import socket
    import time

    from robotatfactory.experiments._faults_net import LOCAL, Proxy
    from robotatfactory.simtwo import SensorFrame

    bridge = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    bridge.bind((LOCAL, 0))
    bridge.settimeout(2.0)
    proxy = Proxy((LOCAL, bridge.getsockname()[1]))
    out = proxy._out

    def stalled(direction, data, addr):
        fate = out(direction, data, addr)
        time.sleep(0.2)
        return fate

    monkeypatch.setattr(proxy, "_out", stalled)
    sim = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for seq in range(3):
            frame = SensorFrame(seq=seq, time_ms=40 * (seq + 1), enc_delta=(0, 0), enc_total=(seq, seq), x=0, y=0,
                                theta=0, contact=False, magnet=False)
            sim.sendto(frame.encode(), (LOCAL, proxy.port))
            got = SensorFrame.decode(bridge.recv(65535))
            recorded = [int(r[1]) for r in proxy.truth()]
            assert seq in recorded, f"frame {seq} reached the bridge before the proxy recorded it: {recorded}"
            assert got.seq == seq
    finally:
        proxy.close()
        sim.close()
        bridge.close()
