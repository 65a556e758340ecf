"""What a run is made of: backend, its preset and overrides, the normal source, display options.

Read from YAML with `load_config(path, RunConfig)`; unknown keys and wrong types are errors that
name the key.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from ..drivers.extrinsics import parse_imu_rotation
from ..errors import ConfigError


class RunConfig(BaseModel):
    model_config = ConfigDict(extra="forbid")

    backend: Literal["mekf", "smoother", "single"] = "mekf"
    """mekf: the EKF (with the IMU when the source has one, otherwise its constant-rate model);
    smoother: the paper's sliding-window graph (gyro-aided with an IMU); single: frame by frame."""
    mekf_preset: str | None = None
    """A preset in configs/ (building, vehicle, handheld, imu_only) or a YAML path for the EKF; None:
    chosen from the source (`stages.mekf_preset_for`: handheld with a camera, imu_only without)."""
    mekf: dict[str, Any] = Field(default_factory=dict)
    """Overrides of individual EKF settings (names and units as in the preset files)."""
    smoother: dict[str, Any] = Field(default_factory=dict)
    """Overrides of the smoother settings (configs/paper.yaml, section `smoother`)."""
    normals: str = "auto"
    """auto (the source's exact normals when it has them, else depth when it has depth maps and
    intrinsics, else learned: `stages.AutoNormals`), learned, depth, source, a
    TorchScript/state-dict model file (.pt) or ONNX model (.onnx), or a folder of precomputed normal
    maps (.npz/.npy/.png)."""
    kappa_cap: float = Field(75.0, gt=0)
    """Confidence cap applied before the solver (the paper's released config)."""
    assumed_fov_deg: float = Field(60.0, gt=1.0, lt=179.0)
    """Horizontal field of view assumed for drawing when the source has no intrinsics, degrees."""
    ground_threshold_deg: float = Field(15.0, gt=0.0, lt=90.0)
    """A pixel is ground when its normal is within this angle of up, degrees."""
    intrinsics: str | None = None
    """Camera intrinsics `fx,fy,cx,cy` (pixels, optionally followed by distortion k1,k2,p1,p2[,k3]) or
    a camera file (OpenCV YAML/JSON, Kalibr camchain, EuRoC sensor.yaml); None: the source's own."""
    offline: bool = False
    """A recorded IMU-only file: estimates from the EKF run forward and backward over the whole log
    (`backends.mekf.offline`) instead of the streaming filter."""
    max_frames: int | None = Field(None, gt=0)
    """Stop after this many frames (None: the whole source)."""
    threads: int = Field(1, ge=1, le=256)
    """torch CPU threads of the learned normals. 1 by default: beside another busy process, two
    threads wait on each other and a frame can take 10x longer (README, "Troubleshooting")."""
    imu_rotation: str | None = None
    """Camera-from-IMU rotation `R_ci` (`v_c = R_ci v_i`): a named convention (android, ios), axis
    letters (rub, flu, ...), 9 numbers of a 3x3, a quaternion x,y,z,w or a Kalibr camchain .yaml
    (`drivers.extrinsics.parse_imu_rotation`). None: the source's own (identity unless calibrated)."""
    imu_time_offset_s: float | None = Field(None, allow_inf_nan=False)
    """Added to IMU stamps to put them on the camera clock (`SourceInfo.imu_time_offset_s`).
    None: the source's own (0 unless the recording says otherwise)."""

    @field_validator("mekf", "smoother")
    @classmethod
    def _no_renamed_keys(cls, value: dict, info) -> dict:
        """A key the EKF or smoother has renamed is an error naming the new key (in the file's line)."""
        from ..backends.mekf.config import MekfConfig
        from ..backends.smoother import SmootherConfig
        from ..config import renamed_keys

        renamed = renamed_keys(value, MekfConfig if info.field_name == "mekf" else SmootherConfig)
        if renamed:
            raise ValueError(f"{'; '.join(renamed)}: rename the key")
        return value

    @field_validator("imu_rotation")
    @classmethod
    def _imu_rotation_parses(cls, value: str | None) -> str | None:
        if value is not None:
            try:
                parse_imu_rotation(value, option="imu_rotation")
            except ConfigError as exc:  # "imu_rotation 'x': why" -> "why" (the key and value are named by pydantic)
                raise ValueError(str(exc).split(": ", 1)[-1]) from None
        return value
    cues: str = "normals,lines,sky"
    """Visual cues of the joint solver: normals, lines, sky (comma-separated); see solver/cues.py."""

    @field_validator("cues")
    @classmethod
    def _known_cues(cls, value: str) -> str:
        from ..solver.cues import parse_cues

        return ",".join(parse_cues(value))
