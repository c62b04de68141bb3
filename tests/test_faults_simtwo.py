"""``raf experiment faults --simulator simtwo``: the fault campaign's proxy, fuzz, loss and restarts against the
real SimTwo (the Linux build of raf simtwo build), short (about 1.5 minutes on a quiet 2-core machine). The
bounds come from the runs in docs/benchmarks.md ("Fault campaign"); what SimTwo cannot do is reported as not
applicable, never as met."""
from __future__ import annotations

import argparse
import math

import pytest

from robotatfactory.errors import ConfigError
from robotatfactory.experiments import faults


def make_args(*argv: str):
    p = argparse.ArgumentParser()
    p.add_argument("--field", default="rules2026")
    faults.add_arguments(p)
    return p.parse_args(list(argv))


def test_simtwo_refuses_the_soak_and_names_why():
    """The soak resets rounds through raf sim's control channel: on SimTwo it is refused, not run in some other
    way."""
    with pytest.raises(ConfigError, match="control channel"):
        faults.run(make_args("--simulator", "simtwo", "--parts", "soak"), None)


def test_simtwo_result_is_prefixed_and_lists_what_does_not_apply():
    from robotatfactory.experiments import _faults_simtwo as side

    r = side.result({"fuzz_crashes": 0, "fuzz_crashes_target_met": True, "notes": ""})
    assert r["simulator"] == "simtwo" and r["faults_mode"] == "real_simtwo"
    assert r["real_simtwo_fuzz_crashes_target_met"] is True and "fuzz_crashes" not in r
    assert "soak_rss_growth_max_pct" in r["real_simtwo_targets_not_applicable"]
    assert "real_simtwo_soak_rss_growth_max_pct" not in faults.TARGETS
    assert faults.TARGETS["real_simtwo_fuzz_crashes"] == faults.TARGETS["fuzz_crashes"]


@pytest.mark.ros
@pytest.mark.simtwo
@pytest.mark.slow
def test_fuzz_loss_and_restarts_on_the_real_simtwo(tmp_path):
    from robotatfactory.simtwo_linux import build

    build.require()  # built by scripts/bootstrap.sh (raf simtwo build): never skipped
    args = make_args("--simulator", "simtwo", "--fuzz-datagrams", "30000", "--fuzz-seconds", "6",
                     "--fuzz-inband", "0.1", "--loss-seconds", "8")
    r = faults.run(args, tmp_path)
    p = "real_simtwo_"
    assert not r["notes"], r["notes"]
    assert r["simulator"] == "simtwo" and args.field == "simtwo2022"
    # what SimTwo cannot do: absent, and said so
    assert not any(k.startswith(f"{p}soak") for k in r), [k for k in r if "soak" in k]
    assert "lockstep" in r[f"{p}not_applicable"]
    # fuzz: nothing forged or foreign reaches odom or /clock, the odometry is the fuzz-free one
    assert r[f"{p}fuzz_crashes"] == 0
    assert r[f"{p}fuzz_odom_from_forged_or_foreign"] == 0 and r[f"{p}fuzz_clock_from_forged_or_foreign"] == 0
    assert r[f"{p}fuzz_odometry_error_m"] <= 0.01
    assert r[f"{p}fuzz_odometry_distance_m"] > 0.3  # SimTwo's robot drove its loops
    assert r[f"{p}fuzz_bridge_rejected_foreign_source"] > 10000
    assert r[f"{p}fuzz_bridge_held"] > 0 and r[f"{p}fuzz_bridge_implausible"] > 0
    assert r[f"{p}fuzz_bridge_restarts"] == 0 and r[f"{p}fuzz_bridge_source_takeovers"] == 0
    assert r[f"{p}fuzz_sim_frame_rate_during_fuzz_hz"] > 20  # SimTwo kept its 25 Hz under the fuzz
    # loss: 20 % dropped, 5 % duplicated, 5 % reordered both ways; no encoder tick lost
    assert r[f"{p}loss_proxy_dropped"] > 10 and r[f"{p}loss_bridge_lost"] > 10
    assert r[f"{p}loss_ticks_lost"] == 0, (r[f"{p}loss_bridge_ticks"], r[f"{p}loss_sim_ticks"])
    assert r[f"{p}loss_speed_error_mps"] <= 0.01
    # restarts: SimTwo killed and restarted, the bridge killed and restarted, roscore restarted
    assert r[f"{p}restart_sim_process_start_to_first_frame_s"] <= 60
    assert r[f"{p}restart_sim_odom_back_s"] <= 1.0 and r[f"{p}restart_sim_clock_back_s"] <= 1.0
    assert r[f"{p}restart_sim_image_back_s"] <= 5.0  # raf simtwo run opens SimTwo's Cameras window first
    assert r[f"{p}restart_sim_odometry_resets"] == 1
    # control.pas: TimeMs - LastValidMs > 500 ms, checked each 40 ms cycle: the first stop 0.52 s after the last
    # valid command (its own log line); at most one cycle beyond its 0.5 s timeout
    stop = r[f"{p}restart_bridge_stop_s"]
    assert math.isfinite(stop) and 0.5 <= stop <= 0.54 + 1e-9, stop
    assert r[f"{p}restart_bridge_stop_target_met"] == (stop <= 0.54 + 1e-6)
    assert r[f"{p}restart_bridge_at_rest_s"] <= 1.0
    assert r[f"{p}restart_bridge_resume_s"] <= 1.0
    assert r[f"{p}restart_roscore_nodes_clear"], r[f"{p}restart_roscore_exit_codes"]
