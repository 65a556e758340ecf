"""The two motion strategies of `Mekf`, chosen once when its mode is known.

- `GyroMotion` (modes `visual_imu`, `imu_only`): IMU samples are released from the reorder buffer and
  integrated by the kernels (`kernel_imu.integrate_batch`: chunk by chunk, gaps and saturated samples
  included), the accelerometer updates falling due per `accel_update_period_s`.
- `ConstantRateMotion` (mode `visual_only`): the constant-rate model between frames
  (`kernel_visual.constant_rate_predict`); the world is the first Manhattan frame; IMU samples are
  ignored. `image_rotation_motion.ImageRotationMotion` (visual only, `visual_only_image_rotation`) is
  one, predicting the frames that carry the image rotation by it instead.

`measures_motion`: the motion between frames is measured (gyro, image rotation), not modelled (`scene.py`
then fuses a disagreeing frame under the gate instead of coasting past it). `waits_for_frame`: the
prediction to a frame needs the frame's own visual rotation (`propagate_to`'s `visual`), so a prediction
asked before it (`Mekf.predicted_R_cm`) leaves the state where it is (`predicted_R_wc`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ...rotations import R_CM_UPRIGHT, WORLD_UP
from ...types import IMU_COLUMNS as COLUMNS, ImuBatch, VisualRotation, visual_R_wc_covariance
from . import status_bits
from .accel import tilt_direction
from .compiled import constant_rate_predict, integrate
from .config import MekfMode
from .source_trust import note_accel_information
from .state import BG, I3, N_STATE, RATE, TH

_NO_ROWS = np.zeros((0, COLUMNS))


class ConstantRateMotion:
    """Visual only: constant-rate model between frames; the world is the first Manhattan frame
    labelled with its z the axis nearest image up (`R_wm = I`)."""

    uses_imu = False
    estimates_rate = True
    measures_motion = False
    waits_for_frame = False

    def __init__(self, mode: MekfMode = MekfMode.VISUAL_ONLY):
        self.mode = mode
        self.fuses_visual = True

    def propagate_to(self, filt, t_s: float, visual: VisualRotation | None = None) -> None:
        """`R_wc <- R_wc Exp(omega_c dt)` and the covariance prediction, to `t_s` (s) (`visual`, the
        frame's: not used)."""
        if filt.initialised and t_s > filt.t_state:
            self.predict_by_rate(filt, t_s)

    def predict_by_rate(self, filt, t_s: float) -> None:
        """The constant-rate prediction to `t_s` (s), later than the state's time
        (`kernel_visual.constant_rate_predict`)."""
        constant_rate_predict(filt, t_s, filt.config.rate_rw_rad_s2_sqrt_hz**2)

    def has_bias(self, filt) -> bool:
        """Whether the current frame is fused against the visual bias state: never with the rate alone
        (`ImageRotationMotion.has_bias`)."""
        return False

    def visual_noise_scale(self, filt) -> float:
        """The factor on a frame's visual covariance as fused: its independent share (`VisualNoiseShare`;
        1 when that is off)."""
        return filt.noise_share.share if filt.noise_share.enabled else 1.0

    def persistent_cov(self, filt) -> np.ndarray:
        """(3, 3) rad^2 added to the reported covariance: the current frame's persistent error, which the
        filter following the frames carries (`VisualNoiseShare.persistent_cov`)."""
        return filt.noise_share.persistent_cov

    def start_from_visual(self, filt, t_s: float, visual: VisualRotation) -> None:
        """`R_wc` from the first frame's `R_cm` labelled upright; the rate starts at 0."""
        visual = visual.symmetric_to(R_CM_UPRIGHT)
        filt.labelling.start(t_s, visual)
        filt.R_wm = np.eye(3)
        filt.R_wc = visual.R_cm.T
        self._restart(filt, visual)
        filt.t_state = t_s
        filt.initialised = filt.manhattan_initialised = True

    def reinitialise(self, filt, visual: VisualRotation) -> None:
        """A new scene alignment: `R_wc` from `R_cm`, as the track labelled it (`labelling_track.py`), against
        the kept world (= Manhattan) frame."""
        filt.R_wc = filt.R_wm @ visual.R_cm.T
        self._restart(filt, visual)

    def _restart(self, filt, visual: VisualRotation) -> None:
        filt.P = np.zeros((N_STATE, N_STATE))
        filt.P[TH, TH] = visual_R_wc_covariance(visual)
        filt.P[RATE, RATE] = filt.config.rate_initial_std_rad_s**2 * I3
        filt.omega_c = np.zeros(3)
        filt.rejections = 0



class GyroMotion:
    """Gyro-driven: IMU samples propagate the attitude; world z is up from the accelerometer.
    `fuses_visual` False in `imu_only` mode."""

    uses_imu = True
    estimates_rate = False
    measures_motion = True
    waits_for_frame = False

    def __init__(self, mode: MekfMode):
        self.mode = mode
        self.fuses_visual = mode != MekfMode.IMU_ONLY

    def propagate_to(self, filt, t_s: float, visual: VisualRotation | None = None) -> None:
        """Integrate IMU samples up to `t_s` (camera clock, s), then hold the last rate (`visual`, the
        frame's: not used)."""
        rows = filt.stream.release_rows_until(t_s)
        # The common case of a frame after its samples, in one kernel call: what `integrate_pending`
        # does for one batch when nothing else waits, without queueing it first.
        if rows.shape[0] and filt.initialised and filt.imu_is_camera and not filt.pending and not filt.accel.due:
            integrate(filt, rows, max(t_s - float(rows[-1, 0]), 0.0), self.fuses_visual)
            return
        filt.queue(ImuBatch.from_rows(rows))
        self.integrate_pending(filt, extrapolate_to_s=t_s, force_init=True)

    def start_from_visual(self, filt, t_s: float, visual: VisualRotation) -> None:
        """No attitude before the accelerometer gives gravity: the frame waits."""
        filt.flags |= status_bits.VISUAL_MISSING

    def reinitialise(self, filt, visual: VisualRotation) -> None:
        """A new scene alignment: the Manhattan frame re-initialised nearest the old one."""
        filt.initialise_manhattan(visual, R_wm_ref=filt.R_wm)

    # ------------------------------------------------------------------ IMU integration
    def integrate_pending(self, filt, extrapolate_to_s: float | None = None, force_init: bool = False) -> None:
        """Integrate the released samples; with `extrapolate_to_s`, then hold the last gyro rate up
        to that time (a synthetic sample that carries no accelerometer weight)."""
        batches, filt.pending, filt.pending_span_s = filt.pending, [], 0.0
        rows = ImuBatch.concat(batches).rows if batches else _NO_ROWS
        if not filt.imu_is_camera:
            rows = rows_in_camera(rows, filt.R_ci)
        if not filt.initialised:
            if rows.shape[0] == 0:
                return
            rows = self._initialise_from_accel(filt, rows, force_init)
            if not filt.initialised:
                return
        last_t = float(rows[-1, 0]) if rows.shape[0] else filt.t_state
        extra_s = extrapolate_to_s - last_t if extrapolate_to_s is not None and extrapolate_to_s > last_t else 0.0
        if rows.shape[0] == 0 and extra_s == 0.0:
            return
        if filt.accel.due:  # a deferred update that no frame took: apply it before moving on
            filt.accel_update()
        # Propagating to a frame: an update due at its end waits for the frame's visual update (IMU-only
        # there is none: the frame would apply it at once, so it is applied here, in the same order).
        self.integrate_rows(filt, rows, extra_s, extrapolate_to_s is not None and filt.motion.fuses_visual)

    def integrate_rows(self, filt, rows: np.ndarray, extra_s: float, defer: bool) -> None:
        """Integrate camera-frame rows (n, 8) and extrapolate `extra_s` s (`compiled.integrate`); `defer`:
        an update due at the end waits for the frame."""
        integrate(filt, rows, extra_s, defer)

    def _initialise_from_accel(self, filt, rows: np.ndarray, force: bool = False) -> np.ndarray:
        """Tilt from the mean of the first `init_accel_window_s` of accelerometer samples (`rows`
        (n, 8), camera frame, as `ImuBatch.rows`); yaw is the gauge (variance 0). Returns the rows
        still to integrate."""
        cfg = filt.config
        filt.init_samples.append(ImuBatch.from_rows(rows))
        held = ImuBatch.concat(filt.init_samples)
        t_all = held.t_s
        if t_all[-1] - t_all[0] < cfg.init_accel_window_s and not force:
            return rows[:0]
        filt.init_samples = []
        window = t_all <= t_all[0] + cfg.init_accel_window_s
        up_c = tilt_direction(held.accel_m_s2[window].mean(axis=0))
        rot, _ = Rotation.align_vectors(WORLD_UP[None], up_c[None])
        filt.R_wc = rot.as_matrix()
        filt.P = np.zeros((N_STATE, N_STATE))
        filt.P[TH, TH] = cfg.initial_tilt_std_rad**2 * (I3 - np.outer(up_c, up_c))
        filt.P[BG, BG] = cfg.gyro_bias_initial_std_rad_s**2 * I3
        note_accel_information(filt.views["s"], cfg.accel_tilt_noise_rad_sqrt_s**2, 1.0)  # before its first update
        filt.t_state = filt.imu_t_s = float(t_all[0])
        filt.last_gyro_c = held.gyro_rad_s[0]
        filt.initialised = True
        filt.resolve_mode(MekfMode.VISUAL_IMU)
        return held.rows[1:]


def rows_in_camera(rows: np.ndarray, R_ci: np.ndarray) -> np.ndarray:
    """IMU rows (n, 8) (`types.IMU_COLUMNS`) with gyro and accelerometer turned into the camera frame
    (`R_ci` (3, 3) maps IMU to camera): a copy."""
    out = rows.copy()
    out[:, 1:4] = rows[:, 1:4] @ R_ci.T
    out[:, 4:7] = rows[:, 4:7] @ R_ci.T
    return out
