"""raf bench bridge's bookkeeping across middlewares: which ones it measures, how runs combine, the table.
(The measurement itself is the benchmark: raf bench bridge; speed targets are not unit tests.)"""
import math

import pytest

from robotatfactory.bench import bridge


def _run(p99, fps, rtt=0.5):
    return {"middleware": "x", "odom_latency_p99_ms": p99, "camera_max_frames_per_s": fps, "reply_rtt_median_ms": rtt,
            "odom_samples": 1000, "odom_p99_target_met": p99 <= 2.0, "camera_latency_p99_ms": None}


def test_runs_combine_into_medians_per_middleware():
    out = bridge.combine({"ros1": [_run(1.5, 200.0), _run(3.0, 150.0), _run(1.8, 120.0)],
                          "ros2": [_run(2.5, 90.0)]})
    assert out["ros1_odom_latency_p99_ms"] == pytest.approx(1.8)
    assert out["ros1_camera_max_frames_per_s"] == pytest.approx(150.0)
    assert out["ros1_odom_samples"] == 1000 and isinstance(out["ros1_odom_samples"], int)
    assert out["ros1_odom_latency_p99_ms_runs"] == "1.50 / 3.00 / 1.80"
    assert out["ros1_runs"] == 3 and out["ros2_runs"] == 1
    # targets judged on the medians, not copied from one run (run 2 missed, the median meets)
    assert out["ros1_odom_p99_target_met"] is True and out["ros1_camera_rate_target_met"] is True
    assert out["ros2_odom_p99_target_met"] is False and out["ros2_camera_rate_target_met"] is False
    assert "ros2_odom_latency_p99_ms_runs" not in out  # one run: nothing to list
    assert out["ros1_camera_latency_p99_ms"] is None  # a figure a run could not measure stays missing
    assert not any(k.startswith(("odom", "camera")) for k in out)  # every key names its middleware


def test_a_missing_p99_is_no_target_met():
    out = bridge.combine({"ros2": [_run(float("nan"), 0.0)]})
    assert math.isnan(out["ros2_odom_latency_p99_ms"]) and out["ros2_odom_p99_target_met"] is False


def test_side_by_side_table_has_one_column_per_middleware():
    out = bridge.combine({"ros1": [_run(1.5, 200.0)], "ros2": [_run(2.5, 90.0)]})
    text = bridge.side_by_side(out, ["ros1", "ros2"], 1)
    row = next(line for line in text.splitlines() if "`odom_latency_p99_ms`" in line)
    assert row.split("|")[2].strip() == "1.50" and row.split("|")[3].strip() == "2.50"
    assert "| figure | ros1 | ros2 |" in text
    assert set(bridge.TARGETS) == {f"{m}_{k}" for m in ("ros1", "ros2")
                                   for k in ("odom_latency_p99_ms", "camera_max_frames_per_s")}


def test_middleware_choice(monkeypatch):
    from robotatfactory.errors import ConfigError
    from robotatfactory.ros import processes

    monkeypatch.setattr(processes, "interpreter", lambda m: "/usr/bin/python3" if m == "ros1" else None)
    assert bridge.middlewares_to_measure(None) == ["ros1"]
    assert bridge.middlewares_to_measure("ros1, ros1") == ["ros1"]
    for bad in ("ros3", "ros2", ","):
        with pytest.raises(ConfigError):
            bridge.middlewares_to_measure(bad)
