"""The competition experiment's camera calibration (``--calibration``, issue 20 item 1): the robot's side gets
the nominal map and robot file plus whatever ``raf calibrate`` recovers on a calibration drive before the
round, as a team would do.

``--calibration`` (:func:`resolve`):

* ``auto`` (the default when the world's camera is perturbed, ``--perturb`` or ``--sim perturb.camera_*``, on
  the stand-in's whole stack): before each run whose simulated camera differs from the robot file's, the
  localization experiment's calibration drive (:func:`._localization_record.calibration_drive`: the
  ``calibration`` route driven by pure pursuit on ground truth, camera/image_raw, camera_info and odom recorded
  into a bag, ``raf calibrate --bag`` on it) in the run's own world: ``raf sim --round R --seed S`` with the
  run's ``perturb.*`` settings, so the stand-in renders with the round's drawn camera (the draw is seeded by
  round and seed, one stream per kind: :mod:`robotatfactory.sim.perturb`), the fixtures displaced as in the
  round; only the start pose's perturbation is left out (the drive starts at its route's start, which is not
  in the start area). The YAML goes to the round's ``raf bridge --calibration`` and ``raf localize
  --calibration``. A run whose camera is the nominal one gets no drive (the nominal camera, said so).
* ``none`` (the default otherwise): the robot file's nominal camera, as before.
* ``FILE``: that calibration YAML for every run.

Every run says how its camera was calibrated (``calibration``) and how far the camera the robot side uses is
from the one the simulator renders with (:func:`error_keys`: ``calibration_fx_error_pct``, ``_fy_error_pct``,
``_cx_error_px``, ``_cy_error_px``, ``_pitch_error_deg``, ``_roll_error_deg``, ``_height_error_mm``,
``_forward_error_mm``; with ``none`` that is the world's camera draw, negated).

The drive runs in a child process of its own (``spawn``): it needs this process's ROS node on a private graph
(:func:`._localization_record.experiment_graph`), and rospy allows one node per process, while the experiment
plays several runs in one.
"""
from __future__ import annotations

import argparse
import json
import re
import tempfile
from pathlib import Path

CHOICES = ("auto", "none")
DRIVE_TIMEOUT_S = 300.0  # wall s for the calibration drive (about 40 s of simulated driving)
CALIBRATION_SPEED = 0.15  # m/s, the localization experiment's default
#: raf sim --set items appended for the drive: the start pose's perturbation off (last wins)
DRIVE_WORLD_OVERRIDES = ("perturb.start_cm=0", "perturb.start_deg=0")
#: the keys of :func:`error_keys`, in order
ERROR_KEYS = ("fx_error_pct", "fy_error_pct", "cx_error_px", "cy_error_px", "pitch_error_deg", "roll_error_deg",
              "height_error_mm", "forward_error_mm")


def camera_perturbed(perturb) -> bool:
    """Does this world's camera depart from the robot file's (any camera size non-zero)?"""
    return bool(perturb.camera_pct or perturb.camera_px or perturb.camera_deg)


def resolve(value: str | None, perturb, mode: str, simulator: str = "standin") -> str:
    """``--calibration`` checked: ``auto``, ``none`` or a calibration file's absolute path. None (not given):
    ``auto`` when the stand-in's whole stack renders a perturbed camera, else ``none``. ConfigError names the
    problem."""
    from ..errors import ConfigError

    whole = mode.endswith("full_stack")
    if value is None:
        return "auto" if whole and simulator == "standin" and camera_perturbed(perturb) else "none"
    value = str(value)
    if value == "none":
        return value
    if not whole:
        raise ConfigError(f"--calibration {value}: the whole stack's bridge and localizer use it; bare_truth's pose "
                          "is the ground truth (use --mode full_stack)")
    if value == "auto":
        if simulator != "standin":
            raise ConfigError("--calibration auto drives the stand-in's world; on the real SimTwo calibrate with "
                              "raf experiment calibration --simulator simtwo (or raf calibrate) and give the FILE")
        return value
    p = Path(value)
    if not p.is_file():
        raise ConfigError(f"--calibration {value!r}: not a file (or one of {', '.join(CHOICES)})")
    from ..localization.calibration import load_calibration

    load_calibration(p)  # a bad file is a ConfigError now, not in every run
    return str(p.resolve())


def drive_sim_options(round_no: int, seed: int, sim_set: tuple[str, ...]) -> tuple[str, ...]:
    """``raf sim`` options of the calibration drive in the run's world (besides ``--seed``, which the drive
    passes): the round, the run's ``--set perturb.*`` items, the start pose's perturbation off."""
    out = ["--round", str(round_no)]
    for item in (*sim_set, *DRIVE_WORLD_OVERRIDES):
        out += ["--set", item]
    return tuple(out)


def world_of(sim_set: tuple[str, ...]):
    """The :class:`~robotatfactory.sim.perturb.Perturb` that ``--set`` items make."""
    from ..settings import parse_set
    from ..sim.config import sim_config

    return sim_config(parse_set(list(sim_set))).perturb


def true_camera(perturb, round_no: int, seed: int, robot=None):
    """The camera raf sim renders with in run (round, seed) (:func:`robotatfactory.sim.perturb.true_camera` on
    the shipped robot's, as ``raf sim --robot simtwo``)."""
    from ..robot import load_robot
    from ..sim.perturb import true_camera as draw

    robot = robot or load_robot()
    return draw(robot.camera, perturb, round_no, seed)


def error_keys(calib: str | Path | None, truth, nominal) -> dict:
    """How far the camera the robot side uses (``calib`` applied to the robot file's ``nominal`` camera, as
    the bridge and the localizer do; the nominal camera when None) is from the rendering camera ``truth``:
    ``calibration_*`` keys with units (:data:`ERROR_KEYS`)."""
    from ..localization.calibration import compare, load_calibration

    used = load_calibration(calib).apply(nominal) if calib is not None else nominal
    e = compare(used, truth)
    return {f"calibration_{k}": round(float(e[k]), 4) for k in ERROR_KEYS}


def logged_world(sim_log: Path) -> dict:
    """The world offsets raf sim logged (``raf sim: world perturbed: ...; offsets {...}``), {} if none."""
    try:
        text = sim_log.read_text(errors="replace")
    except OSError:
        return {}
    found = re.findall(r"raf sim: world perturbed: .*?; offsets (\{.*\})", text)
    try:
        return json.loads(found[-1]) if found else {}
    except ValueError:
        return {}


def prepare(choice: str, round_no: int, seed: int, sim_set: tuple[str, ...], field_name: str | None,
            run_dir: Path, simulator: str = "standin") -> tuple[str | None, dict]:
    """The calibration file for run (round, seed) and its result keys (``calibration``, the errors, and with a
    drive ``calibration_wall_s``, ``calibration_bag_images``, ``calibration_drive_camera``). ``choice``: what
    :func:`resolve` gave. ``run_dir``: the run's log directory (the drive's logs and calibration.yaml go
    there). On the real SimTwo (``simulator="simtwo"``) the rendered camera is not known here: no error keys."""
    from ..robot import load_robot

    perturb = world_of(sim_set)
    nominal = load_robot()
    truth = true_camera(perturb, round_no, seed, nominal)
    calib: str | None = None
    out: dict = {}
    if choice == "none":
        out["calibration"] = "none: the robot file's nominal camera"
    elif choice == "auto" and truth == nominal.camera:
        out["calibration"] = "auto: the simulated camera is the robot file's: no drive, the nominal camera"
    elif choice == "auto":
        calib, keys = calibration_drive_in_child(round_no, seed, sim_set, field_name, run_dir)
        out["calibration"] = ("auto: raf calibrate on a calibration drive in the run's world (round "
                              f"{round_no}, seed {seed}, the start pose's perturbation left out)")
        out.update({k: v for k, v in keys.items() if k in ("calibration_wall_s", "calibration_bag_images",
                                                             "calibration_drive_wall_s", "calibration_notes")})
        cam = {k: v for k, v in keys.get("drive_world", {}).items() if k.startswith("camera_")}
        out["calibration_drive_camera"] = cam  # what the drive's raf sim logged: compared with the round's
    else:
        calib = choice
        out["calibration"] = f"file {choice}"
    if simulator == "standin":
        out.update(error_keys(calib, truth, nominal.camera))
    return calib, out


def calibration_drive_in_child(round_no: int, seed: int, sim_set: tuple[str, ...], field_name: str | None,
                               run_dir: Path) -> tuple[str, dict]:
    """:func:`_drive` in a fresh interpreter (see the module docstring); its exception, if any, raised here."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=1, mp_context=mp.get_context("spawn")) as pool:
        return pool.submit(_drive, round_no, seed, tuple(sim_set), field_name, str(run_dir)).result()


def _drive(round_no: int, seed: int, sim_set: tuple[str, ...], field_name: str | None, run_dir: str) \
        -> tuple[str, dict]:
    """The calibration drive and raf calibrate (in the child): (calibration.yaml's path, keys)."""
    import time

    from ..field import DEFAULT_FIELD
    from ..robot import load_robot
    from ._localization_record import calibration_drive, experiment_graph
    from .localization import Plan

    run_dir_p = Path(run_dir)
    run_dir_p.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="raf-comp-cal-"))  # the ~130 MB bag; removed after the drive
    # what Session and calibration_drive read of the localization experiment's options (its SimTwo-like mode:
    # raf sim's defaults, as the competition's whole stack runs it)
    largs = argparse.Namespace(field=field_name or DEFAULT_FIELD, timeout=DRIVE_TIMEOUT_S, set=[],
                               no_beacons=True, save_bag=None, calibration_speed=CALIBRATION_SPEED, seed=seed)
    plan = Plan("simtwo", (), "auto", False, 0.0, 0.0, CALIBRATION_SPEED)
    notes: list[str] = []
    t0 = time.monotonic()
    with experiment_graph("raf_experiment_competition_calibration", work, run_dir_p) as graph:
        calib, keys = calibration_drive(largs, plan, graph, run_dir_p, work, None, load_robot(), run_dir_p, notes,
                                        sim_extra=drive_sim_options(round_no, seed, sim_set))
    if notes:  # a drive that timed out: calibrated on what it recorded, said so
        keys["calibration_notes"] = "; ".join(notes)
    keys["calibration_drive_wall_s"] = round(time.monotonic() - t0, 1)
    keys["calibration_wall_s"] = round(keys.get("calibration_wall_s", 0.0), 1)
    keys["drive_world"] = logged_world(run_dir_p / "calibration" / "sim.log")
    return str(calib), keys
