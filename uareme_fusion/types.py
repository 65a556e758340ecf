"""Typed values that cross stage boundaries (see docs/design.md "Data flow").

Conventions: camera frame `c` is OpenCV (x right, y down, z forward); world `w` is z up; `m` is the
Manhattan frame. `R_ab` maps b-coordinates to a-coordinates. Covariances are of the right
perturbation `delta` in `R = R_hat @ Exp(delta)`, in rad^2. Times are float seconds.
"""

from __future__ import annotations

import dataclasses
import enum
from dataclasses import dataclass, field

import numpy as np

from .rotations import nearest_symmetric, up_in_camera


@dataclass(frozen=True)
class Frame:
    """One camera image. `rgb` (H, W, 3) uint8 in RGB order; `depth` (H, W) float32 metres with 0 or
    NaN where missing; `K` (3, 3) intrinsics in pixels, None when unknown."""

    t_s: float
    rgb: np.ndarray | None = None
    depth: np.ndarray | None = None
    K: np.ndarray | None = None
    index: int = -1
    normals: "NormalMap | None" = None
    """Precomputed normals for this frame (the simulator's exact normals, or a file), used when the
    pipeline is told to take normals from the source instead of estimating them."""


IMU_COLUMNS = 8
"""Columns of an `ImuBatch` row: time (s), gyro x y z (rad/s), accel x y z (m/s^2), saturated (0 or 1)."""


class ImuBatch:
    """Consecutive IMU readings in the IMU frame `i`: gyro in rad/s, specific force in m/s^2 (an
    accelerometer at rest reads +9.81 along up), one row each of `rows` (N, 8) (see `IMU_COLUMNS`).
    The fields are views: `t_s` (N,), `gyro_rad_s` (N, 3), `accel_m_s2` (N, 3), `saturated` (N,)
    (nonzero where the gyro is at or beyond its range on some axis).

        batch = ImuBatch(t_s, gyro_rad_s, accel_m_s2)     # copies the columns into rows
        batch[10:20], ImuBatch.concat([a, b]), ImuBatch.empty()
    """

    __slots__ = ("rows",)

    def __init__(self, t_s, gyro_rad_s, accel_m_s2, saturated=None):
        rows = np.empty((np.shape(t_s)[0], IMU_COLUMNS))
        rows[:, 0], rows[:, 1:4], rows[:, 4:7] = t_s, gyro_rad_s, accel_m_s2
        rows[:, 7] = 0.0 if saturated is None else saturated
        self.rows = rows

    @classmethod
    def from_rows(cls, rows: np.ndarray) -> "ImuBatch":
        """A batch holding `rows` (N, 8) itself (no copy)."""
        batch = cls.__new__(cls)
        batch.rows = rows
        return batch

    @classmethod
    def empty(cls) -> "ImuBatch":
        return cls.from_rows(np.zeros((0, IMU_COLUMNS)))

    @classmethod
    def concat(cls, batches: list["ImuBatch"]) -> "ImuBatch":
        """One batch of all rows in order (the batch itself when there is one)."""
        if len(batches) == 1:
            return batches[0]
        return cls.from_rows(np.concatenate([b.rows for b in batches]) if batches else np.zeros((0, IMU_COLUMNS)))

    def __getitem__(self, index) -> "ImuBatch":
        """The rows at `index` (a slice gives views, a mask or index array copies)."""
        return ImuBatch.from_rows(self.rows[index])

    @property
    def t_s(self) -> np.ndarray:
        return self.rows[:, 0]

    @property
    def gyro_rad_s(self) -> np.ndarray:
        return self.rows[:, 1:4]

    @property
    def accel_m_s2(self) -> np.ndarray:
        return self.rows[:, 4:7]

    @property
    def saturated(self) -> np.ndarray:
        return self.rows[:, 7]

    def __len__(self) -> int:
        return self.rows.shape[0]


@dataclass(frozen=True)
class NormalMap:
    """Per-pixel unit normals (H, W, 3) in the camera frame and confidence kappa (H, W) >= 0
    (0 means "ignore this pixel")."""

    normals: np.ndarray
    kappa: np.ndarray
    t_s: float = float("nan")
    independent_regions: float | None = None
    """How many independent errors a fully valid map of this source carries (errors are spatially
    correlated); the solver's covariance shrinks with it. None: the solver's default, fitted for
    network-like errors. Depth normals set it from their plane-fitting window."""
    regions_cost: float | None = None
    """For a network's normals: the solver's residual cost E (its normalised quartic) up to which
    `independent_regions` holds; above it, a map explained that badly is wrong by whole surfaces, and its
    independent errors shrink as regions_cost / E (`manhattan.surface_regions`). None: they do not."""
    textured_fraction: float | None = None
    """The image's textured fraction (`solver.evidence.textured_fraction`, at its default width) where the
    source measured it (learned normals), for the evidence check to reuse; None: not measured."""


@dataclass(frozen=True)
class VisualRotation:
    """The Manhattan solver's answer for one normal map.

    `R_cm` maps Manhattan coordinates to camera coordinates; its columns are the scene's three axes
    seen from the camera. `cov` (3, 3, rad^2) is the covariance of `delta` in
    `R_cm_true = R_cm @ Exp(delta)`: absolute and calibrated, usable by a filter as it is.
    """

    R_cm: np.ndarray
    cov: np.ndarray
    cost: float
    """Weighted mean cost sum_i w_i (1 - sum_k (n_i . r_k)^4) / sum_i w_i, in [0, 1]; 0 is a perfect
    Manhattan map, 0.4 is what isotropic random normals give."""
    iterations: int
    n_valid: int
    n_invalid: int = 0
    quality: float = 0.0
    """1 - cost / 0.4, clipped to [0, 1]: how Manhattan the view looks."""
    converged: bool = True
    t_s: float = float("nan")
    timing_ms: dict = field(default_factory=dict)
    cues: dict = field(default_factory=dict)
    """Per visual cue ("normals", "lines") that took part: its share of the information (trace of
    its information matrix over the total), cost and count. Empty for the normals-only solver."""
    jump_deg: float = 0.0
    """When the frame's own evidence overrode the prior it was started from (a stream's previous frame or
    prediction), the angle (deg) from the prior's own minimum to the one kept; 0 when it did not."""
    reason: str = ""
    """Why the covariance is wide, when the frame has no usable evidence (e.g. "no valid normals, too few
    segments"); empty otherwise."""
    R_cp: np.ndarray | None = None
    """In a stream: the camera's rotation since the previous frame from the image motion
    (`solver.frame_motion`), mapping the previous frame's camera coordinates to this frame's; None when
    unknown (the first frame, a single image, too few tracks). Independent of the Manhattan labelling."""
    R_cp_std_rad: float = float("nan")
    """Its std per axis (rad) of the left perturbation `R_cp_true = Exp(eps) R_cp`."""
    cov_steady: np.ndarray | None = None
    """The steady part of `cov` (rad^2, the same perturbation): one error shared by every frame of a stream
    and fixed in the camera, the calibration's (a principal point not given: `focal.unknown_centre_floor`).
    A constant alignment of the stream's rotations removes it where the camera turns little, so a score after
    that alignment holds the rest, `cov_frame()`, the error new in each frame. None: nothing steady."""

    def cov_frame(self) -> np.ndarray:
        """The per-frame part of `cov`: `cov - cov_steady` (rad^2)."""
        return self.cov if self.cov_steady is None else self.cov - self.cov_steady

    def is_finite(self) -> bool:
        """Whether the rotation and its covariance are finite (a frame the backends can fuse)."""
        return bool(np.isfinite(self.R_cm).all() and np.isfinite(self.cov).all())

    def has_image_rotation(self) -> bool:
        """Whether the frame carries a usable image rotation since the previous frame (`R_cp` finite, its
        std finite and > 0)."""
        return (self.R_cp is not None and bool(np.isfinite(self.R_cp).all()) and np.isfinite(self.R_cp_std_rad)
                and self.R_cp_std_rad > 0)

    def symmetric_to(self, R_cm_ref: np.ndarray) -> "VisualRotation":
        """The same measurement expressed with the Manhattan labelling nearest `R_cm_ref`.

        The covariance is rotated with it: `delta' = P^T delta` for `R_cm' = R_cm @ P`.
        """
        R_new, P = nearest_symmetric(self.R_cm, R_cm_ref)
        steady = None if self.cov_steady is None else P.T @ self.cov_steady @ P
        return dataclasses.replace(self, R_cm=R_new, cov=P.T @ self.cov @ P, cov_steady=steady)


class Status(enum.IntFlag):
    """Why an estimate is what it is; several flags may be set at once."""

    OK = 0
    ACCEL_DOWNWEIGHTED = enum.auto()
    """The accelerometer disagreed with gravity and was trusted less."""
    VISUAL_REJECTED = enum.auto()
    """The visual rotation failed the Mahalanobis gate."""
    VISUAL_MISSING = enum.auto()
    """No usable visual rotation for this frame (dropped, blank, no valid normals)."""
    REINITIALISED = enum.auto()
    """The Manhattan frame was re-initialised after persistent disagreement."""
    IMU_GAP = enum.auto()
    """A gap in IMU data longer than the configured limit; the covariance was inflated instead."""
    GYRO_SATURATED = enum.auto()
    """A gyro reading at or above the configured range."""
    IMU_DROPPED = enum.auto()
    """Non-finite or out-of-order IMU samples were dropped."""
    NOT_INITIALISED = enum.auto()
    """The filter has not seen enough data to know its attitude."""
    OPTIMISER_FAILED = enum.auto()
    """A smoother optimisation failed; the window restarted from the last good estimate."""
    DEPTH_MISSING = enum.auto()
    """Depth normals were asked for and this frame has no depth map: it used the remaining cues."""
    UPDATE_NONFINITE = enum.auto()
    """A filter update gave a non-finite correction or covariance and was dropped."""
    VISUAL_JUMP = enum.auto()
    """The frame's own evidence overrode the prior its solve started from (`VisualRotation.jump_deg`)."""
    VISUAL_NO_EVIDENCE = enum.auto()
    """The frame had no usable evidence (black, blank, blurred, or segments that fit no better than
    chance): its visual covariance is the cap
    (`VisualRotation.reason` says why)."""
    VISUAL_IGNORED = enum.auto()
    """The frame's visual rotation disagreed with the filter's prediction beyond what both
    covariances allow (`MekfConfig.disagreement_chi2`, at least `disagreement_min_deg`), so its update
    was rejected or Huber-weighted down to little: the estimate may be drifting from the camera.
    After `MekfConfig.reinit_after_disagreement_s` of it the filter re-initialises (`REINITIALISED`)."""


def visual_R_wc_covariance(visual: VisualRotation) -> np.ndarray:
    """Covariance (rad^2) of the right perturbation of `R_mc = R_cm^T` given `visual.cov` of `R_cm`.

    `(R_cm Exp(d))^T = R_cm^T Exp(-R_cm d)`, so the right error of `R_mc` (and of `R_wc = R_wm R_mc`)
    is `-R_cm d` with covariance `R_cm cov R_cm^T`.
    """
    cov = visual.R_cm @ visual.cov @ visual.R_cm.T
    return 0.5 * (cov + cov.T)


def chained_image_rotation(R_cps) -> np.ndarray | None:
    """The camera's rotation over consecutive frames from their image rotations (`VisualRotation.R_cp` of
    each frame after the first, in order): `R_wc,first^T R_wc,last = prod R_cp^T` (3, 3); None where one
    is missing."""
    chain = np.eye(3)
    for R_cp in R_cps:
        if R_cp is None:
            return None
        chain = chain @ R_cp.T  # R_wc,k = R_wc,k-1 R_cp^T
    return chain


def visual_R_wc_steady(visual: VisualRotation) -> np.ndarray | None:
    """`visual.cov_steady` as one of `R_wc`'s right perturbation (as `visual_R_wc_covariance`), None without."""
    if visual.cov_steady is None:
        return None
    cov = visual.R_cm @ visual.cov_steady @ visual.R_cm.T
    return 0.5 * (cov + cov.T)


def stacked_steady(n: int, steady_at: dict[int, np.ndarray]) -> np.ndarray | None:
    """The steady parts (`Estimate.cov_steady`, rad^2) of `n` estimates as one (n, 3, 3) array, from
    `{index: cov_steady}` of those that have one, NaN elsewhere (as `scoring.metrics.attitude_errors` takes
    them); None when none has one."""
    if not steady_at:
        return None
    out = np.full((n, 3, 3), np.nan)
    for k, cov in steady_at.items():
        out[k] = cov
    return out


def steady_within(cov: np.ndarray, steady: np.ndarray | None) -> np.ndarray | None:
    """`steady` (rad^2) shrunk, direction by direction, until `cov - steady` is positive semi-definite: the
    steady part an estimate of covariance `cov` can carry (a filter's covariance may be smaller than a
    frame's, never its steady error larger than its whole). None for None."""
    if steady is None:
        return None
    val, vec = np.linalg.eigh(0.5 * (cov + cov.T))
    root = vec * np.sqrt(np.maximum(val, 0.0))
    inv = vec * np.divide(1.0, np.sqrt(val), out=np.zeros_like(val), where=val > 0)
    g_val, g_vec = np.linalg.eigh(inv.T @ (0.5 * (steady + steady.T)) @ inv)  # steady in cov's whitened axes
    shrunk = (g_vec * np.clip(g_val, 0.0, 1.0)) @ g_vec.T
    out = root @ shrunk @ root.T
    return 0.5 * (out + out.T)


@dataclass(frozen=True)
class Estimate:
    """A backend's output at time `t_s` (s).

    `R_wc` maps camera coordinates to the world (z up); `cov` (3, 3, rad^2) is the covariance of the
    right perturbation of `R_wc`. `up_c` is world up in the camera frame. `R_wm` is the Manhattan
    frame's attitude in the world and `gyro_bias_rad_s` the estimated gyro bias, when the backend has
    them. `tilt_shares` is `(accelerometer, camera)`: each source's share of the tilt information the
    filter fuses now (`backends/mekf/source_trust.py`; NaN for a source it has not seen), when the
    backend weighs sources.
    """

    t_s: float
    R_wc: np.ndarray
    cov: np.ndarray
    status: Status = Status.OK
    R_wm: np.ndarray | None = None
    gyro_bias_rad_s: np.ndarray | None = None
    tilt_shares: tuple[float, float] | None = None
    cov_steady: np.ndarray | None = None
    """The steady part of `cov` (rad^2, the same perturbation): the error the stream's visual rotations
    share, the calibration's (`VisualRotation.cov_steady`) or what the stream does not show varying
    (`backends.base.SteadyPart`), `steady_within` the estimate's covariance, which no fusion of frames
    averages away; None when there is none."""

    @property
    def up_c(self) -> np.ndarray:
        return up_in_camera(self.R_wc)


@dataclass(frozen=True)
class Estimates:
    """Many `Estimate`s as arrays (an IMU-only run handled in bulk): `t_s` (M,), `R_wc` (M, 3, 3),
    `cov` (M, 3, 3) rad^2, `status` (M,) int (`Status` bits); `R_wm` and `gyro_bias_rad_s` (M, 3, 3)
    and (M, 3), or None when the backend has none (NaN rows where one estimate has none)."""

    t_s: np.ndarray
    R_wc: np.ndarray
    cov: np.ndarray
    status: np.ndarray
    R_wm: np.ndarray | None = None
    gyro_bias_rad_s: np.ndarray | None = None

    def __len__(self) -> int:
        return self.t_s.shape[0]

    def __getitem__(self, k: int) -> Estimate:
        def row(a):
            return None if a is None or not np.isfinite(a[k]).all() else a[k].copy()
        return Estimate(float(self.t_s[k]), self.R_wc[k].copy(), self.cov[k].copy(), Status(int(self.status[k])),
                        row(self.R_wm), row(self.gyro_bias_rad_s))

    @classmethod
    def of(cls, estimates: list[Estimate]) -> "Estimates":
        """The arrays of a list of estimates."""
        def column(values, shape):
            if all(v is None for v in values):
                return None
            return np.array([np.full(shape, np.nan) if v is None else v for v in values], float).reshape(-1, *shape)
        n = len(estimates)
        return cls(np.array([e.t_s for e in estimates], float), np.array([e.R_wc for e in estimates], float).reshape(n, 3, 3),
                   np.array([e.cov for e in estimates], float).reshape(n, 3, 3),
                   np.array([int(e.status) for e in estimates], np.int64),
                   column([e.R_wm for e in estimates], (3, 3)), column([e.gyro_bias_rad_s for e in estimates], (3,)))

    @classmethod
    def concatenate(cls, parts: list["Estimates"]) -> "Estimates":
        if len(parts) == 1:
            return parts[0]
        n = [len(p) for p in parts]

        def column(name, shape):
            values = [getattr(p, name) for p in parts]
            if all(v is None for v in values):
                return None
            return np.concatenate([np.full((k, *shape), np.nan) if v is None else v for v, k in zip(values, n)])
        return cls(np.concatenate([p.t_s for p in parts]), np.concatenate([p.R_wc for p in parts]).reshape(-1, 3, 3),
                   np.concatenate([p.cov for p in parts]).reshape(-1, 3, 3),
                   np.concatenate([p.status for p in parts]).astype(np.int64),
                   column("R_wm", (3, 3)), column("gyro_bias_rad_s", (3,)))

    def without(self, flags: Status) -> "Estimates":
        """The same estimates with `flags` cleared from every status."""
        return Estimates(self.t_s, self.R_wc, self.cov, self.status & ~int(flags), self.R_wm, self.gyro_bias_rad_s)


@dataclass(frozen=True)
class FrameResult:
    """Everything the pipeline knows about one output time. `frame` is None for the estimates of an
    IMU-only source; `normal_map` and `visual` are None when there was no usable image."""

    t_s: float
    estimate: Estimate
    frame: Frame | None = None
    normal_map: NormalMap | None = None
    visual: VisualRotation | None = None
    K: np.ndarray | None = None
    """The intrinsics the visual cues used (given, or estimated from the scene), None if unknown."""
