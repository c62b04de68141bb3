"""Issue 10: a short version of each fault of ``raf experiment faults`` (seconds, not minutes), on the real
``raf sim`` and bridge with a private roscore, all on loopback. Each asserts the part's own targets."""
from __future__ import annotations

import argparse

import pytest

from robotatfactory.experiments import faults

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def make_args(**kw):
    p = argparse.ArgumentParser()
    faults.add_arguments(p)
    a = p.parse_args([])
    a.field = "rules2026"
    for k, v in kw.items():
        setattr(a, k, v)
    return a


def test_proxy_loss_loses_no_encoder_tick(tmp_path):
    """20 % dropped, 5 % duplicated, 5 % reordered both ways: the bridge's wheel angles equal the simulator's
    totals to the tick, and the robot still drives at the commanded speed."""
    r = faults.run_part("loss", make_args(loss_seconds=6.0), tmp_path)
    assert r["loss_proxy_dropped"] > 10 and r["loss_proxy_duplicated"] > 0 and r["loss_proxy_reordered"] > 0
    assert r["loss_bridge_lost"] > 10  # the bridge saw the loss ...
    assert r["loss_ticks_lost"] == 0, (r["loss_bridge_ticks"], r["loss_sim_ticks"])  # ... and lost no tick
    assert r["loss_speed_error_mps"] <= 0.01
    assert r["loss_bridge_restarts"] == 0


def test_fuzz_never_reaches_odom_or_clock(tmp_path):
    r = faults.run_part("fuzz", make_args(fuzz_datagrams=30000, fuzz_seconds=6.0, fuzz_inband=0.1), tmp_path)
    assert r["fuzz_crashes"] == 0
    assert r["fuzz_odom_from_forged_or_foreign"] == 0 and r["fuzz_clock_from_forged_or_foreign"] == 0
    assert r["fuzz_odometry_error_m"] <= 0.01
    assert r["fuzz_bridge_rejected_foreign_source"] > 10000  # the other senders were there, and dropped
    assert r["fuzz_bridge_held"] > 0 and r["fuzz_bridge_implausible"] > 0  # forged frames from the bound source
    assert r["fuzz_bridge_restarts"] == 0 and r["fuzz_bridge_source_takeovers"] == 0
    assert r["fuzz_odom_messages"] <= r["fuzz_frames_sent_by_sim"]


def test_restarts_of_simulator_bridge_camera_and_roscore(tmp_path):
    r = faults.run_part("restarts", make_args(), tmp_path)
    assert r["restart_sim_odom_back_s"] <= 1.0 and r["restart_sim_clock_back_s"] <= 1.0
    assert r["restart_sim_image_back_s"] <= 1.0
    assert r["restart_sim_odometry_resets"] == 1
    # as control.pas: the first 40 ms cycle more than 0.5 s after the last valid command runs with V = W = 0
    assert 0.5 < r["restart_bridge_stop_s"] <= 0.54 + 1e-9
    assert r["restart_bridge_resume_s"] <= 1.0
    assert r["restart_roscore_nodes_clear"], r["restart_roscore_exit_codes"]


def test_a_parts_own_wall_time_is_not_overwritten_by_its_total(tmp_path, monkeypatch):
    """run() records each part's whole wall time as <part>_part_wall_s, beside what the part measured itself
    (the fuzz's own phase, fuzz_wall_s, was overwritten by the total before)."""
    monkeypatch.setattr(faults, "run_part", lambda p, args, log_dir: {f"{p}_wall_s": 12.5})
    res = faults.run(make_args(parts="fuzz"), tmp_path)
    assert res["fuzz_wall_s"] == 12.5
    assert res["fuzz_part_wall_s"] >= 0
