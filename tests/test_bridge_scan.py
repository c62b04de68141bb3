"""The bridge's LIDAR scans: SimTwo's whole-sweep delivery (simtwo/scan.py) and the self-filter (simtwo/selfhits.py).

SimTwoRanger below is a line-by-line model of SimTwo's ranger2d timing (P33a/SimTwo: Viewer.pas 5228-5231 the
script's subsampling, 5414-5417 PreProcess of every sensor, 4370-4373 dSpaceCollide then the step, 5446-5452
the sensor period; ODERobots.pas 1593-1624 PreProcess enables the rays whose turn it is and clears them,
1842-1846 UpdateMeasures copies every ray at once), in float64 like SimTwo's doubles. Each ray reads a value
that encodes when it was measured, so every stamp can be checked against the truth.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from robotatfactory.robot import load_robot
from robotatfactory.simtwo.scan import PerRayAssembler, WholeSweepAssembler, make_assembler
from robotatfactory.simtwo.selfhits import Footprint, SelfFilter

N, P, D = 360, 0.2, 0.04


class SimTwoRanger:
    """SimTwo's physics loop as far as the ranger and the script see it.

    ``scene(i, t_ms)``: the range ray ``i`` measures at Tms-time ``t_ms`` (the time of the state it sees).
    ``sensor_offset`` steps run before the script starts counting (the script may be started at any moment;
    Tms counts the script's own calls, 40 ms each). ``noise_every``: control.pas's noise before 58a4e75,
    redrawn for every ray every that many frames (and when a ray's raw value changes), 0 = none;
    ``noise="sweep"``: control.pas since then, every ray redrawn when any raw value changed (a delivery) and,
    while they repeat, every 5 frames after the last change.
    """

    def __init__(self, scene, sensor_offset=0, noise_every=0, seed=0, noise=None):
        self.scene = scene
        self.dt = 0.001
        self.T = 0.0  # TimeFromLastMeasure
        self.S = 0.0  # SecondsCount
        self.step = 0
        self.measure = np.full(N, -1.0)
        self.measured_at = np.full(N, np.nan)  # Tms-time each ray was last measured
        self.values = np.zeros(N)  # Measures[].value: 0 before the first update
        self.values_at = np.full(N, np.nan)
        self.deliveries: list[float] = []  # Tms-time of each UpdateMeasures
        self.calls = 0
        # Tms - physTime (ms) of the state a call sees: the first call (Tms 40) comes 40 steps after the
        # script starts, and sees the state after 39 of them
        self.offset_ms = 1 - sensor_offset
        self.noise_every = noise_every
        self.noise = noise
        self.draw_call = 0
        self.rng = np.random.default_rng(seed)
        self.raw = np.full(N, np.nan)
        self.noisy = np.zeros(N)
        for _ in range(sensor_offset):
            self._physics_step()

    def _phys_ms(self):
        return self.step  # state after `step` steps of 1 ms

    def _tms(self, phys_ms):
        return phys_ms + self.offset_ms

    def _physics_step(self):
        a = round(N * self.dt / P) + 1
        f = round(N * self.T / P)
        i = np.arange(N)
        on = (i >= f) & (i <= f + a)  # PreProcess: the enabled rays, measured in this step's collide
        t = self._tms(self._phys_ms())
        self.measure[on] = [self.scene(k, t) for k in np.flatnonzero(on)]
        self.measured_at[on] = t
        self.step += 1
        self.T += self.dt
        if self.T > P:
            self.T -= P
            self.values = self.measure.copy()
            self.values_at = self.measured_at.copy()
            self.deliveries.append(self._tms(self._phys_ms()))

    def frame(self):
        """Run to the next script call; (Tms, the array control.pas sends)."""
        while True:
            self.S += self.dt
            if self.S > D:
                self.S -= D
                self.calls += 1
                assert 40 * self.calls == self._tms(self._phys_ms())
                out = self.values.copy()
                if self.noise == "sweep":  # control.pas LidarLine since 58a4e75
                    fresh = not np.array_equal(out, self.raw)
                    if fresh:
                        self.draw_call = self.calls
                    elif (self.calls - self.draw_call) % 5 == 0:
                        fresh = True
                    if fresh:
                        self.raw = out.copy()
                        self.noisy = out + self.rng.normal(0, 0.0015, N)
                    out = np.where(out >= 0, np.maximum(self.noisy, 0), -1.0)
                elif self.noise_every:  # control.pas NoisyRange: redraw when the ray changes or every k frames
                    redraw = (out != self.raw) | ((self.calls - 1) % self.noise_every == 0)
                    self.raw[redraw] = out[redraw]
                    self.noisy[redraw] = out[redraw] + self.rng.normal(0, 0.0015, redraw.sum())
                    out = np.where(out >= 0, np.maximum(self.noisy, 0), -1.0)
                self._physics_step()
                return 40 * self.calls, out
            self._physics_step()


def moving(i, t):
    return 1.0 + t / 1000.0  # the range encodes when the ray was measured


def static(i, t):
    return 1.0 + 0.001 * i


def run(frames, scene=moving, drop=(), sensor_offset=0, noise_every=0, asm=None):
    """Feed ``frames`` frames to a whole-sweep assembler; (assembler, [(sweep, true ray times, Tms)])."""
    sim = SimTwoRanger(scene, sensor_offset, noise_every)
    asm = asm or WholeSweepAssembler(N, P, D)
    out = []
    for j in range(frames):
        t, arr = sim.frame()
        if j in drop:
            continue
        truth = sim.values_at.copy() / 1000.0  # Tms-time of each ray's measurement in this array
        for sw in asm.add(t, arr):
            out.append((sw, truth, t))
    return asm, out


def test_the_emulated_simtwo_delivers_a_whole_sweep_measured_over_the_period_before():
    sim = SimTwoRanger(moving)
    arrays = [sim.frame() for _ in range(30)]
    t, a = arrays[4]
    assert t == 200 and np.all(a == 0)  # zeros before the first delivery
    deliveries = np.array(sim.deliveries)
    assert np.all(np.diff(deliveries) == 200)  # exactly every period
    t, a = arrays[5]  # the frame after the first delivery holds the sweep measured over [0, P]
    rays_t = (a - 1.0) * 1000
    assert rays_t[0] == pytest.approx(deliveries[0] - 200, abs=1.0)
    assert np.max(np.abs(rays_t - (rays_t[0] + np.arange(N) * 200 / N))) <= 1.5  # steps, rounding
    for j in range(6, 10):  # unchanged until the next delivery
        assert np.array_equal(arrays[j][1], a)
    assert not np.array_equal(arrays[10][1], a)


def _check_stamps(out, max_bound=0.040, exact=False):
    """Every sweep's stamp within its own error bound (+1.5 ms: physics steps, rounding), the bound within
    ``max_bound`` (one control cycle), every ray's time too; ``exact``: within 1.5 ms of the truth."""
    assert out
    for sw, truth, _ in out:
        err = abs(sw.t0 - truth[0])
        assert err <= sw.error_bound + 0.0015, (sw.t0, truth[0], sw.error_bound)
        assert sw.error_bound <= max_bound
        assert not exact or err <= 0.0015, (sw.t0, truth[0])
        rays = sw.t0 + np.arange(N) * sw.time_increment
        assert np.max(np.abs(rays - truth)) <= err + 0.0015
        assert sw.time_increment == pytest.approx(P / N)


def test_zeros_are_never_published_and_every_sweep_is_stamped_within_half_a_cycle():
    asm, out = run(60)
    assert asm.counters.pre_sweep == 5  # frames at 40..200 ms carry SimTwo's zeros
    assert all(not np.all(sw.ranges < 0.02) for sw, _, _ in out)
    assert [sw.index for sw, _, _ in out] == list(range(1, 12))  # one per delivery, none twice
    _check_stamps(out, exact=True)  # SimTwo delivers 1 ms after a script call: delivery_lag puts it there
    assert asm.locked and asm.counters.locks == 1


def test_the_old_per_ray_assembler_stamps_simtwo_sweeps_one_sweep_late():
    sim = SimTwoRanger(moving)
    old = PerRayAssembler(N, P, 0.001)
    errs = []
    for _ in range(60):
        t, arr = sim.frame()
        for sw in old.add(t, arr):
            ok = ~np.isnan(sw.ranges)
            measured = (sw.ranges[ok] - 1.0)  # when the rays it published were really measured
            errs.append(sw.t0 + np.flatnonzero(ok)[0] * sw.time_increment - measured[0])
    assert len(errs) >= 8 and np.median(errs) >= 0.15  # stamped ~0.2 s after the rays were measured


@pytest.mark.parametrize("offset", [0, 1, 7, 20, 39, 40, 113, 199])
def test_the_bound_holds_at_any_phase_of_the_sensor_against_the_script(offset):
    # other alignments than SimTwo's (the sensor clock started `offset` steps before the script's)
    asm, out = run(80, sensor_offset=offset)
    assert len(out) >= 13
    _check_stamps(out, exact=offset % 40 == 0)  # within one cycle even where delivery_lag is wrong
    asm, out = run(80, sensor_offset=offset, asm=WholeSweepAssembler(N, P, D, delivery_lag=None))
    _check_stamps(out, max_bound=0.0195)  # the bracket's middle: half a cycle


def test_identical_sweeps_of_a_static_noise_free_scene_are_still_published_once_per_period():
    asm, out = run(100, scene=static)
    assert len(out) == 19 and asm.counters.repeated == 18  # every delivery after the first
    assert np.all(np.diff([sw.t0 for sw, _, _ in out]) == pytest.approx(P))
    _check_stamps(out)


def test_a_lost_frame_costs_no_sweep_and_a_lost_sweep_is_counted():
    # frame 5 (Tms 240) is the first to carry sweep 1; frames 10-14 carry sweep 2 only
    asm, out = run(60, drop={5, 10, 11, 12, 13, 14, 27})
    idx = [sw.index for sw, _, _ in out]
    assert 1 in idx and 2 not in idx and 6 in idx
    assert asm.counters.lost == 1
    # the first sweep's bracket is 80 ms (a frame lost): within one cycle, until a delivery seen in the frame
    # right after it narrows the phase (sweep 4: sweep 3's change came after five lost frames, no information)
    _check_stamps(out)
    assert out[0][0].error_bound > 0.039  # an 80 ms arc: its middle, 39.5 ms at worst
    _check_stamps([o for o in out if o[0].index >= 4], exact=True)


def test_a_restart_relocks_from_the_new_zeros():
    asm = WholeSweepAssembler(N, P, D)
    _, out1 = run(40, asm=asm)
    # the simulator restarts: Tms from 40 again, zeros, a sensor phase 13 ms different
    _, out2 = run(40, asm=asm, sensor_offset=13)
    assert asm.counters.restarts == 1 and asm.counters.locks == 2
    assert len(out2) >= 6
    _check_stamps(out1 + out2)


def test_joining_a_running_simulation_publishes_nothing_unstampable():
    sim = SimTwoRanger(moving)
    for _ in range(17):
        sim.frame()
    asm = WholeSweepAssembler(N, P, D)
    out = []
    for _ in range(40):
        t, arr = sim.frame()
        truth = sim.values_at.copy() / 1000
        out += [(sw, truth, t) for sw in asm.add(t, arr)]
    assert asm.counters.unstamped == 1  # the first array: delivered sometime in the last period
    assert asm.locked and len(out) >= 7
    _check_stamps(out)
    # a static scene joined mid-run: no change, so nothing can be stamped and nothing is published
    sim = SimTwoRanger(static)
    for _ in range(17):
        sim.frame()
    asm = WholeSweepAssembler(N, P, D)
    assert sum(len(asm.add(*sim.frame())) for _ in range(30)) == 0 and not asm.locked


def test_noise_redrawn_between_deliveries_is_no_sweep_once_locked():
    # control.pas before 58a4e75 redrew every ray's noise every 5th frame, out of phase with the deliveries
    asm, out = run(100, noise_every=5, sensor_offset=80)
    assert asm.counters.off_phase > 0
    assert len(out) == 19
    _check_stamps(out)


def test_control_pas_noise_on_the_sweep_schedule_lets_a_late_bridge_lock_on_a_still_robot():
    # a bridge started while SimTwo runs, robot still: only control.pas's noise redraws change the array,
    # on the delivery schedule, so the bridge locks onto the right phase
    sim = SimTwoRanger(static, noise="sweep")
    for _ in range(23):
        sim.frame()
    asm, out = WholeSweepAssembler(N, P, D), []
    for _ in range(60):
        t, arr = sim.frame()
        truth = sim.values_at.copy() / 1000
        out += [(sw, truth, t) for sw in asm.add(t, arr)]
    assert asm.locked and asm.counters.off_phase == 0 and len(out) >= 10
    _check_stamps(out[1:], exact=True)  # once locked (the first one, unlocked, is within its bracket)
    _check_stamps(out[:1])


def test_per_ray_mode_is_the_old_assembler():
    a = make_assembler("per_ray", N, P, D, 0.001)
    assert isinstance(a, PerRayAssembler)
    arr, out, step = np.full(N, -1.0), [], 0
    for _ in range(26):  # rays refreshed in turn, value = global ray counter
        for _ in range(40):
            prev = (step * N) // 200
            step += 1
            for g in range(prev, (step * N) // 200):
                arr[g % N] = g
        out += a.add(step, arr.copy())
    assert [s.index for s in out] == [0, 1, 2, 3, 4]
    assert all(np.array_equal(s.ranges, s.index * N + np.arange(N)) for s in out)
    assert isinstance(make_assembler("sweep", N, P, D, 0.001, "instant"), WholeSweepAssembler)
    with pytest.raises(ValueError):
        make_assembler("burst", N, P, D, 0.001)


def test_instant_ray_timing_stamps_the_delivery():
    asm, out = run(40, asm=WholeSweepAssembler(N, P, D, ray_timing="instant"))
    assert out
    for sw, truth, t in out:
        assert sw.time_increment == 0.0
        assert abs(sw.t0 - (truth[-1] + P / N)) <= 0.0215  # the delivery, just after the last ray


# ---- the self-filter ----------------------------------------------------------------------------------

def _wheel_scan(robot):
    """A 360-ray scan from the centre at 0.05 m: SimTwo's wheels (6 mm thick, inner faces at 0.0645 m)
    in front of walls 1 m away."""
    ang = robot.lidar.angles()
    r = np.full(N, 1.0)
    hit = np.zeros(N, dtype=bool)
    R, z = robot.wheel_radius, robot.lidar.xyz[2]
    half = math.sqrt(R * R - (z - R) ** 2)
    for i, a in enumerate(ang):
        s, c = math.sin(a), math.cos(a)
        if abs(s) < 1e-9:
            continue
        d = 0.0645 / abs(s)  # the inner face of the wheel on that side
        if abs(d * c) <= half:
            r[i], hit[i] = d, True
    return r, hit


def test_the_self_filter_removes_exactly_the_wheel_hits():
    robot = load_robot()
    r, hit = _wheel_scan(robot)
    assert 60 <= hit.sum() <= 100  # about 90 rays within ~23 degrees of +-90 degrees
    ang = np.degrees(robot.lidar.angles()[hit])
    assert np.all(np.abs(np.abs(ang) - 90) <= 25)
    r[180] = 0.085  # a part held at the electromagnet, in front of the robot: an obstacle, kept
    r[7] = -1.0  # no return stays -1
    f = SelfFilter(Footprint.from_robot(robot), robot.lidar.angles(), robot.lidar.xyz[:2])
    out, k = f.apply(r)
    assert k == hit.sum() and np.array_equal(np.isnan(out), hit)
    assert out[180] == 0.085 and out[7] == -1.0 and f.filtered_total == k


def test_the_footprint_follows_the_robot_and_the_scan_height():
    robot = load_robot()
    fp = Footprint.from_robot(robot, margin=0.0)
    yw = robot.track / 2
    assert fp.contains(0.0, yw) and fp.contains(0.0, -yw) and fp.contains(0.06, 0.0)
    assert not fp.contains(0.0, yw + robot.wheel["width"] / 2 + 0.002)
    assert not fp.contains(robot.base["size"][0] / 2 + 0.002, 0.0)
    # a scan plane above the wheels: only the base remains
    high = Footprint.from_robot(robot, scan_z=0.2, margin=0.0)
    assert len(high.boxes) == 1


def test_beacons_next_to_filtered_rays_are_not_trusted_and_the_others_still_found():
    from robotatfactory.localization.lidar import extract_beacons, simulate_scan

    robot = load_robot()
    ang = robot.lidar.angles()
    beacon = (0.0, 0.6)  # straight to the left, 0.6 m: behind where the left wheel hides rays
    r = simulate_scan((0.0, 0.0, 0.0), [beacon, (0.8, 0.0)], 0.09, ang)
    found = extract_beacons(r, ang)
    assert len(found) == 2
    # rays next to the left beacon's cluster invalid (the wheel's NaNs): its edge may be hidden: dropped
    left = np.flatnonzero(np.isfinite(r) & (r > 0) & (np.abs(ang - math.pi / 2) < 0.2))
    r2 = r.copy()
    r2[left[-1] + 1: left[-1] + 4] = np.nan
    found2 = extract_beacons(r2, ang)
    assert len(found2) == 1 and found2[0].center[0] == pytest.approx(0.8, abs=0.01)


# ---- against the stand-in simulator (raf sim's physics, no ROS) ----------------------------------------

def _wall_distance(field, pts, z):
    """Distance (m) of each world point (k, 2) to the nearest wall, rib or beacon cut by the plane at z."""
    best = np.full(len(pts), np.inf)
    for b in field.boxes:
        if not (b.center[2] - b.size[2] / 2 <= z <= b.center[2] + b.size[2] / 2):
            continue
        c, s = math.cos(b.yaw), math.sin(b.yaw)
        d = pts - np.asarray(b.center[:2])
        lx, ly = np.abs(d[:, 0] * c + d[:, 1] * s), np.abs(-d[:, 0] * s + d[:, 1] * c)
        hx, hy = b.size[0] / 2, b.size[1] / 2
        out = np.hypot(np.maximum(lx - hx, 0), np.maximum(ly - hy, 0))
        inside = np.minimum(hx - lx, hy - ly)
        best = np.minimum(best, np.where((lx <= hx) & (ly <= hy), inside, out))
    for bx, by in field.beacons:
        best = np.minimum(best, np.abs(np.hypot(pts[:, 0] - bx, pts[:, 1] - by) - 0.045))
    return best


def _best_shift(sw, ranges, poses, field, robot):
    """The time shift (s) that puts a scan's points best on the map: 0 for a correctly stamped scan."""
    t, x, y, th = poses.T
    th = np.unwrap(th)
    ang = robot.lidar.angles()
    ok = np.isfinite(ranges) & (ranges > 0.1)
    i = np.flatnonzero(ok)
    shifts = np.arange(-0.30, 0.101, 0.005)
    cost = []
    for dlt in shifts:
        ti = sw.t0 + i * sw.time_increment + dlt
        px, py, pth = np.interp(ti, t, x), np.interp(ti, t, y), np.interp(ti, t, th)
        a = pth + ang[i]
        pts = np.stack([px + ranges[i] * np.cos(a), py + ranges[i] * np.sin(a)], axis=1)
        cost.append(np.median(_wall_distance(field, pts, robot.lidar.xyz[2])))
    return float(shifts[int(np.argmin(cost))]), float(min(cost))


def _turn_on_the_spot(lidar_update, cycles=75):
    """The stand-in turning on the spot at up to 2 rad/s for 2.4 s: its frames and true poses."""
    from robotatfactory.field import load_field
    from robotatfactory.sim.config import SimConfig
    from robotatfactory.sim.simulator import Simulator
    from robotatfactory.simtwo import Command

    field, robot = load_field("rules2026"), load_robot()
    cfg = SimConfig(camera=False, competition=False, lidar_update=lidar_update, lidar_self_hits=True,
                    start_pose=(0.0, 0.0, 0.0))  # between the machines, clear of everything
    sim = Simulator(field, robot, cfg)
    frames, poses = [], [(0.0, 0.0, 0.0, 0.0)]
    for k in range(cycles):  # a stamp 0.1 s off turns a scan by 0.2 rad
        f = sim.step_cycle(Command(0.0, 2.0 if k < 60 else 0.0, False, k))
        frames.append(f)
        poses.append((f.time_ms / 1000, f.x, f.y, f.theta))
    del sim
    return field, robot, frames, np.array(poses)


def test_stand_in_scans_are_stamped_within_a_cycle_and_free_of_wheel_hits():
    field, robot, frames, poses = _turn_on_the_spot("sweep")
    whole = WholeSweepAssembler(N, P, D)
    old = PerRayAssembler(N, P, robot.physics_step)
    filt = SelfFilter(Footprint.from_robot(robot), robot.lidar.angles(), robot.lidar.xyz[:2])
    new_sweeps, old_sweeps, raw_self_hits = [], [], []
    for f in frames:
        raw_self_hits.append(int(filt.mask(f.ranges).sum()))
        new_sweeps += whole.add(f.time_ms, f.ranges)
        old_sweeps += old.add(f.time_ms, f.ranges)
    assert whole.counters.pre_sweep >= 4  # the stand-in reads 0 before its first sweep, as SimTwo does
    assert len(new_sweeps) >= 12 and whole.locked
    assert max(raw_self_hits) >= 40  # the stand-in's rays hit its own wheels, as SimTwo's do
    shifts = []
    for sw in new_sweeps:
        ranges, k = filt.apply(sw.ranges)
        fin = ranges[np.isfinite(ranges) & (ranges >= 0)]
        assert k >= 40 and fin.min() > 0.08  # every wheel hit removed, nothing nearer than the robot's edge
        if sw.t0 + P <= 60 * D:  # measured while turning (a still robot fits at any shift)
            shift, cost = _best_shift(sw, ranges, poses, field, robot)
            assert cost < 0.01
            shifts.append(shift)
    # the points fit the map best with the bridge's stamps (within one control cycle; within the 5 ms search
    # step with the default delivery_lag, which the stand-in, like SimTwo, meets) ...
    assert len(shifts) >= 8 and max(abs(s) for s in shifts) <= 0.005, shifts
    # ... and the old per-ray assembler's stamps are a sweep late
    old_shifts = [_best_shift(sw, filt.apply(np.nan_to_num(sw.ranges, nan=-1.0))[0], poses, field, robot)[0]
                  for sw in old_sweeps[3:]]
    assert np.median(old_shifts) <= -0.15, old_shifts


def test_per_ray_mode_matches_the_stand_ins_per_ray_idealisation():
    field, robot, frames, poses = _turn_on_the_spot("per_ray")
    asm = make_assembler("per_ray", N, P, D, robot.physics_step)
    filt = SelfFilter(Footprint.from_robot(robot), robot.lidar.angles(), robot.lidar.xyz[:2])
    sweeps = [sw for f in frames for sw in asm.add(f.time_ms, f.ranges)]
    shifts = [_best_shift(sw, filt.apply(sw.ranges)[0], poses, field, robot)[0]
              for sw in sweeps if sw.t0 + P <= 60 * D and sw.missing == 0]
    assert len(shifts) >= 8 and max(abs(s) for s in shifts) <= 0.005, shifts
