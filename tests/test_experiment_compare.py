"""raf experiment compare: its summary and table (the measurements themselves run the other experiments)."""
import pytest
from robotatfactory.errors import ConfigError
from robotatfactory.experiments import compare


def test_ranges_difference_and_spread_per_simulator():
    values = {"speed": {"standin": [{"speed_rmse_mps": 0.006}, {"speed_rmse_mps": 0.008}],
                        "simtwo": [{"speed_rmse_mps": 0.012}, {"speed_rmse_mps": 0.011}]},
              "competition": {"standin": [{"points": 4}], "simtwo": [{"points": 1, "last_score_s": float("nan")}]}}
    out = compare.summarise(values, ["speed", "competition"], ["standin", "simtwo"])
    assert out["speed_rmse_mps_standin_min"] == pytest.approx(6.0)  # scaled to mm/s
    assert out["speed_rmse_mps_simtwo_median"] == pytest.approx(11.5)
    assert out["speed_rmse_mps_difference"] == pytest.approx(4.5)
    assert out["speed_rmse_mps_spread"] == pytest.approx(2.0)
    assert out["speed_rmse_mps_beyond_spread"] is True
    assert out["points_difference"] == -3 and out["points_beyond_spread"] is True  # one run each: no spread
    assert "last_score_s_simtwo_median" not in out  # NaN is no value
    text = compare.table(out, ["speed", "competition"], ["standin", "simtwo"])
    assert "| speed test RMS error | mm/s | 6 .. 8 | 11 .. 12 | **yes** |" in text
    assert "| round points | - | 4 | 1 | **yes** |" in text


def test_a_difference_within_the_spread_is_not_flagged():
    values = {"speed": {"standin": [{"speed_lag_ms": 20.0}, {"speed_lag_ms": 30.0}],
                        "simtwo": [{"speed_lag_ms": 24.0}, {"speed_lag_ms": 27.0}]}}
    out = compare.summarise(values, ["speed"], ["standin", "simtwo"])
    assert out["speed_lag_ms_beyond_spread"] is False


def test_options_are_checked():
    with pytest.raises(ConfigError, match="--parts"):
        compare._choice("drive,nope", compare.PARTS, "--parts")
    assert compare._choice("simtwo", compare.SIMULATORS, "--simulators") == ["simtwo"]
