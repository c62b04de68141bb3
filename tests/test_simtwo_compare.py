"""The stand-in against the real SimTwo in the suite: the short version of ``raf experiment compare`` (one drive,
one speed test, one localization lap with the nominal camera, one round-1 run on each simulator) and bounds on
how far each figure may be from the other simulator's. The bounds come from the measured spread
(docs/benchmarks.md, "The stand-in and the real SimTwo side by side"): a change that moves either simulator
beyond them (the stand-in drifting from SimTwo, or a SimTwo build or script that behaves differently) fails
here. Differences that are known and named (docs/simtwo.md) have bounds on each side instead.

About 12 minutes (SimTwo runs in real time); ROS 1 only (the middleware is not what is compared)."""
from __future__ import annotations

import argparse

import pytest

# the first test sets the comparison up (about 12 minutes): above the suite's 600 s per test
pytestmark = [pytest.mark.ros, pytest.mark.simtwo, pytest.mark.slow, pytest.mark.timeout(2400)]

#: figure -> the largest |SimTwo - stand-in| accepted (units as raf experiment compare reports them)
SAME = {
    "frames_per_s_sim": 0.5,  # both 25 per simulated second
    "replies_applied_share": 0.05,  # 0.995 vs 1.0 (SimTwo with patch 15; 0.58-0.61 before it)
    "lidar_self_hits_per_sweep": 4.0,  # 92 vs 92.5 (the wheels in the scan)
    "lidar_wall_abs_error_rest_mm_median": 3.0,  # 3.6-4.1 vs 3.1-3.5 mm
    "spin_slow_truth_over_odom_turn": 0.012,  # 1.020-1.022 vs 1.019-1.025 (the grip inside the tyres)
    "spin_fast_truth_over_odom_turn": 0.025,  # 1.020-1.021 vs 1.004-1.024 (one disturbed SimTwo run: 1.004)
    "odom_error_mm_per_m": 20.0,  # 25-28 vs 20-24 mm/m
    "speed_rmse_mps": 12.0,  # mm/s
    "ekf_position_rmse_m": 8.0,  # mm: 0.37 vs 2.2 with the nominal camera (0.34-0.37 vs 0.9-1.7 calibrated)
    "ekf_heading_rmse_deg": 1.0,  # 0.13 vs 0.17-0.24 deg calibrated; 0.16 vs 0.80 nominal, before odometry_track
}
#: figure -> (stand-in's range, SimTwo's range): named differences, each side within its own measured range
#: (None: no bound on that side)
NAMED = {
    # 14.4 vs 6.4-7.2: SimTwo renders in software, as fast as the host's CPU allows: 9.3 in a suite run on
    # 2026-11-27, 2.3 and 1.19 in CI runs, 0.84 on a 2-core EPYC host (2026-11-29), 12.01 in a suite run on
    # 2026-12-01 (the bound was 12.0 until then). SimTwo's side says it sends frames (more than one every 2 s)
    # and renders slower than the stand-in, below the stand-in's range
    "camera_frames_per_s": ((13.5, 15.5), (0.5, 13.4)),
    # both 5 on the earlier hosts; SimTwo 4.56-4.84 in CI runs on a host that renders at half speed and 3.97-4.34
    # on a 2-core EPYC host (its loop stalls and sweeps go unseen: the stand-in is kinder there, docs/simtwo.md)
    "lidar_sweeps_per_s_sim": ((4.9, 5.05), (3.5, 5.05)),
    "straight_odom_over_truth": ((1.0, 1.035), (0.99, 1.01)),  # the stand-in's slip from rest (~2 %)
    # round 1: the stand-in scored the maximum in 3 of 3 compare runs and 3 of 4 once in CI (2026-11-26: a part
    # left short in the outgoing warehouse, as on SimTwo); SimTwo anything from 0 to 4 (0 in a CI run on the slow
    # host: 6 of 9 picks failed, 3 parts dropped; 3 twice the same hour: docs/simtwo.md, "The agent on SimTwo"),
    # so no bound on SimTwo's side: its picks are the named difference (picks_attempted)
    "points": ((3, 4), None),
    "picks_attempted": ((4, 6), (2, 40)),  # SimTwo: the agent gets the first part at least, then retries
}


@pytest.fixture(scope="module")
def compared(tmp_path_factory):
    from robotatfactory.experiments import compare
    from robotatfactory.simtwo_linux import build

    build.require()  # built by scripts/bootstrap.sh (raf simtwo build): never skipped
    p = argparse.ArgumentParser()
    p.add_argument("--field", default="rules2026")
    compare.add_arguments(p)
    args = p.parse_args(["--repeats", "1", "--seeds", "1", "--calibration", "none"])
    return compare.run(args, tmp_path_factory.mktemp("compare"))


@pytest.mark.parametrize("key", sorted(SAME))
def test_figure_agrees_between_the_simulators(compared, key):
    st, s2 = compared.get(f"{key}_standin_median"), compared.get(f"{key}_simtwo_median")
    assert st is not None and s2 is not None, f"{key}: not measured on both simulators"
    assert abs(s2 - st) <= SAME[key], f"{key}: stand-in {st:.4g}, SimTwo {s2:.4g}: more than {SAME[key]} apart"


@pytest.mark.parametrize("key", sorted(NAMED))
def test_named_difference_stays_its_size(compared, key):
    for sim, bounds in zip(("standin", "simtwo"), NAMED[key]):
        if bounds is None:
            continue
        lo, hi = bounds
        v = compared.get(f"{key}_{sim}_median")
        assert v is not None and lo <= v <= hi, f"{key} on {sim}: {v} outside its measured range {lo}..{hi}"


def test_the_comparison_covers_every_part(compared):
    for part in ("drive", "speed", "localization", "competition"):
        assert compared[f"{part}_standin_wall_s"] > 0 and compared[f"{part}_simtwo_wall_s"] > 0
    assert compared["clearance_min_m_simtwo_median"] > 0.02  # the drive stayed clear of posts and walls
