"""Loading YAML presets into pydantic models, with errors that name the file and the key.

Each component owns its pydantic model (e.g. `MekfConfig` in `backends/mekf/config.py`); this module only
reads files. Presets live in `uareme_fusion/configs/` and are found by
name: `load_config("vehicle", MekfConfig)` or by path: `load_config("my.yaml", MekfConfig)`.
A key given twice in one mapping is an error (plain YAML loading would keep the last silently), and
so is a NaN or infinite number (`.nan`, `.inf`) anywhere in a file: no parameter means "unbounded".
Aliases (`*name`, which let a few hundred bytes expand to gigabytes: "billion laughs") and nesting
deeper than `MAX_YAML_DEPTH` are refused with a one-line error before anything is built.
"""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path
from typing import TypeVar

import yaml
from pydantic import BaseModel, ValidationError

from .errors import ConfigError, InputError
from .io.paths import is_pipe, read_pipe_text

ModelT = TypeVar("ModelT", bound=BaseModel)

MAX_YAML_DEPTH = 32
"""Deepest nesting of mappings and lists accepted in a configuration file (ours use 2)."""


class _UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML's safe loader, except that a key given twice in one mapping is an error (PyYAML keeps
    the last value silently), and aliases and deep nesting are refused (see the module docstring)."""

    _depth = 0

    def compose_node(self, parent, index):
        if self.check_event(yaml.events.AliasEvent):
            event = self.peek_event()
            raise yaml.composer.ComposerError(None, None, f"found the alias *{event.anchor}: aliases are not "
                                              "allowed in configuration files (write the value out)", event.start_mark)
        self._depth += 1
        try:
            if self._depth > MAX_YAML_DEPTH:
                raise yaml.composer.ComposerError(None, None, f"nested more than {MAX_YAML_DEPTH} levels deep",
                                                  self.peek_event().start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            try:
                duplicate = key in seen
            except TypeError:  # unhashable key: construct_mapping reports it
                break
            if duplicate:
                raise yaml.constructor.ConstructorError(
                    "while constructing a mapping", node.start_mark, f"found duplicate key '{key}'", key_node.start_mark
                )
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def preset_names() -> list[str]:
    """Names of the YAML presets shipped with the package."""
    return sorted(p.name[:-5] for p in resources.files("uareme_fusion.configs").iterdir() if p.name.endswith(".yaml"))


def read_yaml(name_or_path: str | Path) -> tuple[dict, str]:
    """The mapping in a preset (by name) or a YAML file (by path), and where it came from."""
    if not str(name_or_path).strip():
        raise ConfigError(f"Unknown preset '{name_or_path}' (an empty name); presets are: {', '.join(preset_names())}")
    path = Path(name_or_path)
    if path.suffix.lower() not in (".yaml", ".yml") and not path.exists():
        preset = resources.files("uareme_fusion.configs") / f"{name_or_path}.yaml"
        if not preset.is_file():
            raise ConfigError(f"Unknown preset '{name_or_path}'; presets are: {', '.join(preset_names())}")
        text, where = preset.read_text(), f"preset '{name_or_path}'"
    else:
        if path.is_dir():
            raise ConfigError(f"Cannot read config file {path}: it is a folder")
        try:
            text = read_pipe_text(path) if is_pipe(path) else path.read_text(encoding="utf-8-sig")
        except InputError as exc:  # a pipe nobody wrote to (`--config <(...)` that failed, a silent FIFO)
            raise ConfigError(f"Cannot read config file {exc}") from None
        except OSError as exc:
            raise ConfigError(f"Cannot read config file {path}: {exc.strerror or exc}") from None
        except UnicodeDecodeError as exc:
            raise ConfigError(f"Cannot read config file {path}: not UTF-8 text (byte {exc.object[exc.start]:#04x} "
                              f"at offset {exc.start})") from None
        where = str(path)
    try:
        data = yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 (a SafeLoader subclass)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError(f"{where} is not valid YAML{at}: {problem}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{where} must hold a mapping of keys to values, got {type(data).__name__}")
    bad = _non_finite_keys(data)
    if bad:
        raise ConfigError(f"{where}: {', '.join(bad)}: NaN and infinity are not allowed in configuration files")
    return data, where


def _non_finite_keys(value, prefix: str = "") -> list[str]:
    """Dotted keys (list items as [i]) holding a NaN or infinite float, anywhere in `value`."""
    if isinstance(value, float):
        return [] if math.isfinite(value) else [prefix or "(top level)"]
    if isinstance(value, dict):
        return [k for key, v in value.items() for k in _non_finite_keys(v, f"{prefix}.{key}" if prefix else str(key))]
    if isinstance(value, list):
        return [k for i, v in enumerate(value) for k in _non_finite_keys(v, f"{prefix}[{i}]")]
    return []


def renamed_keys(data, model: type[BaseModel]) -> list[str]:
    """'OLD is now NEW' for each key of `data` that `model` has renamed (its class attribute
    `renamed_keys`: old name -> new name). Old names are errors, never silent aliases."""
    renamed = getattr(model, "renamed_keys", {})
    return [f"'{old}' is now '{renamed[old]}'" for old in data if old in renamed] if isinstance(data, dict) else []


def validate_config(data: dict, model: type[ModelT], where: str = "config") -> ModelT:
    """`model(**data)` with pydantic's errors turned into one ConfigError naming each bad key; a key the
    model has renamed is one ConfigError naming the new key (`renamed_keys`)."""
    renamed = renamed_keys(data, model)
    if renamed:
        raise ConfigError(f"{where}: {'; '.join(renamed)}: rename the key")
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        problems = "; ".join(
            f"{'.'.join(str(p) for p in err['loc']) or '(top level)'}: {err['msg']}{_got(err)}" for err in exc.errors()
        )
        raise ConfigError(f"{where}: {problems}") from None


def _got(err: dict) -> str:
    """' (got VALUE)' for a scalar or short value the user wrote, '' otherwise."""
    value = err.get("input")
    if isinstance(value, dict) or err["type"] == "missing":
        return ""
    text = repr(value)
    return f" (got {text if len(text) <= 40 else text[:37] + '...'})"


def load_config(name_or_path: str | Path, model: type[ModelT], section: str | None = None) -> ModelT:
    """Read a preset or file and validate it (or its `section`, when given) against `model`.

    Models should set `model_config = ConfigDict(extra="forbid")` so unknown keys are errors.
    """
    data, where = read_yaml(name_or_path)
    if section is not None:
        data = data.get(section, {})
        where = f"{where} [{section}]"
        if data is None:
            data = {}
        if not isinstance(data, dict):
            raise ConfigError(f"{where}: the section must hold a mapping of keys to values, got {type(data).__name__}")
    return validate_config(data, model, where)
