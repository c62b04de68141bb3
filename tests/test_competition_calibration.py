"""``raf experiment competition --calibration`` (issue 20 item 1): the option's plumbing only, no drive and no
whole-stack run (a calibration drive and a round take minutes of realtime)."""
import argparse
import dataclasses

import pytest
from expargs import options

from robotatfactory.errors import ConfigError
from robotatfactory.experiments import _competition_calibration as cc
from robotatfactory.experiments import competition
from robotatfactory.robot import load_robot
from robotatfactory.sim.perturb import ISSUE_20, Perturb, World

PERTURB_ITEMS = tuple(f"perturb.{k}={v}" for k, v in dataclasses.asdict(ISSUE_20).items())


def args(**kw):
    return options(competition, field=None, **kw)


def test_the_default_is_auto_only_when_the_whole_stack_renders_a_perturbed_camera(tmp_path):
    no_camera = dataclasses.replace(ISSUE_20, camera_pct=0.0, camera_px=0.0, camera_deg=0.0)
    assert cc.resolve(None, ISSUE_20, "full_stack") == "auto"
    assert cc.resolve(None, Perturb(camera_deg=0.5), "full_stack") == "auto"
    assert cc.resolve(None, no_camera, "full_stack") == "none"  # the field, parts and start only
    assert cc.resolve(None, Perturb(), "full_stack") == "none"
    assert cc.resolve(None, ISSUE_20, "bare_truth") == "none"  # ground truth as the pose: no camera
    assert cc.resolve(None, ISSUE_20, "simtwo_full_stack", "simtwo") == "none"
    assert cc.resolve("none", ISSUE_20, "full_stack") == "none"
    with pytest.raises(ConfigError, match="bare_truth's pose"):
        cc.resolve("auto", ISSUE_20, "bare_truth")
    with pytest.raises(ConfigError, match="real SimTwo"):
        cc.resolve("auto", Perturb(), "simtwo_full_stack", "simtwo")
    with pytest.raises(ConfigError, match="not a file"):
        cc.resolve(str(tmp_path / "missing.yaml"), ISSUE_20, "full_stack")
    bad = tmp_path / "bad.yaml"
    bad.write_text("camera: {fx: -3}\n")
    with pytest.raises(ConfigError):
        cc.resolve(str(bad), ISSUE_20, "full_stack")
    good = _calibration_file(tmp_path, load_robot().camera)
    assert cc.resolve(str(good), ISSUE_20, "full_stack") == str(good.resolve())
    with pytest.raises(ConfigError, match="bare_truth's pose"):  # checked before any run
        competition.run(args(mode="bare_truth", rounds="1", seeds=1, calibration="auto"), None)


def _calibration_file(tmp_path, camera, name="cal.yaml"):
    from robotatfactory.localization.calibration import write_calibration

    return write_calibration(tmp_path / name, camera, {"source": "test"})


@pytest.mark.parametrize("round_no,seed", [(1, 100), (3, 107)])
def test_the_calibration_drive_renders_the_rounds_camera_in_the_rounds_world(round_no, seed):
    """The drive's raf sim options (its --seed is the run's) draw the same camera and fixtures as the round's
    raf sim, and no start pose error (the drive starts at its route's start, outside the start area)."""
    from robotatfactory.field import load_field
    from robotatfactory.settings import parse_set
    from robotatfactory.sim.config import sim_config

    opts = cc.drive_sim_options(round_no, seed, PERTURB_ITEMS)
    assert opts[:2] == ("--round", str(round_no))
    items = [opts[i + 1] for i, o in enumerate(opts) if o == "--set"]
    drive_cfg = sim_config({**parse_set(items), "round_no": round_no, "seed": seed})
    round_cfg = sim_config({**parse_set(list(PERTURB_ITEMS)), "round_no": round_no, "seed": seed})
    assert drive_cfg.perturb.start_cm == drive_cfg.perturb.start_deg == 0.0
    field, robot = load_field(), load_robot()
    route_start = (-0.725, -0.40, 1.5708)
    drive = World.draw(field, robot, drive_cfg.perturb, round_no, seed, route_start)
    rnd = World.draw(field, robot, round_cfg.perturb, round_no, seed)
    assert drive.robot.camera == rnd.robot.camera != robot.camera
    assert drive.robot.camera == cc.true_camera(round_cfg.perturb, round_no, seed)
    assert [m.position.tolist() for m in drive.field.markers] == [m.position.tolist() for m in rnd.field.markers]
    assert drive.start is None and rnd.start is not None
    # another round or seed: another camera
    assert cc.true_camera(round_cfg.perturb, round_no, seed + 1) != rnd.robot.camera


def test_the_used_cameras_errors_against_the_rendered_one(tmp_path):
    nominal = load_robot()
    truth = cc.true_camera(ISSUE_20, 1, 100, nominal)
    none = cc.error_keys(None, truth, nominal.camera)
    assert list(none) == [f"calibration_{k}" for k in cc.ERROR_KEYS]
    assert none["calibration_cx_error_px"] == pytest.approx(nominal.camera.cx - truth.cx, abs=1e-3)
    assert none["calibration_pitch_error_deg"] == pytest.approx(nominal.camera.pitch_down_deg - truth.pitch_down_deg,
                                                                abs=1e-3)
    assert none["calibration_fx_error_pct"] == pytest.approx(100 * (nominal.camera.fx / truth.fx - 1), abs=1e-3)
    exact = cc.error_keys(_calibration_file(tmp_path, truth), truth, nominal.camera)
    assert all(abs(v) < 1e-3 for v in exact.values())


def test_prepare_drives_only_when_the_camera_differs(tmp_path, monkeypatch):
    nominal = load_robot()
    calls = []

    def fake_drive(round_no, seed, sim_set, field_name, run_dir):
        calls.append((round_no, seed, sim_set, run_dir))
        truth = cc.true_camera(cc.world_of(sim_set), round_no, seed, nominal)
        return str(_calibration_file(run_dir, truth, "calibration.yaml")), {
            "calibration_wall_s": 50.0, "calibration_bag_images": 170, "calibration_drive_wall_s": 60.0,
            "drive_world": {"camera_fx_error_pct": 2.6, "start_error_cm": 0.0}}

    monkeypatch.setattr(cc, "calibration_drive_in_child", fake_drive)
    calib, keys = cc.prepare("none", 1, 100, PERTURB_ITEMS, None, tmp_path)
    assert calib is None and keys["calibration"].startswith("none") and not calls
    assert abs(keys["calibration_fx_error_pct"]) > 0.01
    calib, keys = cc.prepare("auto", 1, 100, ("perturb.field_mm=2",), None, tmp_path)  # the nominal camera
    assert calib is None and "no drive" in keys["calibration"] and not calls
    assert keys["calibration_fx_error_pct"] == 0.0
    calib, keys = cc.prepare("auto", 1, 100, PERTURB_ITEMS, None, tmp_path)
    assert calls == [(1, 100, PERTURB_ITEMS, tmp_path)] and calib == str(tmp_path / "calibration.yaml")
    assert keys["calibration"].startswith("auto: raf calibrate") and keys["calibration_bag_images"] == 170
    assert keys["calibration_drive_camera"] == {"camera_fx_error_pct": 2.6}
    assert abs(keys["calibration_fx_error_pct"]) < 1e-3  # the fake calibrated exactly
    calib, keys = cc.prepare(str(calib), 2, 101, PERTURB_ITEMS, None, tmp_path)  # a file for every run
    assert keys["calibration"].startswith("file ") and len(calls) == 1 and "calibration_fx_error_pct" in keys
    _, keys = cc.prepare(str(calib), 1, 0, (), "simtwo2022", tmp_path, "simtwo")  # SimTwo's camera: unknown here
    assert keys["calibration"].startswith("file ") and not any("_error_" in k for k in keys)


def test_the_whole_stack_run_gets_the_file_and_reports_it(tmp_path, monkeypatch):
    from robotatfactory.experiments import _competition_full as full

    seen = {}

    def fake_prepare(choice, round_no, seed, sim_set, field_name, run_dir, simulator="standin"):
        seen["run_dir"] = run_dir
        return str(tmp_path / "cal.yaml"), {"calibration": "auto: ...", "calibration_fx_error_pct": 0.1,
                                            "calibration_roll_error_deg": -0.2,
                                            "calibration_drive_camera": {"camera_fx_error_pct": 2.6}}

    def fake_play(round_no, seed, out_dir, record, field_name, simulator, localize, agent, sim_set, loss,
                  calibration=None, log_dir=None, paced=False, compose=False):
        seen.update(calibration=calibration, log_dir=log_dir, paced=paced, compose=compose)
        return {"round": round_no, "seed": seed, "points": 4, "max_points": 4, "max_score": True,
                "last_score_s": 60.0, "notes": [], "false_start": False, "picks_attempted": 4, "pick_failures": 0,
                "timeouts": 0, "collision_checks_hit": 0, "parts_pushed": 0, "wall_s": 1.0, "logs": "x",
                "world": {"camera_fx_error_pct": 2.6, "start_error_cm": 3.0}}

    monkeypatch.setattr(cc, "prepare", fake_prepare)
    monkeypatch.setattr(full, "play_full_stack", fake_play)
    r = competition._full_job(1, 100, tmp_path, False, None, sim_set=PERTURB_ITEMS, calibration="auto")
    assert seen["calibration"] == str(tmp_path / "cal.yaml") and seen["log_dir"] == seen["run_dir"] \
        == tmp_path / "full_r1_s100"
    assert seen["paced"] is False  # the wall clock's pace unless asked (--pace paced)
    assert seen["compose"] is False  # a process per node unless asked (--nodes composed)
    competition._full_job(1, 100, tmp_path, False, None, sim_set=PERTURB_ITEMS, calibration="auto", paced=True)
    assert seen["paced"] is True
    assert r["calibration_drive_same_camera"] is True and "calibration_drive_camera" not in r
    res = competition.summarize("full_stack", [r, dict(r, seed=101, calibration_fx_error_pct=-0.3)])
    assert res["full_stack_heldout_r1_s100_calibration"] == "auto: ..."
    assert res["full_stack_heldout_r1_s100_calibration_fx_error_pct"] == 0.1
    assert res["full_stack_heldout_r1_calibration_fx_error_max_abs_pct"] == 0.3
    assert res["full_stack_heldout_r1_calibration_roll_error_max_abs_deg"] == 0.2

    def broken(*a, **k):
        raise RuntimeError("raf calibrate failed")

    monkeypatch.setattr(cc, "prepare", broken)
    r = competition._full_job(1, 100, tmp_path, False, None, calibration="auto")
    assert "camera calibration (auto)" in r["error"] and r["max_score"] is False

    # a port taken between choosing and binding it (another run's, a node's connection): the drive again, twice
    tried = []

    def port_race(*a, **k):
        tried.append(1)
        if len(tried) < 3:
            raise RuntimeError("sim exited early with code 2: cannot bind the camera publisher tcp://127.0.0.1:1: "
                               "Address already in use")
        return fake_prepare(*a, **k)

    monkeypatch.setattr(cc, "prepare", port_race)
    r = competition._full_job(1, 100, tmp_path, False, None, sim_set=PERTURB_ITEMS, calibration="auto")
    assert len(tried) == 3 and "error" not in r and r["calibration_drive_same_camera"] is True

    def always(*a, **k):
        tried.append(1)
        raise RuntimeError("Address already in use")

    tried.clear()
    monkeypatch.setattr(cc, "prepare", always)
    r = competition._full_job(1, 100, tmp_path, False, None, calibration="auto")
    assert len(tried) == 3 and "camera calibration (auto)" in r["error"]


def test_the_calibration_drive_passes_the_worlds_options_to_raf_sim(tmp_path, monkeypatch):
    """Session.start hands sim_extra to raf sim after its own options (the localization experiment's drive has
    none)."""
    from robotatfactory.experiments import _localization_record as rec
    from robotatfactory.experiments.localization import Plan
    from robotatfactory.localization.route import make_route

    started = {}
    monkeypatch.setattr(rec.time, "sleep", lambda s: None)
    largs = argparse.Namespace(field="rules2026", timeout=10.0, set=[], no_beacons=True, save_bag=None,
                               calibration_speed=0.15, seed=100)
    plan = Plan("simtwo", (), "auto", False, 0.0, 0.0, 0.15)
    graph = argparse.Namespace(env=lambda: {})
    extra = cc.drive_sim_options(2, 100, ("perturb.camera_pct=2",))
    ses = rec.Session(largs, plan, graph, tmp_path, "calibration", make_route("calibration", 1), None, None,
                      localize=False, sim_extra=extra)
    monkeypatch.setattr(ses.procs, "start", lambda name, cmd, env: started.__setitem__(name, cmd))
    ses.start()
    sim = started["sim"]
    assert sim[-len(extra):] == list(extra) and "--seed" in sim and sim[sim.index("--seed") + 1] == "100"
    assert "--calibration" not in started["bridge"] and "localize" not in started


def test_the_help_prints():
    """argparse formats help with %: the --perturb help names "camera 2 %" (it raised ValueError)."""
    p = argparse.ArgumentParser()
    competition.add_arguments(p)
    text = p.format_help()
    assert "--calibration auto|none|FILE" in text and "camera 2 % 3 px" in text


def test_a_kept_run_measured_again_keeps_how_its_camera_was_calibrated(tmp_path):
    """--analyse DIR re-measures a kept run from its logs; the calibration keys come from its runs.json."""
    import json

    (tmp_path / "full_r1_s100").mkdir()
    (tmp_path / "full_r1_s100" / "sim.log").write_text("nothing\n")
    (tmp_path / "runs.json").write_text(json.dumps([{"round": 1, "seed": 100, "wall_s": 200.0,
                                                      "calibration": "auto: ...", "calibration_cy_error_px": -2.1}]))
    r = competition._reanalysed(tmp_path, 1, 100, False, None)
    assert r["calibration"] == "auto: ..." and r["calibration_cy_error_px"] == -2.1 and r["wall_s"] == 200.0


def test_a_round_tried_again_after_a_port_race_starts_on_a_clean_directory(tmp_path, monkeypatch):
    """raf sim exits at once when another run took its port (SimStartError): the round is tried again. The first
    attempt's recorder had opened pose.bag, and the recorder never overwrites a bag: the second attempt failed
    (issue 20's batch at 1c0c55a, round 1 seed 113). The attempt's outputs go before the next one."""
    from robotatfactory.experiments import _competition_full as full

    attempts = []

    def play(round_no, seed, out_dir, record, field_name, simulator, localize, agent, sim_set, loss,
             calibration=None, log_dir=None, paced=False, compose=False):
        attempts.append(sorted(p.name for p in log_dir.iterdir()))
        if (log_dir / "pose.bag").exists():  # as raf record does
            raise RuntimeError(f"stack exited early with code 2: {log_dir / 'pose.bag'} exists already")
        (log_dir / "pose.bag").write_bytes(b"#ROSBAG V2.0\n")
        (log_dir / "trace.jsonl").write_text("{}\n")
        (log_dir / "pose_bag").mkdir()
        (log_dir / "sim.log").write_text("raf sim: cannot bind: Address already in use\n")
        if len(attempts) < 3:
            raise full.SimStartError("raf sim could not start (exit code 2)")
        return {"round": round_no, "seed": seed, "points": 4, "max_points": 4, "max_score": True,
                "last_score_s": 60.0, "notes": [], "false_start": False}

    monkeypatch.setattr(full, "play_full_stack", play)
    r = competition._full_job(1, 100, tmp_path, False, None)
    assert "error" not in r and r["max_score"] is True, r
    assert attempts == [[], ["sim.log"], ["sim.log"]]  # the logs stay (overwritten), the outputs go


def test_a_round_whose_stack_lost_a_port_to_another_run_is_tried_again(tmp_path, monkeypatch):
    """A node of the stack (the bridge in raf compose) that finds its port taken exits at once: the round is tried
    again on fresh ports, as when raf sim does (lost as a failed run in a camera_every=12 batch, round 1 seed 102);
    any other crash is a failed run at once."""
    from robotatfactory.experiments import _competition_full as full

    attempts = []

    def play(round_no, seed, *a, log_dir=None, **k):
        attempts.append(1)
        if len(attempts) < 2:
            raise RuntimeError("stack exited early with code 2:\nraf compose: error: the bridge cannot bind udp "
                               "127.0.0.1:50971: Address already in use (~udp/bind_host, ~udp/port)")
        return {"round": round_no, "seed": seed, "points": 4, "max_points": 4, "max_score": True,
                "last_score_s": 60.0, "notes": [], "false_start": False}

    monkeypatch.setattr(full, "play_full_stack", play)
    r = competition._full_job(1, 100, tmp_path, False, None)
    assert "error" not in r and r["max_score"] is True and len(attempts) == 2, r

    def crash(*a, **k):
        attempts.append(1)
        raise RuntimeError("stack exited early with code 1: raf localize: Traceback ...")

    attempts.clear()
    monkeypatch.setattr(full, "play_full_stack", crash)
    r = competition._full_job(1, 100, tmp_path, False, None)
    assert len(attempts) == 1 and "raf localize" in r["error"] and r["max_score"] is False


def test_the_whole_stack_refuses_the_bare_stand_ins_sim_settings_and_simtwo_the_stand_ins():
    """``--sim``: the whole stack passes only perturb.NAME and camera_every on to raf sim; another SimConfig
    setting is the bare stand-in's, and the real SimTwo takes none of the stand-in's (checked before any run)."""
    with pytest.raises(ConfigError, match="bare_truth's"):
        competition.run(args(mode="full_stack", rounds="1", seeds=1, sim=["magnet=weld"]), None)
    with pytest.raises(ConfigError, match="real SimTwo's scene and camera"):
        competition.run(args(mode="full_stack", rounds="1", seeds=1, simulator="simtwo", sim=["camera_every=12"]),
                        None)


def test_an_out_directory_with_an_earlier_batchs_bags_is_refused_before_any_run(tmp_path, monkeypatch):
    """The recorder never overwrites a bag: in an ``--out`` that holds an earlier batch's runs every run would fail
    at its start, minutes in (the real SimTwo started for each); the batch is refused before the first."""
    started = []
    monkeypatch.setattr(competition, "_full_item", lambda *a, **kw: started.append(a))
    (tmp_path / "simtwo_r2_s101").mkdir()
    (tmp_path / "simtwo_r2_s101" / "pose.bag").write_bytes(b"")
    with pytest.raises(ConfigError, match=r"simtwo_r2_s101/pose.bag from an earlier batch"):
        competition.run(args(mode="full_stack", rounds="1,2", seeds=2, first_seed=100, simulator="simtwo"), tmp_path)
    (tmp_path / "full_r1_s100").mkdir()
    (tmp_path / "full_r1_s100" / "trace.jsonl").write_text("{}\n")
    with pytest.raises(ConfigError, match=r"full_r1_s100/trace.jsonl from"):
        competition.run(args(mode="full_stack", rounds="1", seeds=1, first_seed=100), tmp_path)
    assert not started
    with pytest.raises(ConfigError, match="and 1 more"):  # both runs' leftovers named by count
        (tmp_path / "full_r2_s101").mkdir()
        (tmp_path / "full_r2_s101" / "pose_bag").mkdir()
        competition.run(args(mode="full_stack", rounds="1,2", seeds=2, first_seed=100), tmp_path)
