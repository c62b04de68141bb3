"""Issue 10, 22: a short version of each fault of ``raf experiment faults`` (seconds, not minutes), on the real
``raf sim`` and bridge with a private roscore, all on loopback. Each asserts the part's own targets, which the
observer (experiments/_faults_observe.py) measures from the simulator's frames and the published messages."""
from __future__ import annotations

import pytest
from expargs import options

from robotatfactory.experiments import faults

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def make_args(**kw):
    return options(faults, field="rules2026", **kw)


def test_loss_odometry_stays_within_the_chord_bound_at_every_message(tmp_path):
    """20 % dropped, 5 % duplicated, 5 % reordered both ways: at every odom message during the loss the pose is
    within the chord errors of the lost frames (the observer, from the simulator's frames), the heading and
    every joint_states message exact (no tick lost), nothing poisoned."""
    r = faults.run_part("loss", make_args(loss_seconds=6.0), tmp_path)
    assert r["loss_proxy_dropped"] > 10 and r["loss_proxy_duplicated"] > 0 and r["loss_proxy_reordered"] > 0
    assert r["loss_frames_missing_runs"] > 10  # the proxy's own record of what it did not deliver
    assert r["loss_odom_messages_checked"] > 50 and r["loss_joint_messages_checked"] > 50
    assert r["loss_odometry_error_max_m"] <= r["loss_odometry_bound_m"] < 0.005
    assert r["loss_heading_error_max_rad"] <= 1e-5
    assert r["loss_ticks_off_max"] == 0
    assert r["loss_poisoned_messages"] == 0, r.get("loss_poisoned_first")
    assert r["loss_scans_checked"] > 5
    assert r["loss_speed_error_mps"] <= 0.01


def test_fuzz_poisons_nothing_kind_by_kind(tmp_path):
    r = faults.run_part("fuzz", make_args(fuzz_datagrams=30000, fuzz_seconds=6.0, fuzz_inband=0.1), tmp_path)
    assert r["fuzz_crashes"] == 0
    assert r["fuzz_poisoned_messages"] == 0, r.get("fuzz_poisoned_first")
    kinds = [k for k in faults.TARGETS if k.startswith("fuzz_") and k.endswith("_poisoned")]
    assert len(kinds) == 14
    for k in kinds:  # every kind was sent, reached the bridge's socket and poisoned nothing
        assert r[k] == 0 and r[k.replace("_poisoned", "_reached")] > 0, k
    assert r["fuzz_datagrams_reached_socket"] <= r["fuzz_datagrams_sent"] <= 30000 + r["fuzz_impossible_ticks_sent"]
    assert r["fuzz_messages_checked"] > 4 * r["fuzz_odom_messages"] > 0 and r["fuzz_scans_checked"] > 5
    assert r["fuzz_odometry_error_m"] <= 0.01


def test_restarts_of_simulator_bridge_camera_and_roscore(tmp_path):
    r = faults.run_part("restarts", make_args(), tmp_path)
    assert r["restart_poisoned_messages"] == 0, r.get("restart_poisoned_first")
    assert r["restart_sim_odom_back_s"] <= 1.0 and r["restart_sim_clock_back_s"] <= 1.0
    assert r["restart_sim_image_back_s"] <= 1.0
    assert r["restart_sim_odometry_resets"] == 1
    # the ground truth (the simulator's frames), not the simulator's own log line: the wheels slow down in the
    # first cycle more than the command timeout after the last command (never before), and the robot is at rest
    # soon after: issue 22's 0.54 s after the last command and 0.6 s after the bridge's death (with a cycle of
    # slack for a loaded machine; the campaign judges the targets themselves)
    timeout = faults.STOP_S - faults.PERIOD
    assert timeout <= r["restart_bridge_stop_s"] <= faults.STOP_S + 1e-9
    assert r["restart_bridge_stop_s"] < r["restart_bridge_at_rest_s"] <= 0.54 + 0.04
    assert r["restart_bridge_at_rest_after_death_s"] <= 0.6 + 0.04
    assert r["restart_bridge_resume_s"] <= 1.0
    assert r["restart_roscore_nodes_clear"], r["restart_roscore_exit_codes"]
    # the private graph's ROS logs are kept beside the part's own (roscore's, this part's rospy subscribers')
    assert list((tmp_path / "restarts" / "ros_log").rglob("master.log"))


def test_a_parts_own_wall_time_is_not_overwritten_by_its_total(tmp_path, monkeypatch):
    """run() records each part's whole wall time as <part>_part_wall_s, beside what the part measured itself
    (the fuzz's own phase, fuzz_wall_s, was overwritten by the total before)."""
    monkeypatch.setattr(faults, "run_part", lambda p, args, log_dir: {f"{p}_wall_s": 12.5})
    res = faults.run(make_args(parts="fuzz"), tmp_path)
    assert res["fuzz_wall_s"] == 12.5
    assert res["fuzz_part_wall_s"] >= 0
