"""`Mekf`: the multiplicative (error-state) EKF, scheduling its models.

See docs/design.md "Backends" and the package docstring for the conventions. The filter holds the
nominal state and its covariance in one state buffer (`state_buffer.py`), and schedules: IMU samples
and frames propagate through the motion strategy chosen once for its mode (`motion.py`); a frame's
visual rotation, the vertical pseudo-measurement and a due accelerometer update (or, visual only, the
gravity of an accelerometer without gyro) are fused in one stacked update. The maths run in the
kernels (`kernels.py`, called through `compiled.py`), the filter's one implementation.
"""

from __future__ import annotations

import numpy as np

from ...config import load_config, preset_names
from ...errors import InputError
from ...types import Estimate, Estimates, ImuBatch, VisualRotation
from ..base import Backend
from ..imu_stream import ImuStream, check_imu_arrays
from ..labelling_track import LabellingTrack
from ..visual_noise_share import VisualNoiseShare
from . import status_bits
from .accel import AccelPeriod
from . import kernels
from .compiled import (STAGE_ROWS, accel_update, harvest_kernel_counters, integrate_staged, stage, update,
                       visual_distance, visual_update)
from .config import GyroSampling, MekfConfig, MekfMode
from .gravity_only import GravityOnly
from .image_rotation_motion import ImageRotationMotion
from .motion import ConstantRateMotion, GyroMotion
from .parameters import KernelParameters
from .scene import ignored_too_long, initialise_manhattan
from .segments import process_imu_segments
from .source_trust import tilt_shares
from .status_bits import status_of
from .state import I3
from .state_buffer import ESTIMATE_INDEX, BufferArray, BufferScalar, field_views, new_state_buffer


_CAMERA_ONLY = (float("nan"), 1.0)
"""`Estimate.tilt_shares` without an IMU: the camera alone."""


def _shape(a) -> tuple:
    """`np.shape(a)`, an ndarray's without a numpy call (a frame's checks run between solver calls,
    where each numpy call costs microseconds)."""
    return a.shape if type(a) is np.ndarray else np.shape(a)


def motion_for(mode: MekfMode, image_rotation: bool = False):
    """The motion strategy of a mode; `auto` starts gyro-driven and is resolved once (`Mekf.resolve_mode`).
    Visual only, `image_rotation` (`MekfConfig.visual_only_image_rotation`): frames are predicted by their
    image rotation (`image_rotation_motion.py`)."""
    if mode != MekfMode.VISUAL_ONLY:
        return GyroMotion(mode)
    return ImageRotationMotion() if image_rotation else ConstantRateMotion()


class Mekf(Backend):
    """The multiplicative EKF fusing visual Manhattan rotations with a gyro and accelerometer.

    Feed IMU samples with `process_imu(t_s (N,) s, gyro_rad_s (N, 3), accel_m_s2 (N, 3))` (IMU frame
    and clock) and frames with `process_frame(t_s, VisualRotation or None)`, which returns the
    `Estimate` at `t_s`: `R_wc` (3, 3) camera to a z-up world, `cov` (3, 3) rad^2 of its right
    perturbation, `gyro_bias_rad_s` (3,) in the IMU frame. Counters of what happened are in
    `counters` (e.g. `nonfinite_updates`: updates dropped because their result was not finite,
    flagged `Status.UPDATE_NONFINITE`). The state attributes (`R_wc`, `P`, `b_c`, ...) are live views
    of the filter's one state array (`state_buffer.py`): copy one to keep it; `Estimate`s are copies.

    The mode (`MekfConfig.mode`) fixes the motion strategy: `visual_imu` and `imu_only` integrate
    the gyro, `visual_only` runs a constant-rate model. `auto` resolves once, to `visual_imu` when
    IMU samples arrived before the first frame and to `visual_only` otherwise.

    Example: a camera at rest, upright, seeing a Manhattan frame aligned with the world.

    >>> import numpy as np
    >>> from uareme_fusion.types import VisualRotation
    >>> filt = Mekf(MekfConfig(mode="visual_imu"))
    >>> t = np.arange(1, 201) / 200.0                    # 1 s of IMU at 200 Hz
    >>> filt.process_imu(t, np.zeros((200, 3)), np.tile([0.0, -9.81, 0.0], (200, 1)))
    >>> R_cm = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])   # camera y down = world -z
    >>> visual = VisualRotation(R_cm, 1e-4 * np.eye(3), cost=0.0, iterations=1, n_valid=1000)
    >>> est = filt.process_frame(1.0, visual)
    >>> bool(np.allclose(est.R_wc @ [0, -1, 0], [0, 0, 1], atol=1e-6))   # image up is world up
    True
    >>> est.R_wm is not None, filt.counters["nonfinite_updates"]        # the scene frame is known
    (True, 0)
    """

    name = "mekf"
    # The nominal state, covariance and accelerometer period live in one record of named fields, `x`, which
    # the compiled kernels update in place (`state_buffer.py`); these attributes read and write it.
    R_wc = BufferArray("R_wc")
    R_wm = BufferArray("R_wm")
    b_c = BufferArray("b_c")
    P = BufferArray("P")
    last_gyro_c = BufferArray("last_gyro")
    omega_c = BufferArray("omega_c")  # visual only: the camera's angular rate, rad/s (camera frame)
    t_state = BufferScalar("t_state_s", optional=True)
    imu_t_s = BufferScalar("imu_t_s")  # time of the newest integrated IMU sample (camera clock), s; -inf before any
    products_unnormalised = BufferScalar("products", int)
    t_visual_s = BufferScalar("t_visual_s", optional=True)  # time of the previous visual update (camera clock), s
    rejections = BufferScalar("rejections", int)  # consecutive frames gated out
    in_imu_gap = BufferScalar("in_gap", bool)  # frames are being extrapolated past `imu_gap_limit_s` of no IMU
    accel_info_rate, visual_info_rate = BufferScalar("accel_info_rate"), BufferScalar("visual_info_rate")  # tilt info/s

    def __init__(self, config: MekfConfig | str | None = None):
        """`config`: a `MekfConfig`, a preset name or YAML path (`Mekf("vehicle")`), or None for the defaults."""
        if isinstance(config, str):
            config = load_config(config, MekfConfig)
        elif config is not None and not isinstance(config, MekfConfig):
            raise TypeError(f"Mekf(config): expected a MekfConfig, a preset name ({', '.join(preset_names())}) or a "
                            f"YAML path, got {type(config).__name__}")
        self.config = cfg = config or MekfConfig()
        self.R_ci = np.asarray(cfg.R_ci, float)
        self.imu_is_camera = bool(np.array_equal(self.R_ci, I3))
        self.q_gyro = cfg.gyro_noise_rad_s_sqrt_hz**2
        self.q_bias = cfg.gyro_bias_rw_rad_s2_sqrt_hz**2
        self.q_rate = cfg.gyro_rate_noise_sqrt_s**2
        self.manhattan_walks = bool(cfg.manhattan_yaw_rw_rad_per_sqrt_s or cfg.manhattan_tilt_rw_rad_per_sqrt_s)
        self.trapezoid = cfg.gyro_sampling == GyroSampling.INSTANT
        self._stream = ImuStream(cfg.reorder_window_s, cfg.gyro_range_rad_s)
        self._stage = np.empty((STAGE_ROWS, 8))  # a frame's samples (`process_imu`)
        self._staged = 0  # how many
        self.stage_span_s = cfg.accel_update_period_s + self._stream.reorder_window_s  # a staged batch spans less
        self.x = new_state_buffer()  # R_wc = R_wm = I, b_c = 0, P = 0, t_state None
        self.estimate_out = np.empty((4, 3, 3))  # the estimate after a visual update with an IMU
        self.views = field_views(self.x)
        self.set_motion(motion_for(cfg.mode, cfg.visual_only_image_rotation))
        self._mode_resolved = cfg.mode != MekfMode.AUTO
        self.initialised = False
        self.manhattan_initialised = False
        self._counters = dict(visual_rejected=0, visual_nonfinite=0, visual_ignored=0, reinitialised=0,
                              accel_downweighted=0, accel_skipped=0,
                              imu_gaps=0, imu_ignored=0, visual_updates=0, accel_updates=0,
                              rest_updates=0, nonfinite_updates=0)
        self.flags = status_bits.OK  # `Status` bits gathered since the last estimate (`status_bits.py`)
        self.disagree_since_s: float | None = None  # first frame of the current run of ignored visual rotations, s
        self._disagree_R_cm = None  # visual only: the previous frame of that run (labelled)
        self._disagree_P = None  # the error-state covariance at that frame
        self.pending: list[ImuBatch] = []
        self.pending_span_s = 0.0
        self.init_samples: list[ImuBatch] = []
        self.noise_share = VisualNoiseShare(cfg.visual_noise_share_frames)  # visual only (its `persistent_cov`)
        self.labelling = LabellingTrack()  # visual only: each frame labelled nearest a track of the frames
        self._dropped_reported = 0
        self.accel = AccelPeriod(self.x)
        self.gravity_only = GravityOnly(cfg)  # an accelerometer without gyro (visual only: `process_accel`)
        self.accelerometer_lookahead_s = cfg.accel_only_lookahead_s
        self.record_t: list[np.ndarray] = []
        self.record_R: list[np.ndarray] = []
        self.record_P: list[np.ndarray] = []

    @property
    def counters(self) -> dict[str, int]:
        """What happened so far, by name (updates applied, skipped, rejected, ...); the kernels' counts
        (kept in `x`) are added in when read."""
        harvest_kernel_counters(self.x, self._counters)
        if self.gravity_only.active:
            self._counters.update(self.gravity_only.counts)
        return self._counters

    @property
    def mode(self) -> MekfMode:
        """The filter's mode (`auto` until resolved)."""
        return self.motion.mode

    def resolve_mode(self, mode: MekfMode) -> None:
        """Fix an `auto` filter's mode (once: later calls and explicit modes are left alone)."""
        if not self._mode_resolved:
            self._mode_resolved = True
            self.set_motion(motion_for(mode, self.config.visual_only_image_rotation))

    def set_motion(self, motion) -> None:
        """Use `motion` (a strategy of `motion.py`), with the kernels' parameters that go with it."""
        self.motion = motion
        self.kernel_parameters = KernelParameters(self)
        # Whether a frame's IMU batch may wait in the stage for the frame's one kernel call (`process_imu`).
        self._stages_frames = self.imu_is_camera and motion.uses_imu and motion.fuses_visual

    # ------------------------------------------------------------------ public API
    def process_imu(self, t_s, gyro_rad_s, accel_m_s2) -> None:
        """Feed IMU samples: `t_s` (N,) s on the IMU clock, `gyro_rad_s` (N, 3) rad/s and
        `accel_m_s2` (N, 3) m/s^2 in the IMU frame; see `Backend.process_imu`. Non-finite, duplicate
        and late samples are dropped and counted in `self.stream.counts`."""
        if not self.motion.uses_imu:
            self.counters["imu_ignored"] += int(np.size(t_s))
            return
        if self.config.imu_time_offset_s:
            t_s = np.asarray(t_s, float) + self.config.imu_time_offset_s
        if self._staged:
            self._add_staged()
        if self._stages_frames and self.initialised and not self.pending and not self._stream.held_count:
            t, gyro, accel = check_imu_arrays(t_s, gyro_rad_s, accel_m_s2)
            # A frame's worth, clean, nothing else waiting: checked and copied into the stage in one
            # kernel call, where it waits for the frame's one kernel call (`propagate_to`); any other
            # use of the stream adds it first, as below (a batch this short releases nothing).
            self._staged = stage(self, t, gyro, accel)
            if self._staged:
                return
            t_s, gyro_rad_s, accel_m_s2 = t, gyro, accel  # checked: `ImuStream.add` takes them as they are
        self._add(t_s, gyro_rad_s, accel_m_s2)

    @property
    def uses_image_motion(self) -> bool:
        """Visual only (or not yet known): the labelling track takes the image rotation."""
        return not self._mode_resolved or not self.motion.uses_imu

    def process_accel(self, t_s, accel_m_s2) -> None:
        """Feed accelerometer samples of a sensor without gyro: `t_s` (N,) s on the IMU clock,
        `accel_m_s2` (N, 3) m/s^2 in the IMU frame (`R_ci`). The visual-only model uses them as a
        gravity measurement at each frame (`gravity_only.py`); a gyro-driven mode ignores them."""
        if self._mode_resolved and self.motion.uses_imu:
            self.counters["imu_ignored"] += int(np.size(t_s))
            return
        self.gravity_only.add(t_s, accel_m_s2)

    def _gravity_rows(self):
        """Visual only, with an accelerometer without gyro: its gravity rows `(residual, R, H)` at the
        state time, or None (`gravity_only.py`: the first makes the world gravity-aligned)."""
        if self.motion.uses_imu or not self.initialised or not self.gravity_only.active:
            return None
        rows, bits = self.gravity_only.update_rows(self)
        self.flags |= bits
        return rows

    def _gravity_update(self) -> None:
        """`_gravity_rows` alone, for a frame without a visual update."""
        rows = self._gravity_rows()
        if rows is not None:
            update(self, *rows)

    def _add(self, t_s, gyro_rad_s, accel_m_s2) -> None:
        """`process_imu`'s samples into the reorder buffer, released once they span an update period."""
        stream = self._stream
        stream.add(t_s, gyro_rad_s, accel_m_s2)
        dropped = stream.counts.dropped  # only `add` drops samples: flagged here, not per estimate
        if dropped > self._dropped_reported:
            self.flags |= status_bits.IMU_DROPPED
            self._dropped_reported = dropped
        self._release_if_period_held()

    def _release_if_period_held(self) -> None:
        """After samples were added: samples wait in the reorder buffer; a frame's `propagate_to` releases
        them, or, in an IMU-only stream, this does once an accelerometer period's worth is older than the
        window (and integrates them)."""
        stream = self._stream
        if stream.held_span_s + self.pending_span_s >= self.config.accel_update_period_s + stream.reorder_window_s:
            self.queue(stream.release_until(stream.newest_s - stream.reorder_window_s, move_watermark=False))
            if self.pending_span_s >= self.config.accel_update_period_s:
                self.motion.integrate_pending(self)

    def _add_staged(self) -> None:
        """The batch staged for the next frame (clean: see `process_imu`) into the reorder buffer."""
        rows, self._staged = self._stage[:self._staged], 0
        self._stream.add_checked_rows(rows)  # checked when staged, against an empty buffer: none dropped
        self._release_if_period_held()

    @property
    def stream(self) -> ImuStream:
        """The IMU reorder buffer, with the batch `process_imu` may stage for the next frame added first."""
        if self._staged:
            self._add_staged()
        return self._stream

    def flush(self) -> None:
        """Release and integrate every buffered IMU sample (end of an IMU-only stream)."""
        if not self.motion.uses_imu:
            return
        self.queue(self.stream.flush())
        self.motion.integrate_pending(self, force_init=True)
        if self.accel.due:
            self.accel_update()

    def warm_up(self, has_imu: bool, has_frames: bool) -> None:
        """`Backend.warm_up`: load the compiled kernels of the stream to come (`load_kernels`)."""
        if has_imu and self.motion.uses_imu:
            load_kernels(has_frames)

    def process_imu_segments(self, t_s, gyro_rad_s, accel_m_s2, ends) -> Estimates:
        """`Backend.process_imu_segments` (an IMU-only stream in bulk), with clean stretches of the
        stream in one kernel call (`segments.py`)."""
        return process_imu_segments(self, t_s, gyro_rad_s, accel_m_s2, ends)

    def process_frame(self, t_s: float, visual: VisualRotation | None) -> Estimate:
        """Propagate to `t_s` (s, camera clock), fuse `visual` (None for a dropped frame) and return
        the estimate. `Estimate.R_wc` maps camera to world (z up); `cov` (3, 3, rad^2) is that of
        the right perturbation of `R_wc`; `gyro_bias_rad_s` is in the IMU frame; `R_wm` is None
        until a Manhattan frame was seen."""
        t_s = float(t_s)
        if visual is not None and not (_shape(visual.R_cm) == _shape(visual.cov) == (3, 3)):
            raise InputError(f"visual rotation at t = {t_s:g} s: expected R_cm and cov of shape (3, 3), got "
                             f"{np.shape(visual.R_cm)} and {np.shape(visual.cov)}")
        if not self._mode_resolved:
            seen_imu = self.initialised or self.pending or self.stream.newest_s > -np.inf or self.init_samples
            self.resolve_mode(MekfMode.VISUAL_IMU if seen_imu else MekfMode.VISUAL_ONLY)
        self.propagate_to(t_s, visual)
        if visual is not None and self.initialised and not self.motion.uses_imu:
            visual = self.labelling.label(t_s, visual)  # `labelling_track.py`: not nearest a prediction that may drift
        fuses_visual = self.motion.fuses_visual
        if visual is not None and self.manhattan_initialised and fuses_visual:
            ignored = self._ignored_too_long(t_s, visual)
            if ignored is None:
                return self._compiled_estimate(t_s) if self._fuse_visual(visual) else self._estimate(t_s)
            if ignored:  # else skipped (visual only): the filter coasts
                if not self.motion.uses_imu:
                    self.labelling.start(t_s, visual)
                self._reinitialise(visual)
                self.t_visual_s = t_s
            if self.accel.due:
                self.accel_update()
            self._gravity_update()
            return self._estimate(t_s)
        if self.accel.due:
            self.accel_update()
        self._gravity_update()
        if visual is None or not fuses_visual:
            if fuses_visual:
                self.flags |= status_bits.VISUAL_MISSING
                self.visual_info_rate = 0.0  # no share while the camera gives nothing
        elif not visual.is_finite():  # never a start
            self.flags |= status_bits.VISUAL_REJECTED
            self.counters["visual_rejected"] += 1
            self.counters["visual_nonfinite"] += 1
        elif not self.initialised:
            self.motion.start_from_visual(self, t_s, visual)
            self._gravity_update()  # (visual only) the first frame's world is gravity's
        elif not self.initialise_manhattan(visual):
            self._count_rejection()
        return self._estimate(t_s)

    def predicted_R_cm(self, t_s: float) -> np.ndarray | None:
        """`R_cm = R_wc^T R_wm` (3, 3) predicted at `t_s` (s; propagates the filter there); None
        before a Manhattan frame is known."""
        if not self.manhattan_initialised:
            return None
        if self.motion.waits_for_frame:  # predicted by the frame's own image rotation, when the frame comes
            return self.motion.predicted_R_wc(self, float(t_s)).T @ self.R_wm
        self.propagate_to(float(t_s))
        return self.R_wc.T @ self.R_wm

    def propagate_to(self, t_s: float, visual: VisualRotation | None = None) -> None:
        """Propagate the state to `t_s` (s, camera clock) with the mode's motion strategy (`visual`: the
        frame's visual rotation, for a motion that predicts by its image rotation)."""
        if self._staged:
            # A frame's batch, staged by `process_imu`: integrated in one kernel call (with a sample past
            # the frame, or an update waiting, the stream takes it).
            if integrate_staged(self, self._staged, t_s):
                self._staged = 0
                return
            self._add_staged()
        elif not self.pending and t_s == self.t_state and (visual is None or not self.motion.waits_for_frame):
            return  # already there (a frame's prediction, then its update); later stamps are late
        self.motion.propagate_to(self, t_s, visual)

    def imu_trajectory(self) -> tuple[np.ndarray, np.ndarray]:
        """`(t_s (N,), R_wc (N, 3, 3))` after every integrated IMU sample (camera clock), before the
        accelerometer update that may follow it; needs `record_imu_estimates`."""
        if not self.record_t:
            return np.zeros(0), np.zeros((0, 3, 3))
        return np.concatenate(self.record_t), np.concatenate(self.record_R)

    def imu_trajectory_cov(self) -> np.ndarray:
        """(N, 3, 3) covariance (rad^2, right perturbation of `R_wc`) beside each `imu_trajectory`
        rotation: the one predicted to the end of the chunk that sample was integrated in."""
        return np.concatenate(self.record_P) if self.record_P else np.zeros((0, 3, 3))

    def estimate(self, t_s: float | None = None) -> Estimate:
        """Current estimate (at the state time, or stamped `t_s` s) without consuming status flags."""
        return self._make_estimate(self.t_state if t_s is None else t_s, self.flags)

    # ------------------------------------------------------------------ scheduling helpers
    def queue(self, batch: ImuBatch) -> None:
        """Hold released IMU samples until the motion strategy integrates them."""
        rows = batch.rows
        if rows.shape[0]:
            self.pending.append(batch)
            self.pending_span_s = float(rows[-1, 0] - self.pending[0].rows[0, 0]) + 1e-12

    # ------------------------------------------------------------------ updates
    def accel_update(self) -> None:
        """Apply the accelerometer (and zero-rate) update of the period just completed."""
        accel_update(self)

    def _fuse_visual(self, visual: VisualRotation) -> bool:
        """A frame's visual update in one kernel call (`compiled.visual_update`): with an IMU, a due accelerometer
        update stacked in; visual only, the gravity rows of an accelerometer without gyro (`_gravity_rows`) stacked
        in and the covariance cut to its independent share (`VisualNoiseShare`). Re-initialises after
        `reinit_after_rejections` frames gated out. True when the kernel's estimate (`estimate_out`) is the frame's."""
        if self.motion.uses_imu:
            rejected = visual_update(self, visual)
        else:
            rows, shared = self._gravity_rows(), self.noise_share.enabled
            scale, t_previous_s = self.motion.visual_noise_scale(self), self.t_visual_s
            rejected = visual_update(self, visual, scale, rows)
            if not rejected and shared:
                self.noise_share.take(self.t_state, visual)  # labelled by the track (`labelling_track.py`)
            if not rejected and self.gravity_only.active:
                self.gravity_only.note_visual_information(self, visual, scale, t_previous_s)
        if rejected and not visual.is_finite():  # gated out, counted, and no sign of a new scene alignment
            self._count_nonfinite()
        if not rejected or self.rejections < self.config.reinit_after_rejections:
            return self.motion.uses_imu
        self._reinitialise(visual)
        return False

    def _ignored_too_long(self, t_s: float, visual: VisualRotation) -> bool | None:
        """`scene.ignored_too_long`: whether to re-initialise from `visual` (True), fuse it (None) or,
        visual only, skip it (False)."""
        return ignored_too_long(self, t_s, visual)

    def visual_distance(self, visual: VisualRotation, P: np.ndarray) -> tuple[float, float]:
        """`(angle rad, d2)` of a frame's rotation against the prediction under the error covariance
        `P` (12, 12) (`kernel_visual.visual_distance`; labelled nearest the prediction with an IMU)."""
        return visual_distance(self, visual, P, self.motion.uses_imu)

    def _reinitialise(self, visual: VisualRotation) -> None:
        """After `reinit_after_rejections` frames gated out in a row, or `reinit_after_disagreement_s`
        of visual rotations ignored (`_ignored_too_long`): a new scene alignment from `visual`."""
        self.disagree_since_s = self._disagree_R_cm = None
        self.flags |= status_bits.REINITIALISED
        self.counters["reinitialised"] += 1
        self.motion.reinitialise(self, visual)

    def _count_nonfinite(self) -> None:
        """A gated-out frame whose rotation or covariance is not finite: counted apart
        (`visual_nonfinite`), and not a disagreement that leads to a re-initialisation."""
        self.counters["visual_nonfinite"] += 1
        self.rejections -= 1

    def _count_rejection(self) -> None:
        self.flags |= status_bits.VISUAL_REJECTED
        self.counters["visual_rejected"] += 1
        self.rejections += 1

    # ------------------------------------------------------------------ initialisation
    def initialise_manhattan(self, visual: VisualRotation, R_wm_ref: np.ndarray | None = None) -> bool:
        """`scene.initialise_manhattan`: `R_wm = R_wc R_cm`, labelled nearest `R_wm_ref`; False when the
        first frame with an IMU contradicts the accelerometer's tilt."""
        return initialise_manhattan(self, visual, R_wm_ref)

    # ------------------------------------------------------------------ output
    def _estimate(self, t_s: float) -> Estimate:
        est = self._make_estimate(t_s, self.flags)
        self.flags = status_bits.OK
        return est

    def _compiled_estimate(self, t_s: float) -> Estimate:
        """`_estimate` from what the compiled visual update wrote (`estimate_out`): one copy, no arithmetic."""
        R_wc, cov, R_wm, b_c = self.estimate_out.copy()
        bits, self.flags = self.flags, status_bits.OK
        shares = tilt_shares(self.accel_info_rate, self.visual_info_rate)
        return Estimate(t_s, R_wc, cov, status_of(bits), R_wm, self._bias_in_imu(b_c[0]), shares)

    def _bias_in_imu(self, b_c: np.ndarray) -> np.ndarray:
        """The gyro bias `b_c` (3,) rad/s (camera frame, a copy) in the IMU frame."""
        return b_c if self.imu_is_camera else self.R_ci.T @ b_c

    def _make_estimate(self, t_s, bits: int) -> Estimate:
        """The estimate of the state now, stamped `t_s`, with the `Status` of the flag `bits`."""
        if not self.initialised:
            return Estimate(t_s, np.eye(3), np.eye(3), status_of(bits | status_bits.NOT_INITIALISED))
        # The fewest Python steps (a frame's estimate runs between solver calls, where each costs about
        # a microsecond, and a numba call more): one gather copies R_wc, R_wm, P[TH, TH], its transpose, b_c.
        R_wc, R_wm, P_th, P_th_T, b_c = self.views["flat"].take(ESTIMATE_INDEX)
        cov = P_th + P_th_T  # into a new array: in place, numpy would check two views of one array for overlap
        cov *= 0.5
        if not self.motion.uses_imu:
            cov += self.motion.persistent_cov(self)
        bias_i = self._bias_in_imu(b_c[0]) if self.motion.uses_imu else None
        shares = (tilt_shares(self.accel_info_rate, self.visual_info_rate)
                  if self.motion.uses_imu or self.gravity_only.active else _CAMERA_ONLY)
        return Estimate(t_s, R_wc, cov, status_of(bits), R_wm if self.manhattan_initialised else None, bias_i, shares)


_KERNELS_LOADED: set = set()  # which of `load_kernels`' two sets this process has loaded


def load_kernels(with_frames: bool = True) -> None:
    """Have numba load (from its disk cache) or compile every kernel a filter with an IMU calls, with
    frames or IMU-only in bulk (`with_frames` False), by running a scratch filter through them (one or
    two seconds at rest), once per process. numba loads a kernel at its first call (about 0.4 s for
    the fused ones here), which would otherwise stall a live stream's first frames."""
    if with_frames in _KERNELS_LOADED or not kernels.compiled_now():
        return
    t_imu = np.arange(1, 401) / 200.0
    gyro, accel = np.zeros((t_imu.size, 3)), np.tile([0.0, -9.81, 0.0], (t_imu.size, 1))
    if with_frames:
        filt = Mekf(MekfConfig(mode="visual_imu"))
        R_cm = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
        visual = VisualRotation(R_cm, 1e-4 * np.eye(3), cost=0.0, iterations=1, n_valid=1000)
        for k, t_frame in enumerate(np.arange(1, 60) / 30.0):
            batch = (t_imu > t_frame - 1 / 30.0) & (t_imu <= t_frame)
            filt.process_imu(t_imu[batch], gyro[batch], accel[batch])
            filt.process_frame(t_frame, visual if k % 5 else None)
    else:
        filt = Mekf(MekfConfig(mode="imu_only"))
        for half in (slice(0, 200), slice(200, 400)):  # the first initialises the filter
            filt.process_imu_segments(t_imu[half], gyro[half], accel[half], np.arange(10, 201, 10))
    _KERNELS_LOADED.add(with_frames)
