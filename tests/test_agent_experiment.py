"""``raf experiment competition`` on the smallest set: round 1, one seed, the bare stand-in (ground truth as
the agent's pose; the mode says so in every key)."""
import json

import pytest
from expargs import options

from robotatfactory.errors import ConfigError
from robotatfactory.experiments import _competition_log as complog
from robotatfactory.experiments import competition


def args(**kw):
    return options(competition, field=None, **kw)


def test_round_1_one_seed_scores_the_maximum_and_writes_its_figure(tmp_path):
    # the simulator's default magnet: SimTwo's force (docs/simulator.md, "The electromagnet"; docs/agent.md)
    res = competition.run(args(mode="bare_truth", rounds="1", seeds=1, jobs=1, seed_set="tuned"), tmp_path)
    assert res["mode"] == "bare_truth" and "ground truth" in res["pose_source"]
    assert all(k.startswith("bare_truth_") for k in res if k.endswith("_target_met"))
    assert res["bare_truth_tuned_r1_s0_points"] == res["bare_truth_tuned_r1_s0_max_points"] == 4
    assert res["bare_truth_tuned_r1_max_score_target_met"] is True
    assert res["bare_truth_tuned_r1_false_starts"] == 0 and res["bare_truth_tuned_r1_parts_pushed"] == 0
    assert res["bare_truth_tuned_r1_collisions"] == 0 and res["bare_truth_tuned_r1_pick_failures"] == 0
    t = res["bare_truth_tuned_r1_last_score_median_s"]
    assert 10.0 < t < 300.0
    assert res["bare_truth_tuned_r1_last_score_median_target_met"] == (t <= 60.0)
    assert (tmp_path / "round1_seed0_bare_truth.png").stat().st_size > 10_000
    runs = json.loads((tmp_path / "runs.json").read_text())
    assert sum(text.startswith("picked") for _, text, _, _ in runs[0]["events"]) == 4
    # the agent's recoveries, from its counters: each key per run and per round, as many as its events say
    lost = sum("lost the" in text for _, text, _, _ in runs[0]["events"])
    assert res["bare_truth_tuned_r1_s0_parts_lost"] == res["bare_truth_tuned_r1_parts_lost"] == lost
    looks = sum("look at markers" in text for _, text, _, _ in runs[0]["events"])
    assert res["bare_truth_tuned_r1_relocalizations"] == runs[0]["relocalizations"] == looks


def test_the_recoveries_are_counted_per_run_and_summed_per_round():
    """The agent's recoveries (RECOVERY_COUNTS: parts lost, stops to look at markers, ...) per run and summed
    per round over the runs that counted them; a run without the agent's counters has none of the keys."""
    from robotatfactory.agent.behaviour import RECOVERY_COUNTS, recovery_counts

    r = {"round": 1, "seed": 100, "points": 4, "max_points": 4, "max_score": True, "last_score_s": 50.0,
         "notes": [], "false_start": False, "parts_pushed": 0, "picks_attempted": 4, "pick_failures": 0,
         "timeouts": 0, "collision_checks_hit": 0, "wall_s": 1.0}
    counted = {k: 0 for k in RECOVERY_COUNTS}
    runs = [dict(r, **dict(counted, parts_lost=1, relocalizations=2, relocalize_timeouts=1)),
            dict(r, seed=101, **dict(counted, relocalizations=3)), dict(r, seed=102)]  # the last: no counters
    res = competition.summarize("full_stack", runs)
    p = "full_stack_heldout_r1"
    assert (res[f"{p}_parts_lost"], res[f"{p}_relocalizations"], res[f"{p}_relocalize_timeouts"]) == (1, 5, 1)
    assert res[f"{p}_s100_parts_lost"] == 1 and res[f"{p}_s101_relocalizations"] == 3
    assert not any(k.startswith(f"{p}_s102_") and k.endswith(RECOVERY_COUNTS) for k in res)
    assert f"{p}_parts_lost" not in competition.summarize("full_stack", [runs[2]])
    # from the agent's counters as its /diagnostics carry them: only these, and only those it has
    assert recovery_counts({"picks": 4, "parts_lost": 2, "blocked": 1}) == {"parts_lost": 2, "blocked": 1}


def test_a_missed_run_is_the_worst_time_and_fails_the_rate():
    ok = {"round": 1, "seed": 0, "points": 4, "max_points": 4, "max_score": True, "last_score_s": 50.0,
          "notes": [], "false_start": False, "parts_pushed": 0, "picks_attempted": 4, "pick_failures": 0,
          "timeouts": 0, "collision_checks_hit": 0, "wall_s": 1.0}
    miss = dict(ok, seed=1, points=3, max_score=False, last_score_s=40.0)
    res = competition.summarize("bare_truth", [ok, miss, dict(ok, seed=2, last_score_s=55.0)])
    assert res["bare_truth_tuned_r1_max_score_runs"] == 2
    assert res["bare_truth_tuned_r1_max_score_target_met"] is False  # 1 miss in 3 > one tenth
    assert res["bare_truth_tuned_r1_last_score_median_s"] == 55.0  # the miss counts as infinitely slow
    assert res["bare_truth_tuned_r1_last_score_worst_s"] is None


def test_bad_options_are_config_errors():
    with pytest.raises(ConfigError):
        competition.run(args(rounds="4"), None)
    with pytest.raises(ConfigError, match="drive.warp"):
        competition.parse_agent(["drive.warp=9"])
    with pytest.raises(ConfigError, match="dock.place_speed must be a number in"):
        competition.parse_agent(["dock.place_speed=2"])
    assert competition.parse_agent(["drive.k_heading=8", "legs/smooth=false"]) == {
        "drive": {"k_heading": 8}, "legs": {"smooth": False}}


def test_the_full_stack_mode_names_itself_and_reports_the_pose_error_against_its_target():
    """A whole-stack run takes a minute or more (realtime): its summary alone here, a real run below."""
    r = {"round": 1, "seed": 0, "points": 4, "max_points": 4, "max_score": True, "last_score_s": 84.3, "notes": [],
         "false_start": False, "picks_attempted": 4, "pick_failures": 0, "timeouts": 0, "collision_checks_hit": 2,
         "collision_hits": [(5.0, 0.1, 0.2, "wall"), (6.0, 0.1, 0.2, "wall")], "parts_pushed": 0, "wall_s": 1.0,
         "logs": "x", "pose_error_docking_max_m": 0.012, "pose_error_median_m": 0.001}
    res = competition.summarize("full_stack", [r, dict(r, seed=1, pose_error_docking_max_m=0.025)])
    assert res["mode"] == "full_stack" and "EKF" in res["pose_source"]
    assert res["full_stack_tuned_r1_last_score_median_s"] == 84.3
    assert res["full_stack_tuned_r1_last_score_median_target_met"] is False
    assert res["full_stack_tuned_r1_collisions"] == 4 and res["full_stack_tuned_r1_parts_knocked_out_target_met"] is True
    assert res["full_stack_tuned_r1_pose_error_docking_max_m"] == 0.025
    assert res["full_stack_tuned_r1_pose_error_docking_max_target_met"] is False  # 2.5 cm > 2 cm in one run
    res = competition.summarize("full_stack", [r, dict(r, seed=1, pose_error_docking_max_m=float("nan"))])
    assert res["full_stack_tuned_r1_pose_error_docking_max_target_met"] is False  # a run without the measure fails it
    fixes = dict(camera_fixes_accepted=120, camera_fixes_rejected=3, sim_s=60.0)
    res = competition.summarize("full_stack", [dict(r, **fixes), dict(r, seed=1, **dict(fixes, sim_s=30.0)),
                                               dict(r, seed=2)])  # a run without the count: not in the median
    assert [res[f"full_stack_tuned_r1_s{s}_camera_fixes_accepted_per_s"] for s in (0, 1)] == [2.0, 4.0]
    assert "full_stack_tuned_r1_s2_camera_fixes_accepted_per_s" not in res
    assert res["full_stack_tuned_r1_camera_fixes_accepted_per_s_median"] == 3.0
    with pytest.raises(ConfigError, match="bare_truth's"):  # raf sim runs its defaults: refused before any run
        competition.run(args(stack="full", rounds="1", seeds=1, pose_delay=2), None)
    with pytest.raises(ConfigError, match="--agent: .*drive.a_max must be"):  # raf agent takes --agent, checked now
        competition.run(args(stack="full", rounds="1", seeds=1, agent=["drive.a_max=-1"]), None)


REPORT = """t=  129.84s rtf  1.00x | sent 3246 cmd 3244 | score 3/4 (outgoing 3, last at 40.2 s)
raf sim: duration at t = 130.00 s of simulation in 130.00 s (real-time factor 1.00)
Round 1, incoming BBBB: run started at t = 3.00 s, report at t = 130.00 s, 473.0 s left
     40.24     3  blue   outgoing warehouse slot 3               +1
  total: 3 of 4 points; 3 part(s) in the outgoing warehouse; time of the last score 40.24 s
"""


def test_the_full_stack_reads_raf_sims_final_report_or_its_last_status_line(tmp_path):
    assert complog.parse_sim_report(REPORT) == (3, 4, 40.24, True)
    # stopped before its report: the last status line still gives the score (one decimal of time)
    head = REPORT.split("raf sim:")[0]
    assert complog.parse_sim_report(head) == (3, 4, 40.2, True)
    p, mx, t, found = complog.parse_sim_report("t= 1.0s | score 0/4 (outgoing 0)\n")
    assert (p, mx, found) == (0, 4, True) and t != t
    p, mx, t, found = complog.parse_sim_report("nothing here\n")
    assert (p, mx, found) == (0, -1, False)
    log = tmp_path / "sim.log"
    log.write_text(head)
    assert not complog.wait_for_report(log, limit=0.3, poll=0.1)
    log.write_text(REPORT)
    assert complog.wait_for_report(log, limit=0.3, poll=0.1)


def test_analyse_measures_kept_runs_again_and_names_a_missing_one(tmp_path):
    res = competition.run(args(mode="full_stack", analyse=str(tmp_path), rounds="1", seeds=1, seed_set="tuned"), None)
    assert "no such run kept" in res["full_stack_tuned_r1_s0_error"]
    assert res["full_stack_tuned_r1_max_score_target_met"] is False


def test_the_held_out_seeds_are_reported_apart_from_the_tuned_ones():
    assert competition.pick_seeds("heldout") == list(range(100, 120))
    assert competition.pick_seeds("tuned", 3) == [0, 1, 2]
    assert competition.pick_seeds("both", 2) == [0, 1, 100, 101]
    assert competition.pick_seeds("heldout", 2, first=50) == [50, 51]
    assert [competition.seed_set_of(s) for s in (0, 9, 10, 100, 119, 120)] == [
        "tuned", "tuned", "other", "heldout", "heldout", "other"]
    with pytest.raises(ConfigError):
        competition.pick_seeds("tuned", 0)
    r = {"round": 2, "seed": 0, "points": 5, "max_points": 5, "max_score": True, "last_score_s": 60.0, "notes": [],
         "false_start": False, "picks_attempted": 3, "pick_failures": 0, "timeouts": 0, "collision_checks_hit": 0,
         "parts_pushed": 0, "wall_s": 1.0}
    runs = [r, dict(r, seed=1, last_score_s=70.0), dict(r, seed=100, last_score_s=80.0, max_score=False, points=4),
            dict(r, seed=101, last_score_s=90.0)]
    res = competition.summarize("bare_truth", runs)
    assert res["bare_truth_tuned_seeds"] == "0-1" and res["bare_truth_heldout_seeds"] == "100-101"
    assert res["bare_truth_tuned_r2_max_score_runs"] == 2 and res["bare_truth_tuned_r2_last_score_median_s"] == 65.0
    assert res["bare_truth_heldout_r2_max_score_runs"] == 1 and res["bare_truth_heldout_r2_s100_points"] == 4
    assert "bare_truth_r2_max_score_runs" not in res and "heldout: 100-119" in res["seed_sets"]
    assert all(any(k.startswith(p) for k in competition.TARGETS) for p in ("bare_truth_heldout_r2", "full_stack_tuned_r1"))
    text = competition.table("bare_truth", [dict(x, time_split={}) for x in runs])
    assert "tuned 0-1" in text and "heldout 100-101" in text


def test_perturbed_world_and_lossy_link_are_named_in_every_result():
    assert competition.parse_loss("0.05") == pytest.approx((0.05, 0.01, 0.01))
    assert competition.parse_loss("0.1,0,0.02") == (0.1, 0.0, 0.02) and competition.parse_loss("0") == (0, 0, 0)
    for bad in ("x", "1.5", "0.5,0.5,0.1", "0.1,0.2"):
        with pytest.raises(ConfigError, match="--loss"):
            competition.parse_loss(bad)
    with pytest.raises(ConfigError, match="whole stack only"):  # no link to lose datagrams on in bare_truth
        competition.run(args(mode="bare_truth", rounds="1", seeds=1, loss="0.05"), None)
    with pytest.raises(ConfigError, match="bare_truth's"):  # the whole stack takes perturb.NAME only
        competition.run(args(mode="full_stack", rounds="1", seeds=1, sim=["magnet=weld"]), None)
    res = competition.run(args(mode="bare_truth", rounds="1", seeds=1, jobs=1, perturb=True,
                               sim=["perturb.field_mm=1"]), None)
    assert res["perturb_field_mm"] == 1.0 and res["perturb_parts_deg"] == 2.0  # --sim wins over --perturb
    assert res["perturb"].startswith("field 1 mm") and res["link"] == "lossless loopback"
    assert 0 < res["bare_truth_heldout_r1_s100_world_field_slot_max_mm"] < 10
    assert res["bare_truth_heldout_r1_s100_world_start_error_cm"] > 0
    plain = competition.run(args(mode="bare_truth", rounds="1", seeds=1, jobs=1), None)
    assert plain["perturb"] == "none" and not any("_world_" in k for k in plain)


def test_the_full_stack_reads_the_worlds_draw_from_raf_sims_log(tmp_path):
    from robotatfactory.experiments._competition_full import analyse

    (tmp_path / "sim.log").write_text('raf sim: world perturbed: field 2 mm, ...; offsets {"field_slot_max_mm": 4.2}\n'
                                      + REPORT)
    r = analyse(1, 100, tmp_path, tmp_path / "none.jsonl", tmp_path / "none.bag", False, None, 1.0, "ros1")
    assert r["world"] == {"field_slot_max_mm": 4.2} and r["points"] == 3 and "no ground-truth trace" in r["error"]
