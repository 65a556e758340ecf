"""The camera-IMU rotation `R_ci` estimated from a run's own data, and a warning when it disagrees.

Between two frames the camera turns by `R_{c0 c1} = R_cm(0) R_cm(1)^T` (the solver's rotations,
Manhattan symmetry resolved against the previous frame) and the gyro, integrated over the same
camera-time interval, by `R_{i0 i1}`. The two are the same motion seen in two frames:
`R_{c0 c1} = R_ci R_{i0 i1} R_ci^T`, so their rotation vectors satisfy `phi_c = R_ci (phi_i - b dt)`
with `b` the gyro bias. `estimate_imu_rotation` solves this for `R_ci` by Kabsch
(`Rotation.align_vectors`) alternated with a least-squares bias; a few seconds of motion about two
or more axes make it observable. `ImuRotationCheck` collects the pairs during a run (bounded
memory: at most `MAX_PAIRS`) and reports the estimate for summary.json, with one warning line when
it is far from the `R_ci` the run used, naming the nearest axis convention (`drivers.extrinsics`).
It never lets a run fuse a wrongly rotated gyro silently: every `CHECK_EVERY_PAIRS` pairs or so (from
`REFUSE_MIN_PAIRS` on) it estimates `R_ci`, and once the estimate is observable and further than
`DISAGREEMENT_DEG` from the one used it refuses the rest of the stream (an `InputError`: the run
stops as `input_error`, its outputs so far kept, with the `--imu-rotation` to pass).

Convention: `v_c = R_ci v_i`; IMU stamps plus `SourceInfo.imu_time_offset_s` are camera time.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator

import numpy as np
from scipy.spatial.transform import Rotation

from ..drivers.base import Source
from ..drivers.extrinsics import axis_letters, convention_name
from ..errors import InputError
from ..types import ImuBatch
from .runner import FrameResult

MAX_PAIRS = 3000
"""Frame pairs kept (100 s at 30 fps); later pairs are not needed for a rotation."""
MAX_PAIR_GAP_S = 0.25
"""Frames further apart than this (dropped frames, no visual rotation) make no pair."""
MAX_VISUAL_STEP_DEG = 30.0
"""A larger turn between consecutive frames is a solver jump, not motion: no pair."""
MIN_PAIRS = 10
MAX_UNCERTAINTY_DEG = 5.0
"""`R_ci` is called observable when its standard deviation about the least excited axis,
`residual / sqrt(s2^2 + s3^2)` (s: singular values of the gyro rotation vectors; rotation about
one axis alone leaves `R_ci` free about it), is below this."""
DISAGREEMENT_DEG = 30.0
"""Estimated and used `R_ci` further apart than this: warn, or refuse mid-run."""
REFUSE_MIN_PAIRS = 30
"""Frame pairs (a second at 30 fps) before a disagreement can stop the run."""
CHECK_EVERY_PAIRS = 5
"""During the run `R_ci` is estimated again after each this many new pairs (a tenth of the pairs so
far once that is more: the cost stays a few fits per second of a long run)."""
NEAR_CONVENTION_DEG = 20.0
"""An estimate this close to an axis-letter rotation is named by its letters."""
BIAS_ITERATIONS = 5
OUTLIER_FACTOR = 4.0
"""A pair whose residual is above this many times the median residual is an outlier."""


def estimate_imu_rotation(phi_i: np.ndarray, phi_c: np.ndarray, dt_s: np.ndarray) -> dict:
    """`R_ci` (3, 3) and gyro bias (3,) rad/s from rotation-vector pairs `phi_c ~ R_ci (phi_i - b dt)`,
    with the excitation (deg, singular values of `phi_i`), the RMS residual (deg), the standard
    deviation about the least excited axis (deg) and the pairs kept. Pairs whose residual exceeds
    `OUTLIER_FACTOR` times the median (a visual rotation that jumped) are left out of a second fit."""
    phi_i, phi_c, dt_s = np.asarray(phi_i, float), np.asarray(phi_c, float), np.asarray(dt_s, float)
    keep = np.ones(len(phi_i), bool)
    for _ in range(2):
        rot, bias = _fit(phi_i[keep], phi_c[keep], dt_s[keep])
        residual = np.linalg.norm(phi_c - rot.apply(phi_i - bias * dt_s[:, None]), axis=1)
        keep = residual <= OUTLIER_FACTOR * max(np.median(residual), 1e-9)
    residual_rad = float(np.sqrt(np.mean(residual[keep] ** 2)))
    excitation_rad = np.linalg.svd(phi_i[keep], compute_uv=False)
    weakest = np.hypot(excitation_rad[1], excitation_rad[2])
    return {"R_ci": rot.as_matrix(), "gyro_bias_rad_s": bias, "excitation_deg": np.degrees(excitation_rad),
            "residual_deg_rms": float(np.degrees(residual_rad)), "pairs_kept": int(keep.sum()),
            "uncertainty_deg": float(np.degrees(residual_rad / weakest)) if weakest > 0 else float("inf")}


def _fit(phi_i: np.ndarray, phi_c: np.ndarray, dt_s: np.ndarray) -> tuple[Rotation, np.ndarray]:
    """Kabsch (`align_vectors`) alternated with the least-squares gyro bias."""
    bias = np.zeros(3)
    for _ in range(BIAS_ITERATIONS):
        with warnings.catch_warnings():  # a poorly defined rotation shows in `uncertainty_deg`
            warnings.simplefilter("ignore", UserWarning)
            rot, _ = Rotation.align_vectors(phi_c, phi_i - bias * dt_s[:, None])
        bias = (dt_s[:, None] * (phi_i - rot.inv().apply(phi_c))).sum(0) / np.sum(dt_s**2)
    return rot, bias


class _TappedSource(Source):
    """`source` with every IMU batch also handed to `on_imu` as it passes."""

    def __init__(self, source: Source, on_imu):
        self.source, self.on_imu, self.info = source, on_imu, source.info

    def events(self) -> Iterator:
        for event in self.source.events():
            if isinstance(event, ImuBatch):
                self.on_imu(event)
            yield event

    def sample_frames(self, n: int, limit: int | None = None):
        return self.source.sample_frames(n, limit)

    def ground_truth(self):
        return self.source.ground_truth()

    def close(self) -> None:
        self.source.close()


class ImuRotationCheck:
    """A sink that pairs visual and gyro rotations between frames; see the module docstring.

    `tap(source)` returns the source to run (it feeds the gyro here); `report()` the summary entry;
    `warning()` one line or None."""

    def __init__(self, R_ci_used: np.ndarray, imu_time_offset_s: float = 0.0):
        self.R_ci_used = np.asarray(R_ci_used, float)
        self.offset_s = float(imu_time_offset_s)
        self._imu_t: list[np.ndarray] = []
        self._imu_w: list[np.ndarray] = []
        self._prev: tuple[float, np.ndarray] | None = None
        self.pairs: list[tuple[np.ndarray, np.ndarray, float]] = []
        self.refused: str | None = None
        """The message the run was stopped with (`refuse_if_disagreeing`), None while it was not."""

    @classmethod
    def for_source(cls, source: Source) -> "ImuRotationCheck | None":
        """A check for a source with frames and an IMU, None otherwise."""
        info = source.info
        return cls(info.R_ci, info.imu_time_offset_s) if info.has_frames and info.has_imu else None

    def tap(self, source: Source) -> Source:
        return _TappedSource(source, self.add_imu)

    def add_imu(self, batch: ImuBatch) -> None:
        if len(batch) and len(self.pairs) < MAX_PAIRS:
            self._imu_t.append(np.asarray(batch.t_s, float) + self.offset_s)
            self._imu_w.append(np.asarray(batch.gyro_rad_s, float))

    def write(self, result: FrameResult) -> None:
        if len(self.pairs) >= MAX_PAIRS:
            return
        t, prev = result.t_s, self._prev
        imu_t, imu_w = self._buffered_imu()
        if result.visual is None:
            self._prev = None
        else:
            R_cm = result.visual.R_cm if prev is None else result.visual.symmetric_to(prev[1]).R_cm
            if prev is not None and 0 < t - prev[0] <= MAX_PAIR_GAP_S:
                phi_c = Rotation.from_matrix(prev[1] @ R_cm.T).as_rotvec()
                phi_i = _gyro_rotvec(imu_t, imu_w, prev[0], t)
                if phi_i is not None and np.degrees(np.linalg.norm(phi_c)) < MAX_VISUAL_STEP_DEG:
                    self.pairs.append((phi_i, phi_c, t - prev[0]))
                    self.refuse_if_disagreeing()
            self._prev = (t, R_cm)
        keep = imu_t > t  # memory stays bounded by the samples of one frame interval
        self._imu_t, self._imu_w = [imu_t[keep]], [imu_w[keep]]

    def refuse_if_disagreeing(self) -> None:
        """Now and then from `REFUSE_MIN_PAIRS` pairs on (`CHECK_EVERY_PAIRS`): an `InputError` (the run
        stops) when the data's `R_ci` is observable and disagrees with the one used (`warning`)."""
        n = len(self.pairs)
        if n < REFUSE_MIN_PAIRS or n % max(CHECK_EVERY_PAIRS, n // 10):
            return
        line = self.warning(self.report())
        if line is not None:
            self.refused = (f"{line}. Stopped after {n} frame pairs rather than fuse a gyro in the wrong axes; "
                            "rerun with that --imu-rotation (or the camera-IMU calibration)")
            raise InputError(self.refused)

    def _buffered_imu(self) -> tuple[np.ndarray, np.ndarray]:
        """The gyro samples since the last frame as (t (N,) s on the camera clock, w (N, 3) rad/s)."""
        if not self._imu_t:
            return np.zeros(0), np.zeros((0, 3))
        return np.concatenate(self._imu_t), np.concatenate(self._imu_w)

    def close(self) -> None:
        pass

    def report(self) -> dict:
        """The summary.json entry: the estimate (when the data holds enough motion) and how far it is
        from the `R_ci` the run used."""
        doc = {"pairs": len(self.pairs), "R_ci_used": self.R_ci_used.tolist()}
        if len(self.pairs) < MIN_PAIRS:
            return {**doc, "observable": False, "note": "too few frame pairs with a visual rotation"}
        phi_i, phi_c, dt = (np.array(x) for x in zip(*self.pairs))
        est = estimate_imu_rotation(phi_i, phi_c, dt)
        observable = bool(est["uncertainty_deg"] <= MAX_UNCERTAINTY_DEG)
        letters, off_deg = axis_letters(est["R_ci"])
        to_used_deg = float(np.degrees(Rotation.from_matrix(self.R_ci_used.T @ est["R_ci"]).magnitude()))
        doc.update(observable=observable, R_ci=est["R_ci"].tolist(),
                   quat_xyzw=Rotation.from_matrix(est["R_ci"]).as_quat().tolist(),
                   nearest_axis_letters=letters, nearest_axis_letters_deg=off_deg,
                   angle_to_used_deg=to_used_deg,
                   gyro_bias_rad_s=est["gyro_bias_rad_s"].tolist(), excitation_deg=est["excitation_deg"].tolist(),
                   residual_deg_rms=est["residual_deg_rms"], uncertainty_deg=est["uncertainty_deg"],
                   pairs_kept=est["pairs_kept"])
        if not observable:
            doc["note"] = (f"too little rotation about two or more axes: the estimate's uncertainty is "
                           f"{est['uncertainty_deg']:.1f} deg (> {MAX_UNCERTAINTY_DEG:g})")
        return doc

    def warning(self, report: dict) -> str | None:
        """One line when the data shows a camera-IMU rotation far from the one used, else None."""
        if not report.get("observable") or report["angle_to_used_deg"] <= DISAGREEMENT_DEG:
            return None
        letters = report["nearest_axis_letters"]
        if report["nearest_axis_letters_deg"] <= NEAR_CONVENTION_DEG:
            hint = (f"the IMU axes look like {convention_name(letters)} seen from the camera: "
                    f"try --imu-rotation {letters}")
        else:
            q = ",".join(f"{v:.4f}" for v in report["quat_xyzw"])
            hint = f"estimated from the data: --imu-rotation {q} (quaternion x,y,z,w)"
        return (f"vision and the IMU disagree by {report['angle_to_used_deg']:.0f} deg about the camera-IMU "
                f"rotation; {hint}")


def _gyro_rotvec(t: np.ndarray, w: np.ndarray, t0: float, t1: float) -> np.ndarray | None:
    """Rotation vector of the gyro samples (t (N,) s, w (N, 3) rad/s) integrated over camera time
    (t0, t1] (zero-order hold: each sample holds over the interval before it); None without samples."""
    inside = (t > t0) & (t <= t1)
    if not inside.any():
        return None
    dt = np.diff(np.concatenate([[t0], t[inside]]))
    return _compose_rotvecs(w[inside] * dt[:, None])


def _compose_rotvecs(steps: np.ndarray) -> np.ndarray:
    """Rotation vector of `Exp(steps[0]) Exp(steps[1]) ...` (body-frame increments in time order)."""
    R = np.eye(3)
    for M in Rotation.from_rotvec(steps).as_matrix():
        R = R @ M
    return Rotation.from_matrix(R).as_rotvec()
