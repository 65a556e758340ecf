"""What a run is made of: backend, its preset and overrides, the normal source, display options.

Read from YAML with `load_config(path, RunConfig)`; unknown keys and wrong types are errors that
name the key.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator


class RunConfig(BaseModel):
    model_config = ConfigDict(extra="forbid")

    backend: Literal["mekf", "smoother", "single"] = "mekf"
    """mekf: the EKF (with the IMU when the source has one, otherwise its constant-rate model);
    smoother: the paper's sliding-window graph (gyro-aided with an IMU); single: frame by frame."""
    mekf_preset: str = "handheld"
    """A preset in configs/ (building, vehicle, handheld) or a YAML path for the EKF."""
    mekf: dict[str, Any] = Field(default_factory=dict)
    """Overrides of individual EKF settings (names and units as in the preset files)."""
    smoother: dict[str, Any] = Field(default_factory=dict)
    """Overrides of the smoother settings (configs/paper.yaml, section `smoother`)."""
    normals: str = "auto"
    """auto (the source's exact normals when it has them, else learned), learned, depth, source, a
    TorchScript/state-dict model file (.pt), or a folder of precomputed normal maps (.npz/.npy/.png)."""
    kappa_cap: float = Field(75.0, gt=0)
    """Confidence cap applied before the solver (the paper's released config)."""
    assumed_fov_deg: float = Field(60.0, gt=1.0, lt=179.0)
    """Horizontal field of view assumed for drawing when the source has no intrinsics, degrees."""
    ground_threshold_deg: float = Field(15.0, gt=0.0, lt=90.0)
    """A pixel is ground when its normal is within this angle of up, degrees."""
    max_frames: int | None = Field(None, gt=0)
    """Stop after this many frames (None: the whole source)."""
    cues: str = "normals,lines"
    """Visual cues of the joint solver: normals, lines, or both (comma-separated); see pipeline/cues.py."""

    @field_validator("cues")
    @classmethod
    def _known_cues(cls, value: str) -> str:
        from .cues import parse_cues

        return ",".join(parse_cues(value))
