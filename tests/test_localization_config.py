"""config/localization.yaml against the dataclass defaults, and bad settings as clear user errors."""
import pytest

from robotatfactory.errors import ConfigError
from robotatfactory.localization.config import DEFAULT_FILE, LocalizationConfig, from_dict, load_config, read_yaml


def test_the_yaml_file_restates_the_defaults():
    """Every value in config/localization.yaml equals the code's default (the file documents them)."""
    raw = read_yaml(DEFAULT_FILE)
    default = LocalizationConfig()
    for section, values in raw.items():
        if isinstance(values, dict):
            target = getattr(default, section)
            for k, v in values.items():
                expected = target[k] if isinstance(target, dict) else getattr(target, k)
                assert expected == pytest.approx(v) if isinstance(v, float) else expected == v, (section, k)
        else:
            assert getattr(default, section) == values, section
    assert load_config() == from_dict(raw)


@pytest.mark.parametrize("bad", [
    {"nonsense": 1},
    {"pose": {"sigma_min_pix": 0.1}},
    {"pose": {"sigma_min_px": "small"}},
    {"ekf": {"history_s": True}},
    {"node": {"filter_method": "magic"}},
    {"node": {"camera_pose_method": "planar"}},
    {"node": {"initial_pose": "here"}},
    {"node": {"diagnostics_period": 0}},
    {"topics": {"pose": ""}},
    {"topics": {"unknown": "x"}},
    {"frames": "map"},
    {"detector": 3},
])
def test_bad_settings_are_user_errors(bad):
    with pytest.raises(ConfigError):
        from_dict(bad)


def test_frame_prefix_and_methods():
    cfg = from_dict({"frame_prefix": "robot1", "node": {"filter_method": "all_pnp"}})
    assert cfg.frame("base_link") == "robot1/base_link" and cfg.frame("map") == "map"
    assert cfg.node.methods() == ("closest", "all_pnp")
    assert from_dict({"node": {"all_methods": True}}).node.methods() == ("closest", "closest_checked", "all_pnp",
                                                                          "planar")


def test_a_missing_file_is_a_user_error(tmp_path):
    with pytest.raises(ConfigError):
        load_config(tmp_path / "nope.yaml")
    p = tmp_path / "list.yaml"
    p.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError):
        load_config(p)
