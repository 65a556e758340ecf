"""YAML presets and files into pydantic models, with errors naming the file and the key."""

import pytest
from pydantic import BaseModel, ConfigDict

from uareme_fusion import ConfigError
from uareme_fusion.config import load_config, preset_names, read_yaml


class Example(BaseModel):
    model_config = ConfigDict(extra="forbid")
    window: int = 30
    sigma_rad: float = 0.1


def test_file_values_and_defaults(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("window: 12\n")
    cfg = load_config(path, Example)
    assert (cfg.window, cfg.sigma_rad) == (12, 0.1)
    path.write_text("")
    assert load_config(path, Example) == Example()


def test_section(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("smoother:\n  sigma_rad: 0.5\nother: 1\n")
    assert load_config(path, Example, section="smoother").sigma_rad == 0.5


@pytest.mark.parametrize(
    "text, message",
    [
        ("windw: 3\n", r"c\.yaml: windw: Extra inputs are not permitted"),
        ("window: many\n", r"c\.yaml: window: Input should be a valid integer"),
        ("sigma_rad: [1, 2]\n", "sigma_rad"),
        ("- 1\n- 2\n", "must hold a mapping"),
        ("window: [1,\n", "not valid YAML"),
    ],
)
def test_bad_files_name_the_key(tmp_path, text, message):
    path = tmp_path / "c.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_config(path, Example)


def test_missing_file_and_unknown_preset(tmp_path):
    with pytest.raises(ConfigError, match="Cannot read config file"):
        read_yaml(tmp_path / "nope.yaml")
    with pytest.raises(ConfigError, match="Unknown preset 'nope'; presets are: "):
        read_yaml("nope")


def test_presets_are_installed_and_valid_yaml():
    names = preset_names()
    assert "paper" in names
    for name in names:
        data, where = read_yaml(name)
        assert isinstance(data, dict) and name in where


def test_a_renamed_key_is_one_line_naming_the_file_and_the_new_key(tmp_path):
    """Every key the EKF or the smoother has renamed, in a preset-style file or in a run config's section,
    is refused with the file and the new name; never read as an alias."""
    from uareme_fusion.backends.mekf.config import MekfConfig
    from uareme_fusion.backends.smoother import SmootherConfig
    from uareme_fusion.pipeline.config import RunConfig

    path = tmp_path / "mine.yaml"
    for model, section in ((MekfConfig, "mekf"), (SmootherConfig, "smoother")):
        assert model.renamed_keys, model  # each backend has renamed keys to check
        for old, new in model.renamed_keys.items():
            assert new in model.model_fields and old not in model.model_fields
            path.write_text(f"{old}: 0.5\n")
            with pytest.raises(ConfigError) as caught:
                load_config(path, model)
            assert str(caught.value) == f"{path}: '{old}' is now '{new}': rename the key"
            path.write_text(f"{section}:\n  {old}: 0.5\n")
            with pytest.raises(ConfigError) as caught:
                load_config(path, RunConfig)
            message = str(caught.value)
            assert message.startswith(f"{path}: {section}: ") and f"'{old}' is now '{new}'" in message
            assert "\n" not in message
