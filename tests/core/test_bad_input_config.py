"""Bad configuration files and simulator options: each is a ConfigError/InputError naming the file,
the key (or option) and the problem, with the value the user wrote."""

from __future__ import annotations

import re

import numpy as np
import pytest

from uareme_fusion.backends.mekf import MekfConfig
from uareme_fusion.backends.smoother import SmootherConfig
from uareme_fusion.config import load_config, read_yaml
from uareme_fusion.errors import ConfigError, InputError
from uareme_fusion.sim.dataset import SequenceOptions, prepare_out_dir, write_sequence
from uareme_fusion.sim.imu import ImuNoise

MEKF_CASES = [
    ("unknown_key", "gyro_noise: 1e-3\n", r"gyro_noise: Extra inputs are not permitted \(got '1e-3'\)"),
    ("typo_in_one_of_many", "mode: auto\nimu_gap_limt_s: 0.1\n", "imu_gap_limt_s: Extra inputs are not permitted"),
    ("negative_density", "gyro_noise_rad_s_sqrt_hz: -1\n",
     r"gyro_noise_rad_s_sqrt_hz: Input should be greater than or equal to 0.000000001 \(got -1\)"),
    ("zero_density", "gyro_noise_rad_s_sqrt_hz: 0\n", "greater than or equal to 0.000000001"),
    ("string_for_float", "gyro_noise_rad_s_sqrt_hz: small\n", r"valid number.*\(got 'small'\)"),
    ("list_for_float", "accel_update_period_s: [0.1, 0.2]\n", "accel_update_period_s: Input should be a valid number"),
    ("mapping_for_float", "accel_update_period_s: {value: 0.1}\n",
     "accel_update_period_s: Input should be a valid number"),
    ("null_for_float", "accel_update_period_s: null\n", "accel_update_period_s: Input should be a valid number"),
    ("unknown_mode", "mode: fast\n",
     r"mode: Input should be 'auto', 'visual_imu', 'imu_only' or 'visual_only' \(got 'fast'\)"),
    ("fractional_int", "reinit_after_rejections: 2.5\n", r"reinit_after_rejections: .*fractional part \(got 2.5\)"),
    ("zero_int", "reinit_after_rejections: 0\n", "reinit_after_rejections: Input should be greater than or equal to 1"),
    ("bad_bool", "record_imu_estimates: maybe\n", r"record_imu_estimates: Input should be a valid boolean.*'maybe'"),
    ("reflection_R_ci", "R_ci: [[1, 0, 0], [0, 1, 0], [0, 0, -1]]\n",
     "R_ci: Value error, must be a 3x3 rotation matrix"),
    ("scalar_R_ci", "R_ci: 3\n", "R_ci: Input should be a valid list"),
    ("short_R_ci", "R_ci: [[1, 0], [0, 1]]\n", "R_ci: Value error, must be a 3x3 rotation"),
    ("nan_value", "gyro_noise_rad_s_sqrt_hz: .nan\n", "gyro_noise_rad_s_sqrt_hz: NaN and infinity are not allowed"),
    ("inf_value", "gyro_range_rad_s: .inf\n", "gyro_range_rad_s: NaN and infinity are not allowed"),
    ("nan_offset", "imu_time_offset_s: .NaN\n", "imu_time_offset_s: NaN and infinity"),
    ("nan_inside_R_ci", "R_ci: [[1, 0, 0], [0, .nan, 0], [0, 0, 1]]\n", r"R_ci\[1\]\[1\]: NaN and infinity"),
    ("two_errors_at_once", "mode: x\ngyro_range_rad_s: -2\n", "mode: .*; gyro_range_rad_s: "),
    ("duplicate_key", "mode: auto\nmode: imu_only\n", "found duplicate key 'mode'"),
    ("list_at_top", "- mode: auto\n", "must hold a mapping of keys to values, got list"),
    ("scalar_at_top", "42\n", "must hold a mapping of keys to values, got int"),
    ("string_at_top", "mode auto\n", "must hold a mapping of keys to values, got str"),
    ("unclosed_bracket", "R_ci: [[1, 0, 0]\n", "is not valid YAML"),
    ("tab_indentation", "mode:\n\tauto\n", "is not valid YAML"),
    ("bad_indentation", "mode: auto\n  gyro_range_rad_s: 3\n", "is not valid YAML"),
    ("python_tag", "mode: !!python/object:os.system ls\n", "is not valid YAML"),
    ("binary_file", b"\xff\xfe\x00\x00garbage", "not UTF-8 text"),
]


@pytest.mark.parametrize("case, text, message", MEKF_CASES, ids=[c[0] for c in MEKF_CASES])
def test_bad_mekf_config_files_name_the_key(tmp_path, case, text, message):
    path = tmp_path / "mine.yaml"
    path.write_bytes(text) if isinstance(text, bytes) else path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_config(path, MekfConfig)
    assert str(info.value).startswith(str(path)) or str(path) in str(info.value)
    assert re.search(message, str(info.value)), str(info.value)


SECTION_CASES = [
    ("section_is_list", "smoother:\n  - 1\n", "the section must hold a mapping, got list|must hold a mapping of keys"),
    ("section_is_scalar", "smoother: 3\n", "must hold a mapping of keys to values, got int"),
    ("unknown_key_in_section", "smoother:\n  window: 3\n", r"\[smoother\]: window: Extra inputs"),
    ("bad_mode_in_section", "smoother:\n  mode: imu\n", r"\[smoother\]: mode: Input should be"),
    ("nan_in_section", "smoother:\n  visual_huber_k: .nan\n", r"smoother.visual_huber_k: NaN and infinity"),
]


@pytest.mark.parametrize("case, text, message", SECTION_CASES, ids=[c[0] for c in SECTION_CASES])
def test_bad_sections_name_the_section_and_key(tmp_path, case, text, message):
    path = tmp_path / "s.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_config(path, SmootherConfig, section="smoother")


def test_empty_file_and_missing_section_give_the_defaults(tmp_path):
    (tmp_path / "empty.yaml").write_text("# nothing set\n")
    assert load_config(tmp_path / "empty.yaml", MekfConfig) == MekfConfig()
    assert load_config(tmp_path / "empty.yaml", SmootherConfig, section="smoother") == SmootherConfig()


@pytest.mark.parametrize(
    "name, message",
    [("vehicel", "Unknown preset 'vehicel'; presets are: .*vehicle"), ("", "Unknown preset ''"),
     ("../pyproject", "Unknown preset '../pyproject'"), ("missing.yaml", "Cannot read config file .*missing.yaml"),
     ("missing.yml", "Cannot read config file"), ("FOLDER", "it is a folder")],
    ids=["typo", "empty_name", "path_escape", "missing_yaml", "missing_yml", "folder"],
)
def test_unknown_presets_and_unreadable_paths(tmp_path, name, message):
    if name == "FOLDER":
        (tmp_path / "dir.yaml").mkdir()
        name = str(tmp_path / "dir.yaml")
    elif name.startswith("missing"):
        name = str(tmp_path / name)
    with pytest.raises(ConfigError, match=message):
        read_yaml(name)


# ---------------------------------------------------------------- simulator options

OPTION_CASES = [
    ("zero_frames", {"frames": 0}, "--frames must be between 1 and 1000000, got 0"),
    ("too_many_frames", {"frames": 10_000_000}, "--frames must be between"),
    ("tiny_image", {"width": 4, "height": 4}, "--size must be at least 8x8.*got 4x4"),
    ("negative_width", {"width": -320}, "--size must be at least 8x8"),
    ("huge_image", {"width": 100_000, "height": 100_000}, "at most 4096x4096 pixels, got 100000x100000"),
    ("zero_fps", {"fps": 0.0}, "--fps must be between 1 and 1000, got 0.0"),
    ("nan_fps", {"fps": float("nan")}, "--fps must be between 1 and 1000, got nan"),
    ("inf_imu_rate", {"imu_rate_hz": float("inf")}, "--imu-rate must be between 100 and 1000 Hz, got inf"),
    ("slow_imu", {"imu_rate_hz": 10.0}, "--imu-rate must be between"),
    ("narrow_fov", {"hfov_deg": 10.0}, "--fov-deg must be between 45 and 95 degrees, got 10.0"),
    ("nan_fov", {"hfov_deg": float("nan")}, "--fov-deg must be between"),
    ("negative_seed", {"seed": -1}, "--seed must be an integer >= 0, got -1"),
    ("nan_time_offset", {"imu_time_offset_s": float("nan")}, r"time_offset_s must be within \+-1 s, got nan"),
    ("huge_time_offset", {"imu_time_offset_s": 30.0}, "time_offset_s must be within"),
    ("R_ci_reflection", {"R_ci": np.diag([1.0, 1.0, -1.0]).tolist()}, "R_ci must be a 3x3 rotation matrix"),
    ("R_ci_not_square", {"R_ci": ((1.0, 0.0), (0.0, 1.0))}, "R_ci must be a 3x3 rotation matrix"),
    ("R_ci_scaled", {"R_ci": (2 * np.eye(3)).tolist()}, "R_ci must be a 3x3 rotation matrix"),
    ("R_ci_nan", {"R_ci": np.full((3, 3), np.nan).tolist()}, "R_ci must be a 3x3 rotation matrix"),
    ("negative_noise", {"imu_noise": ImuNoise(-1.0, 0.0, 0.0, 0.0)},
     "imu_noise: gyro_noise_rad_s_sqrt_hz must be finite"),
    ("nan_bias", {"imu_noise": ImuNoise(gyro_bias_init_rad_s=(0.0, np.nan, 0.0))}, "imu_noise: gyro_bias_init_rad_s"),
    ("short_bias", {"imu_noise": ImuNoise(accel_bias_init_m_s2=(0.0, 0.0))}, "imu_noise: accel_bias_init_m_s2"),
]


@pytest.mark.parametrize("case, kwargs, message", OPTION_CASES, ids=[c[0] for c in OPTION_CASES])
def test_bad_simulator_options_name_the_option(tmp_path, case, kwargs, message):
    options = SequenceOptions(**kwargs)
    with pytest.raises(InputError, match=message):
        options.validate()
    with pytest.raises(InputError, match=message):  # write_sequence checks before writing anything
        write_sequence("room", tmp_path / "out", options)
    assert not (tmp_path / "out").exists()


def test_unknown_scenario_and_bad_output_folders(tmp_path):
    with pytest.raises(InputError, match="unknown scenario 'moon'; valid: room"):
        write_sequence("moon", tmp_path / "out", SequenceOptions(frames=1, width=16, height=16))
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match="--out .*file exists and is not a folder"):
        prepare_out_dir(tmp_path / "file", force=False)
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "keep.txt").write_text("mine")
    with pytest.raises(InputError, match="is not empty; pass --force"):
        prepare_out_dir(tmp_path / "full", force=False)
    assert (tmp_path / "full" / "keep.txt").read_text() == "mine"
