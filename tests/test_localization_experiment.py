"""The experiment's analysis on fabricated recordings with known errors (the full run is
`raf experiment localization`; it needs the simulator, the bridge and minutes)."""
import math

import numpy as np
import pytest

from robotatfactory.experiments._localization_analysis import analyse, table
from robotatfactory.experiments._localization_views import read_xwd


def _recording():
    t = np.arange(0.04, 20.0, 0.04)
    gt = np.column_stack([t, 0.1 * t - 1.0, 0.05 * np.sin(t), np.full_like(t, 0.2)])
    rng = np.random.default_rng(0)
    # odometry: the truth drifting 1 mm per second in y, seen from an arbitrary odom frame
    drift = gt[:, 1:4] + np.column_stack([np.zeros_like(t), 0.001 * (t - t[0]), np.zeros_like(t)])
    a, ox, oy = 0.7, 0.3, -0.1
    c, s = math.cos(a), math.sin(a)
    odo = np.column_stack([t, c * drift[:, 0] - s * drift[:, 1] + ox, s * drift[:, 0] + c * drift[:, 1] + oy,
                           drift[:, 2] + a])
    ekf = np.column_stack([gt[:, :3] + np.c_[np.zeros(len(t)), rng.normal(0, 0.0005, (len(t), 2))],
                           gt[:, 3], np.full((len(t), 3), 0.0005 ** 2)])
    tc = t[::3] + 0.013
    ref = np.column_stack([tc, np.interp(tc, t, gt[:, 1]), np.interp(tc, t, gt[:, 2]), np.full_like(tc, 0.2)])
    closest = ref.copy()
    closest[:, 1] += 0.004  # 4 mm off in x
    closest[5, 1] += 0.5  # one ambiguity flip
    pad = np.zeros((len(tc), 3))
    return {"gt": gt, "odom": odo, "ekf": ekf, "camera_pose": np.zeros((0, 5)),
            "closest": np.hstack([closest, pad]), "closest_checked": np.hstack([ref, pad]),
            "all_pnp": np.hstack([ref, pad]), "planar": np.hstack([ref, pad]),
            "accepted": np.hstack([ref, pad]), "rejected": np.hstack([closest[5:6], pad[:1]])}


def test_analysis_on_known_errors():
    d = _recording()
    errs, out = analyse(d, done_t=19.0)
    assert out["route_completed"] and out["route_duration_sim_s"] == pytest.approx(19.0 - 0.04, abs=0.05)
    assert out["planar_position_rmse_m"] < 1e-6 and out["planar_heading_rmse_deg"] < 1e-6
    n = out["closest_samples"]
    expect = math.sqrt(((n - 1) * 0.004 ** 2 + 0.504 ** 2) / n)
    assert out["closest_position_rmse_m"] == pytest.approx(expect, rel=1e-3)
    assert out["closest_position_max_m"] == pytest.approx(0.504, abs=1e-6)
    assert 0.0005 < out["ekf_position_rmse_m"] < 0.0009
    assert out["odometry_end_position_error_m"] == pytest.approx(0.019, abs=0.002)  # 1 mm/s for ~19 s
    assert out["odometry_over_ekf_end_position_error"] > 10
    assert out["ekf_position_rmse_target_met"] and out["ekf_3x_closest_target_met"]
    assert out["ekf_10x_odometry_end_met"]
    assert 1.0 < out["ekf_nees_diag_mean"] < 3.0  # x exact, y with the claimed variance: about 1
    assert "| EKF" in table(out) and "closest marker (paper)" in table(out)
    # the filter's verdicts: every accepted fix exact, the one rejected fix 50 cm off
    assert out["ekf_accepted_fixes"] == n and out["ekf_accepted_fixes_over_5cm"] == 0
    assert out["ekf_rejected_fixes"] == 1 and out["ekf_rejected_fixes_over_5cm"] == 1
    assert out["ekf_no_bad_fix_accepted_target_met"]
    d["accepted"] = np.vstack([d["accepted"], d["rejected"]])  # had the filter taken the flipped fix
    _, out2 = analyse(d, done_t=19.0)
    assert out2["ekf_accepted_fixes_over_5cm"] == 1 and not out2["ekf_no_bad_fix_accepted_target_met"]
    assert out2["ekf_accepted_fix_error_max_m"] == pytest.approx(0.504, abs=1e-6)


def _parse(*argv):
    import argparse

    from robotatfactory.experiments import localization as exp

    p = argparse.ArgumentParser()
    exp.add_arguments(p)
    return exp.plan_from_args(p.parse_args(list(argv)))


def test_options_resolve_to_a_plan(tmp_path):
    from robotatfactory.errors import ConfigError

    p = _parse()
    assert p.mode == "simtwo" and p.calibration == "auto" and not p.camera_error
    assert p.routes == (("reference", 2), ("second", 1))
    assert (p.track_error, p.radius_error) == (0.01, -0.005)
    p = _parse("--ideal", "--route", "second", "--laps", "1")
    assert p.mode == "ideal" and p.routes == (("second", 1),) and p.calibration == "none"
    assert _parse("--mode", "ideal", "--camera-error").calibration == "true"
    assert _parse("--calibration", "none", "--wheel-error", "0,0").calibration == "none"
    assert (_parse("--calibration-error", "0.02,0.01").track_error) == 0.02  # the old name still works
    f = tmp_path / "calib.yaml"
    f.write_text("camera: {fx: 230.0}\n")
    assert _parse("--calibration", str(f)).calibration == str(f.resolve())
    bag = tmp_path / "drive.bag"
    bag.write_bytes(b"")
    p = _parse("--ideal", "--bag", str(bag))  # a recorded calibration drive: calibrated from it, path resolved
    assert (p.calibration, p.bag) == ("auto", str(bag.resolve()))
    for bad in (["--calibration", str(tmp_path / "missing.yaml")], ["--laps", "0"], ["--speed", "2"],
                ["--wheel-error", "0.5,0"], ["--wheel-error", "x"]):
        with pytest.raises(ConfigError):
            _parse(*bad)
    with pytest.raises(SystemExit):
        _parse("--mode", "ideal", "--ideal")  # one or the other
    with pytest.raises(SystemExit):
        _parse("--route", "third")



def test_what_raf_calibrate_holds_follows_the_simulator_unless_told():
    """SimTwo's renderer fixes the principal point and square pixels; raf experiment compare asks the same of the
    stand-in (--calibrate-as simtwo), so that its calibration rows compare like with like."""
    import argparse

    from robotatfactory.experiments import localization as exp
    from robotatfactory.simtwo_linux.scene import SIMTWO_CALIBRATION

    p = argparse.ArgumentParser()
    exp.add_arguments(p)
    held = {(a, real): exp._constraints(p.parse_args(["--calibrate-as", a]).calibrate_as, real)
            for a in ("auto", "simtwo", "free") for real in (False, True)}
    assert held == {("auto", False): None, ("auto", True): SIMTWO_CALIBRATION, ("simtwo", False): SIMTWO_CALIBRATION,
                    ("simtwo", True): SIMTWO_CALIBRATION, ("free", False): None, ("free", True): None}
    assert p.parse_args([]).calibrate_as == "auto"

def test_mode_and_route_appear_in_every_target_key():
    from robotatfactory.experiments.localization import MODES, REAL, TARGETS

    def mode_route(k):  # (mode, route) of a key: REAL ("real_simtwo", the real SimTwo) has an underscore
        m = REAL if k.startswith(REAL + "_") else k.split("_")[0]
        return m, k[len(m) + 1:].split("_")[0]

    assert all(mode_route(k)[0] in (*MODES, REAL) and mode_route(k)[1] in ("reference", "second") for k in TARGETS)
    assert "simtwo_second_ekf_position_rmse_m" in TARGETS and "ideal_reference_ekf_accepted_fixes_over_5cm" in TARGETS
    assert "real_simtwo_second_ekf_position_rmse_m" in TARGETS


def test_xwd_reader(tmp_path):
    # a 3x2 ZPixmap, 32 bits per pixel, LSBFirst, no colormap: what xwd writes from a 24-bit Xvfb
    w, h = 3, 2
    header = np.zeros(25, dtype=">u4")
    header[0] = 100 + len(b"root\0")  # header size includes the window name
    header[1], header[2], header[3], header[4], header[5] = 7, 2, 24, w, h
    header[7], header[11], header[12], header[19] = 0, 32, w * 4, 0
    px = np.arange(w * h * 4, dtype=np.uint8).reshape(h, w, 4)
    (tmp_path / "x.xwd").write_bytes(header.tobytes() + b"root\0" + px.tobytes())
    img = read_xwd(tmp_path / "x.xwd")
    assert img.shape == (2, 3, 3) and np.array_equal(img, px[:, :, :3])


def test_bag_options(tmp_path):
    from robotatfactory.errors import ConfigError

    drive = tmp_path / "drive"  # a rosbag2 is a directory
    drive.mkdir()
    p = _parse("--bag", str(drive))
    assert p.calibration == "auto" and p.bag == str(drive.resolve())
    assert _parse().bag is None and _parse("--save-bag", str(tmp_path / "new.bag")).bag is None
    for bad in (["--bag", str(tmp_path / "missing.bag")], ["--bag", str(drive), "--calibration", "none"],
                ["--bag", str(drive), "--save-bag", str(tmp_path / "x.bag")], ["--save-bag", str(drive)]):
        with pytest.raises(ConfigError):
            _parse(*bad)


@pytest.mark.middlewares
def test_calibration_drive_recording_reads_back(middleware, tmp_path):
    """The calibration drive's bag (this middleware's format) holds what raf calibrate reads: an image per 0.2 s
    (every 3rd of a 15 fps camera, every one of a 1 fps camera), every odom and camera_info, under global names,
    at their header stamps."""
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import CameraInfo, Image

    from robotatfactory.experiments._localization_record import BagSink
    from robotatfactory.ros import messages as rm
    from robotatfactory.ros.bags import find_topic, open_bag
    from robotatfactory.ros.mw.base import stamp_ns

    path = tmp_path / ("drive.bag" if middleware == "ros1" else "drive")
    sink = BagSink(path, image_period_s=0.2)
    on_odom, on_info = sink.writer("odom", "odom"), sink.writer("camera/camera_info", "camera_info")
    for k in range(7):
        img = Image(height=2, width=3, encoding="bgr8", step=9, data=bytes([k] * 18))
        img.header.stamp = rm.stamp_ms(round(1000 * k / 15) + 7)   # the stand-in's 15 fps
        sink.image(img)
        info = CameraInfo(height=2, width=3)
        info.header.stamp = rm.stamp_ms(40 * k + 7)
        on_info(info)
        odom = Odometry()
        odom.header.stamp = rm.stamp_ms(40 * k)
        odom.twist.twist.linear.x = 0.1 * k
        on_odom(odom)
    sink.close()
    on_odom(odom)  # a late callback after the close is dropped, not an error
    assert sink.counts == {"images": 3, "odom": 7, "camera_info": 7}
    with open_bag(path) as bag:
        assert set(bag.topics) == {"/camera/image_raw", "/camera/camera_info", "/odom"}
        assert find_topic(bag.topics, "camera/image_raw") == ["/camera/image_raw"]
        images = list(bag.messages(["/camera/image_raw"]))
        odoms = list(bag.messages(["/odom"]))
    assert [t for _, t, _ in images] == [(round(1000 * k / 15) + 7) * 1_000_000 for k in (0, 3, 6)]
    assert [int(m.data[0]) for _, _, m in images] == [0, 3, 6]
    assert [stamp_ns(m.header.stamp) for _, _, m in odoms] == [40 * k * 1_000_000 for k in range(7)]
    assert odoms[-1][2].twist.twist.linear.x == pytest.approx(0.6)

    slow = BagSink(tmp_path / ("slow.bag" if middleware == "ros1" else "slow"), image_period_s=0.2)
    for ms in (0, 840, 1690, 2500, 2450):  # a 1 fps software camera (SimTwo's on a slow host), then a restart
        img = Image(height=2, width=3, encoding="bgr8", step=9, data=bytes(18))
        img.header.stamp = rm.stamp_ms(ms)
        slow.image(img)
    slow.close()
    assert slow.counts["images"] == 5
