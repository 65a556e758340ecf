"""Every backend made by name in one place, with what each one knows (`BackendKind.knows_gravity`).

Names: `single` (each frame alone), `smoother` (the paper's sliding-window graph), `smoother-gyro`
(the same graph aided by the gyro and accelerometer) and `mekf`. `run` asks for `smoother` and gets
the gyro-aided one when its source has an IMU (`backend_kind`); `compare` runs all four by name.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..config import load_config, validate_config
from ..errors import InputError
from .base import Backend


@dataclass(frozen=True)
class BackendKind:
    name: str
    knows_gravity: bool
    """Given IMU samples, its tilt is absolute (it sees gravity): evaluation then scores NEES after a
    rotation about up only, instead of a full constant alignment."""


BACKEND_KINDS = {kind.name: kind for kind in (
    BackendKind("single", knows_gravity=False),
    BackendKind("smoother", knows_gravity=False),
    BackendKind("smoother-gyro", knows_gravity=True),
    BackendKind("mekf", knows_gravity=True),
)}
BACKEND_NAMES = tuple(BACKEND_KINDS)


def backend_kind(name: str, has_imu: bool = False) -> BackendKind:
    """The kind a run asking for `name` gets: `smoother` with an IMU is the gyro-aided smoother."""
    if name not in BACKEND_KINDS:
        raise InputError(f"unknown backend {name!r}; valid: {', '.join(BACKEND_NAMES)}")
    return BACKEND_KINDS["smoother-gyro" if name == "smoother" and has_imu else name]


def knows_gravity(kind_name: str, has_imu: bool) -> bool:
    """Whether the backend kind `kind_name` (a key of `BACKEND_KINDS`, e.g. from `backend_kind`), fed
    this IMU (or none), estimates absolute tilt."""
    return has_imu and backend_kind(kind_name).knows_gravity


def make_backend(name: str, imu_geometry: dict | None = None, mekf_preset: str | None = None,
                 overrides: dict | None = None) -> Backend:
    """Backend `name` (a key of `BACKEND_KINDS`, as given by `backend_kind`).

    `imu_geometry`: `R_ci` (3x3 list) and `imu_time_offset_s` (s, the backends' convention) of an
    IMU-fed smoother-gyro or mekf (None: identity and 0); `mekf_preset`: a shipped or user preset of
    the EKF (None: `MekfConfig` defaults); `overrides`: config keys of the smoother or EKF section
    on top, checked as a `run config [section]`.
    """
    kind = backend_kind(name)
    overrides = overrides or {}
    if kind.name == "single":
        from .single import SingleFrame

        return SingleFrame()
    if kind.name.startswith("smoother"):
        from .smoother import Smoother, SmootherConfig, SmootherMode

        base = load_config("paper", SmootherConfig, section="smoother").model_dump()
        if kind.name == "smoother-gyro":
            base.update(mode=SmootherMode.GYRO, **(imu_geometry or {}))
        return Smoother(validate_config({**base, **overrides}, SmootherConfig, "run config [smoother]"))
    from .mekf import Mekf, MekfConfig

    base = (MekfConfig() if mekf_preset is None else load_config(mekf_preset, MekfConfig)).model_dump()
    base.update(imu_geometry or {})
    return Mekf(validate_config({**base, **overrides}, MekfConfig, "run config [mekf]"))
