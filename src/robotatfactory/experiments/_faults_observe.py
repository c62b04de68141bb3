"""``raf experiment faults``, the observer: what the bridge published against what the simulator sent.

Plain Python and numpy, no ROS, so it is tested on synthetic data (tests/test_faults_observe.py). It trusts
nothing the bridge says about itself (no counter, no diagnostics, no log): its inputs are

* the **truth**: every SensorFrame the simulator sent, as the experiment's proxy recorded it on arrival
  (:meth:`._faults_net.Proxy.truth`: wall time, Seq, Tms, cumulative encoder totals, ground-truth pose; the
  LIDAR ranges and what the proxy did with each frame when asked), before any loss or fuzz;
* the **published** messages, as this experiment's own node received them (:class:`._faults_watch.Watch`):
  ``odom``, ``/clock``, ``joint_states``, TF ``odom -> base_link`` and ``scan``, each with its arrival (wall)
  and stamp;
* the wall times the experiment itself (re)started the bridge (its own actions).

**Poisoned** = a published value that no genuine frame supports, whatever the bridge counted:

* a stamp (``odom``, ``/clock``, ``joint_states``, TF) that is not the ``Tms`` of a frame the simulator had sent
  before the message arrived;
* a pose (``odom``, TF) other than the odometry integrated over the genuine frames' encoder totals at the
  stamps the bridge published, in the simulator's order, from the bridge's baseline (zero when it saw the
  stream start at ``Seq`` 0, else the first frame it accepted, recovered from its first ``joint_states``
  when this observer missed its first messages; :meth:`Observer.tracks`): a frame with forged totals and a
  genuine stamp changes the pose there and after it;
* a stamp that goes back, or repeats, within one bridge process and one simulator run (``odom``, TF,
  ``joint_states``); a ``/clock`` step back other than to a later simulator run (a genuine restart);
* wheel angles (``joint_states``) other than the genuine totals at the stamp, from the same baseline (within
  half a tick);
* a finite LIDAR range (``scan``) that no genuine frame of the sweep's window (stamp - 2 cycles to stamp + 2
  sweep periods + 2 cycles) has on that ray.

The pose tolerance (:data:`POSE_TOL_M`, :data:`POSE_TOL_RAD`) is float rounding plus the chord error of a
frame whose four messages all missed the observer (below 1e-7 m at the campaign's speeds); a forged frame
moves the pose by centimetres (hundreds of ticks) and its heading by radians.

Beside the poison check, :meth:`Observer.odometry_errors` gives each ``odom`` message's distance from the
odometry over *every* genuine frame (what a loss-free bridge would have said), and :func:`chord_bound` the
bound for a lossy segment: the frames the proxy did not deliver in order each cost a correct odometry the
chord error of the arc it then integrates over the gap (the heading stays exact: the totals are cumulative),
computed on the genuine frames, so the error at any message is at most the sum over the gaps so far.
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np

PERIOD_MS = 40  # the control period (ms): SimTwo's script and raf sim
SWEEP_MS = 200  # the LIDAR's sweep period (ms)
POSE_TOL_M = 1e-5
POSE_TOL_RAD = 1e-5
RANGE_TOL = 1e-4  # m: a range travels as ASCII, then float64, then float32 in the LaserScan
RESTART_MAX_SEQ = 25  # a stream from zero starts at Seq <= this (the bridge's stream/reorder_window)

#: what the proxy did with a frame (``Proxy.fates``)
FORWARDED, DROPPED, DELAYED, DUPLICATED = 0, 1, 2, 3


@dataclass(frozen=True)
class Geometry:
    wheel_radius: float
    track: float
    ticks_per_rev: int

    @classmethod
    def of(cls, robot) -> "Geometry":
        return cls(robot.wheel_radius, robot.odometry_track, robot.ticks_per_rev)

    @property
    def rad_per_tick(self) -> float:
        return 2 * math.pi / self.ticks_per_rev


@dataclass
class Published:
    """What the bridge published, as received: lists of tuples, the first two always (wall s, stamp ms)."""

    odom: list = field(default_factory=list)  # (wall, stamp_ms, x, y, theta)
    clock: list = field(default_factory=list)  # (wall, stamp_ms)
    joints: list = field(default_factory=list)  # (wall, stamp_ms, left rad, right rad)
    tf: list = field(default_factory=list)  # (wall, stamp_ms, x, y, theta): odom -> base_link
    scans: list = field(default_factory=list)  # (wall, stamp_ms (float), ranges)


@dataclass(frozen=True)
class Poison:
    topic: str
    wall: float
    stamp_ms: float
    why: str


def _wrap(a: float) -> float:
    return math.remainder(a, 2 * math.pi)


def _integrate(x, y, th, dl, dr, track):
    """The exact constant-curvature arc of one step (the published diff-drive model)."""
    ds, dth = (dl + dr) / 2, (dr - dl) / track
    half = dth / 2
    k = 1.0 - half * half / 6.0 if abs(half) < 1e-4 else math.sin(half) / half
    return x + ds * k * math.cos(th + half), y + ds * k * math.sin(th + half), _wrap(th + dth)


def odometry(totals: np.ndarray, geo: Geometry, baseline=None) -> np.ndarray:
    """Pose (x, y, theta) after each row of cumulative ``totals`` (n x 2), starting at pose 0 at ``baseline``
    (the first row's totals when None)."""
    out = np.zeros((len(totals), 3))
    if not len(totals):
        return out
    m = geo.rad_per_tick * geo.wheel_radius
    prev = totals[0] if baseline is None else np.asarray(baseline, dtype=float)
    x = y = th = 0.0
    for i, t in enumerate(totals):
        x, y, th = _integrate(x, y, th, (t[0] - prev[0]) * m, (t[1] - prev[1]) * m, geo.track)
        prev = t
        out[i] = (x, y, th)
    return out


class Observer:
    """Matches every published message to the genuine frame it claims to come from and checks its values.

    ``truth``: (n, 8) rows wall, Seq, Tms, left total, right total, x, y, theta in the order the simulator sent
    them; ``ranges``: (n, rays) or None (no scan check); ``bridge_starts``: wall times the bridge was
    (re)started, ascending; ``fates``: what the proxy did with each of those frames (:data:`FORWARDED`, ...),
    kept for the caller (empty: not given)."""

    def __init__(self, truth: np.ndarray, published: Published, geo: Geometry, bridge_starts=(0.0,),
                 ranges: np.ndarray | None = None, fates: np.ndarray | None = None):
        self.truth = np.asarray(truth, dtype=float).reshape(-1, 8)
        self.fates = np.zeros(0, dtype=int) if fates is None else np.asarray(fates, dtype=int)
        self.pub, self.geo = published, geo
        self.starts = sorted(float(s) for s in bridge_starts) or [float("-inf")]
        self.ranges = None if ranges is None or len(ranges) != len(self.truth) else np.asarray(ranges, dtype=float)
        tms = self.truth[:, 2]
        # a simulator run ends where its clock goes back (a restart: a new process, Tms from the start)
        self.epoch = np.concatenate([[0], np.cumsum(np.diff(tms) < 0)]).astype(int) if len(tms) else np.zeros(0, int)
        self._by_tms: dict[int, list[int]] = {}
        for i, t in enumerate(tms.astype(np.int64)):
            self._by_tms.setdefault(int(t), []).append(i)
        self.poisoned: list[Poison] = []
        self.matched: dict[str, list] = {}  # topic -> [(message index, frame index or -1)]
        self._tracks: dict = {}
        self._run()

    # -- matching ------------------------------------------------------------------------------------------
    def instance(self, wall: float) -> int:
        """Which bridge process published a message that arrived at ``wall``."""
        return max(0, bisect.bisect_right(self.starts, wall) - 1)

    def frame_of(self, wall: float, stamp_ms) -> int:
        """The genuine frame with ``Tms`` = stamp sent before ``wall`` (the latest such), or -1."""
        try:
            key = int(round(float(stamp_ms)))
        except (TypeError, ValueError, OverflowError):
            return -1
        if not math.isfinite(float(stamp_ms)) or abs(float(stamp_ms) - key) > 0.5:
            return -1
        best = -1
        for i in self._by_tms.get(key, ()):
            if self.truth[i, 0] <= wall:
                best = i
        return best

    def _poison(self, topic, msg, why):
        self.poisoned.append(Poison(topic, float(msg[0]), float(msg[1]) if _num(msg[1]) else float("nan"), why))

    # -- tracks: one bridge process x one simulator run ------------------------------------------------------
    def tracks(self) -> dict:
        """(instance, epoch) -> {"frames": published frame indices ascending, "from_zero": bool, "poses": {i:
        (x, y, theta)}, "angles": {i: (left, right)}, "baseline": totals, "baseline_frame": the frame whose
        totals those are (None from zero), "unseen": the frames a bridge that joined mid-run published before
        the first message seen (its baseline frame and the delivered ones after it; empty when the first
        message seen is its baseline's)}: the odometry over the genuine frames the bridge published (and, for a
        bridge that joined mid-run, the unseen ones between its baseline frame and the first seen)."""
        return self._tracks

    def unseen_at_join(self, inst: int) -> tuple[int, float]:
        """(frames, s): what bridge process ``inst`` published in its first simulator run before this observer's
        first message from it (see :meth:`tracks`' "unseen"), and the wall time from the first of those frames
        to the first seen (the simulator's send times); (0, 0.0) when nothing was missed or nothing seen."""
        keys = sorted(k for k in self._tracks if k[0] == inst)
        if not keys:
            return 0, 0.0
        t = self._tracks[keys[0]]
        if not t["unseen"]:
            return 0, 0.0
        return len(t["unseen"]), float(self.truth[t["frames"][0], 0] - self.truth[t["unseen"][0], 0])

    def _build_tracks(self, used: dict) -> None:
        g = self.geo
        for key, idx in used.items():
            inst, ep = key
            idx = sorted(set(idx))
            first = int(np.flatnonzero(self.epoch == ep)[0])
            r0 = self.truth[first]
            # the bridge saw this run start (it was up before the run's first frame) at Seq 0: totals from zero
            from_zero = (self.starts[inst] <= r0[0] and 0 <= r0[1] <= RESTART_MAX_SEQ
                         and 0 <= r0[2] <= (RESTART_MAX_SEQ + 1) * PERIOD_MS + PERIOD_MS // 2)
            start = None if from_zero else self._joined_at(key, idx[0])
            # the frames the bridge integrated: the unseen ones after its baseline frame, then those it published
            between = [] if start is None else self._delivered(start + 1, idx[0])
            rows = between + idx
            # what the bridge published before this observer's first message (a bridge that joined mid-run)
            unseen = [] if start is None or start == idx[0] else [start] + between
            totals = self.truth[rows, 3:5]
            baseline = (0.0, 0.0) if from_zero else tuple(self.truth[start, 3:5])
            poses = odometry(totals, g, baseline)
            base = np.asarray(baseline)
            angles = (totals - base) * g.rad_per_tick
            self._tracks[key] = {"frames": idx, "from_zero": from_zero, "baseline": baseline, "baseline_frame": start,
                                 "unseen": unseen,
                                 "poses": {i: tuple(p) for i, p in zip(rows, poses)},
                                 "angles": {i: tuple(a) for i, a in zip(rows, angles)}}

    def _joined_at(self, key, first_seen: int) -> int:
        """The frame a bridge that joined a simulator run mid-stream took as its baseline: the first frame it
        accepted, which this observer may not have seen (a subscriber connects to a restarted publisher a
        moment after its first messages, and the robot may move meanwhile). Recovered from the earliest
        ``joint_states`` message of the track (its angles are the genuine totals at its stamp minus the
        baseline's): the latest genuine frame of the run, sent after the bridge started and not after the
        first frame seen published, with those totals. A baseline no such frame has (a forged or kept one)
        leaves the first frame seen published, so every pose and angle from it is checked against that."""
        inst, ep = key
        joints = [(i, self.pub.joints[k]) for k, i in self.matched.get("joints", ())
                  if i >= 0 and self.instance(self.pub.joints[k][0]) == inst and int(self.epoch[i]) == ep]
        if not joints:
            return first_seen
        i, msg = min(joints, key=lambda x: x[0])
        if len(msg) < 4 or not (_num(msg[2]) and _num(msg[3])):
            return first_seen
        est = self.truth[i, 3:5] - np.array([float(msg[2]), float(msg[3])]) / self.geo.rad_per_tick
        rows = np.flatnonzero((self.epoch == ep) & (np.arange(len(self.truth)) <= first_seen)
                              & (self.truth[:, 0] >= self.starts[inst]))
        hit = rows[np.all(np.abs(self.truth[rows, 3:5] - est) <= 0.5, axis=1)]
        return int(hit[-1]) if len(hit) else first_seen

    def _delivered(self, a: int, b: int) -> list[int]:
        """Frames a..b-1 the proxy delivered in order (all of them when no fates were given)."""
        rows = np.arange(a, b)
        if len(self.fates) != len(self.truth):
            return rows.tolist()
        return rows[~undelivered(self.fates[a:b])].tolist()

    def _run(self) -> None:
        p = self.pub
        topics = {"odom": p.odom, "clock": p.clock, "joints": p.joints, "tf": p.tf}
        used: dict = {}
        for topic, msgs in topics.items():
            m = []
            for k, msg in enumerate(msgs):
                if len(msg) < 2 or not _num(msg[0]):
                    self._poison(topic, (float("nan"), float("nan")), "unreadable message")
                    m.append((k, -1))
                    continue
                i = self.frame_of(msg[0], msg[1])
                m.append((k, i))
                if i < 0:
                    self._poison(topic, msg, "stamp of no frame the simulator had sent")
                    continue
                used.setdefault((self.instance(msg[0]), int(self.epoch[i])), []).append(i)
            self.matched[topic] = m
        self._build_tracks(used)
        for topic in ("odom", "tf", "joints"):
            last: dict = {}
            for k, i in self.matched[topic]:
                if i < 0:
                    continue
                msg = topics[topic][k]
                key = (self.instance(msg[0]), int(self.epoch[i]))
                if key in last and i <= last[key]:
                    self._poison(topic, msg, "stamp back or repeated within one simulator run")
                last[key] = max(i, last.get(key, -1))
                tr = self._tracks[key]
                if topic == "joints":
                    a = tr["angles"][i]
                    half = 0.5 * self.geo.rad_per_tick
                    if not (_close(msg[2], a[0], half) and _close(msg[3], a[1], half)):
                        self._poison(topic, msg, "wheel angles of no genuine totals")
                    continue
                x, y, th = tr["poses"][i]
                if not (_num(msg[2]) and _num(msg[3]) and _num(msg[4])
                        and math.hypot(msg[2] - x, msg[3] - y) <= POSE_TOL_M
                        and abs(_wrap(msg[4] - th)) <= POSE_TOL_RAD):
                    self._poison(topic, msg, "pose of no genuine odometry")
        last_clock: dict = {}
        for k, i in self.matched["clock"]:
            if i < 0:
                continue
            msg = p.clock[k]
            inst = self.instance(msg[0])
            prev = last_clock.get(inst)
            if prev is not None and not (self.epoch[i] > self.epoch[prev] or (self.epoch[i] == self.epoch[prev]
                                                                               and i > prev)):
                self._poison("clock", msg, "clock back or repeated without a simulator restart")
            last_clock[inst] = i
        self._check_scans()

    def _check_scans(self) -> None:
        self.scans_checked = 0
        if self.ranges is None:
            return
        tms, wall = self.truth[:, 2], self.truth[:, 0]
        for msg in self.pub.scans:
            if len(msg) < 3 or not (_num(msg[0]) and _num(msg[1])):
                self._poison("scan", (float("nan"), float("nan")), "unreadable message")
                continue
            w, t0 = float(msg[0]), float(msg[1])
            try:
                r = np.asarray(msg[2], dtype=float).ravel()
            except (TypeError, ValueError):
                self._poison("scan", msg, "unreadable ranges")
                continue
            win = np.flatnonzero((tms >= t0 - 2 * PERIOD_MS) & (tms <= t0 + 2 * SWEEP_MS + 2 * PERIOD_MS)
                                 & (wall <= w))
            self.scans_checked += 1
            if r.size != self.ranges.shape[1] or not len(win):
                self._poison("scan", msg, "a sweep of no genuine frame (no frame in its window)")
                continue
            fin = np.isfinite(r)
            if not fin.any():
                continue
            cand = self.ranges[win][:, fin]
            ok = np.any(np.abs(cand - r[fin]) <= RANGE_TOL + 1e-5 * np.abs(r[fin]), axis=0)
            if not ok.all():
                self._poison("scan", msg, f"{int(np.sum(~ok))} range(s) of no genuine frame in the sweep's window")

    # -- figures -------------------------------------------------------------------------------------------
    def counts(self) -> dict:
        p = self.pub
        return {"odom": len(p.odom), "clock": len(p.clock), "joints": len(p.joints), "tf": len(p.tf),
                "scan": len(p.scans)}

    def poisoned_in(self, t0: float, t1: float) -> list[Poison]:
        return [x for x in self.poisoned if t0 <= x.wall < t1]

    def by_segment(self, segments) -> dict:
        """Poisoned messages per named segment: ``segments`` is [(name, t0, t1)]; a message counts for the
        segment whose start it follows most closely (an effect may trail its cause), ``outside`` when none."""
        starts = sorted((s[1], s[0]) for s in segments)
        out = {name: 0 for name, _, _ in segments}
        out["outside"] = 0
        for x in self.poisoned:
            k = bisect.bisect_right([s[0] for s in starts], x.wall) - 1
            out[starts[k][1] if k >= 0 else "outside"] += 1
        return out

    def odometry_errors(self, t0: float = -math.inf, t1: float = math.inf) -> np.ndarray:
        """(wall, stamp_ms, metres, radians) of each matched ``odom`` message in [t0, t1) against the odometry
        over every genuine frame of its simulator run (from the same baseline): what a loss-free bridge says."""
        out = []
        full: dict = {}
        for k, i in self.matched.get("odom", ()):
            msg = self.pub.odom[k]
            if i < 0 or not (t0 <= msg[0] < t1):
                continue
            key = (self.instance(msg[0]), int(self.epoch[i]))
            tr = self._tracks[key]
            if key not in full:
                ep = np.flatnonzero(self.epoch == key[1])
                first = ep[0] if tr["from_zero"] else tr["baseline_frame"]
                rows = ep[ep >= first]
                full[key] = dict(zip(rows.tolist(), odometry(self.truth[rows, 3:5], self.geo, tr["baseline"])))
            x, y, th = full[key][i]
            out.append((msg[0], msg[1], math.hypot(msg[2] - x, msg[3] - y), abs(_wrap(msg[4] - th))))
        return np.array(out, dtype=float).reshape(-1, 4)

    def joint_errors_ticks(self, t0: float = -math.inf, t1: float = math.inf) -> np.ndarray:
        """For each matched ``joint_states`` message in [t0, t1): the larger of its two wheels' distance (whole
        ticks, rounded) from the genuine totals at its stamp (from the same baseline)."""
        out = []
        for k, i in self.matched.get("joints", ()):
            msg = self.pub.joints[k]
            if i < 0 or not (t0 <= msg[0] < t1):
                continue
            a = self._tracks[(self.instance(msg[0]), int(self.epoch[i]))]["angles"][i]
            try:
                off = max(abs(float(msg[2]) - a[0]), abs(float(msg[3]) - a[1])) / self.geo.rad_per_tick
            except (TypeError, ValueError, IndexError):
                off = math.inf
            out.append(round(off) if math.isfinite(off) else 10 ** 9)
        return np.array(out, dtype=np.int64)

    def first_valid(self, topic: str, after_wall: float, epoch: int | None = None) -> float | None:
        """Arrival (wall) of the first message of ``topic`` after ``after_wall`` that matches a genuine frame
        (of simulator run ``epoch`` if given) and is not poisoned; None when there is none."""
        bad = {(x.topic, x.wall) for x in self.poisoned}
        msgs = {"odom": self.pub.odom, "clock": self.pub.clock, "joints": self.pub.joints, "tf": self.pub.tf}[topic]
        for k, i in self.matched.get(topic, ()):
            w = msgs[k][0]
            if i >= 0 and w > after_wall and (epoch is None or self.epoch[i] == epoch) and (topic, w) not in bad:
                return float(w)
        return None

    def resets(self, topic: str = "odom") -> int:
        """How often one bridge process's ``odom`` went on in a later simulator run (published from that run's
        own baseline, which the pose check verified)."""
        n, last = 0, {}
        for k, i in self.matched.get(topic, ()):
            if i < 0:
                continue
            inst = self.instance(self.pub.odom[k][0])
            if inst in last and self.epoch[i] > last[inst]:
                n += 1
            last[inst] = max(int(self.epoch[i]), last.get(inst, -1))
        return n


def _num(v) -> bool:
    try:
        return math.isfinite(float(v))
    except (TypeError, ValueError):
        return False


def _close(a, b, tol) -> bool:
    return _num(a) and abs(float(a) - b) <= tol


# ------------------------------------------------------------------------------------------------ the loss bound

def chord_error(totals: np.ndarray, geo: Geometry) -> float:
    """Position error (m) of integrating rows 0 -> last of ``totals`` in one arc instead of step by step
    through the rows in between (what losing the frames in between costs; the same from any heading)."""
    if len(totals) < 3:
        return 0.0
    steps = odometry(totals, geo)
    m = geo.rad_per_tick * geo.wheel_radius
    d = (totals[-1] - totals[0]) * m
    x, y, _ = _integrate(0.0, 0.0, 0.0, d[0], d[1], geo.track)
    return float(math.hypot(steps[-1, 0] - x, steps[-1, 1] - y))


def undelivered(fates) -> np.ndarray:
    """Which frames the proxy did not deliver in order: dropped, or delayed behind the next one (which the
    bridge then drops as stale)."""
    return np.isin(np.asarray(fates), (DROPPED, DELAYED))


def missing_runs(fates: np.ndarray) -> list[tuple[int, int]]:
    """Runs [a, b] of consecutive frames the proxy did not deliver in order (see :func:`undelivered`)."""
    miss = undelivered(fates)
    runs, a = [], None
    for i, m in enumerate(miss):
        if m and a is None:
            a = i
        elif not m and a is not None:
            runs.append((a, i - 1))
            a = None
    if a is not None:
        runs.append((a, len(miss) - 1))
    return runs


def chord_bound(truth: np.ndarray, fates: np.ndarray, geo: Geometry, rows: np.ndarray | None = None,
                floor: float = POSE_TOL_M) -> dict:
    """The bound of a lossy segment's odometry error, from the genuine (loss-free) frames at the driven speeds:
    ``worst`` = the largest chord error of any run of up to ``longest`` consecutive frames (the longest run
    the proxy did not deliver) anywhere in the segment, ``runs`` the number of such runs, ``bound_m`` =
    floor + runs x worst (the heading stays exact, so the runs' errors add at most)."""
    truth = np.asarray(truth, dtype=float).reshape(-1, 8)
    idx = np.arange(len(truth)) if rows is None else np.asarray(rows)
    runs = [(a, b) for a, b in missing_runs(np.asarray(fates)[idx])]
    longest = max((b - a + 1 for a, b in runs), default=0)
    tot = truth[idx, 3:5]
    worst = 0.0
    for g in range(1, longest + 1):
        for s in range(0, len(tot) - g - 1):
            worst = max(worst, chord_error(tot[s:s + g + 2], geo))
    return {"runs": len(runs), "longest": longest, "worst_m": worst, "bound_m": floor + len(runs) * worst}
