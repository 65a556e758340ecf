"""The interface every backend (mekf, smoother, single) implements.

A backend consumes IMU samples and per-frame visual rotations in time order and returns one
`Estimate` per frame. It also predicts `R_cm` for the next frame, which initialises the solver
(paper Sec. 3.2: "the latest frame's rotation initialises the next frame").

Relations used throughout: `R_wc = R_wm @ R_cm^T` and so `R_cm = R_wc^T @ R_wm`.
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod

import numpy as np

from ..types import (Estimate, Estimates, Status, VisualRotation, steady_within, visual_R_wc_covariance,
                     visual_R_wc_steady)
from .stream_steady import StreamVariation, steady_share


class Backend(ABC):
    """Streaming attitude estimator. Calls come in non-decreasing time order."""

    name: str = "backend"

    def process_imu(self, t_s: np.ndarray, gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray) -> None:
        """Feed IMU samples: `t_s` (N,), `gyro_rad_s` (N, 3), `accel_m_s2` (N, 3) in the IMU frame.

        Backends without IMU support ignore them.
        """

    uses_image_motion: bool = False
    """Whether `process_frame` uses the image rotation since the previous frame (`VisualRotation.R_cp`:
    the labelling track, `labelling_track.py`); the pipeline measures it only then (5 ms a frame)."""

    accelerometer_lookahead_s: float = 0.0
    """How far past a frame's time `process_accel` wants samples before the frame, s (a replay feeds them)."""

    def process_accel(self, t_s: np.ndarray, accel_m_s2: np.ndarray) -> None:
        """Feed samples of an accelerometer without gyro: `t_s` (N,) s, `accel_m_s2` (N, 3) m/s^2 in the
        IMU frame (TUM's Kinect). Only the EKF's visual-only model uses them (as gravity); others ignore them."""

    @abstractmethod
    def process_frame(self, t_s: float, visual: VisualRotation | None) -> Estimate:
        """Fuse one frame's visual rotation (None when the frame gave none) and return the estimate
        at `t_s`."""

    @abstractmethod
    def predicted_R_cm(self, t_s: float) -> np.ndarray | None:
        """Best guess of `R_cm` at `t_s` to initialise the solver; None before any estimate."""

    def warm_up(self, has_imu: bool, has_frames: bool) -> None:
        """Load or compile now what the first estimates would otherwise wait for; `has_imu`, `has_frames`:
        whether IMU samples and frames will come. A pipeline calls this before its stream starts, so
        that a live stream's first frames do not stall. Nothing by default."""

    def process_imu_segments(self, t_s: np.ndarray, gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray,
                             ends: np.ndarray) -> Estimates:
        """An IMU-only stream in bulk: samples as in `process_imu`, cut into segments (segment i is
        samples ends[i-1]:ends[i], the first from 0), each fed and followed by a frame without visual
        rotation at its last sample's time; returns those estimates. This is what feeding the
        segments one by one gives; backends may override it with a faster path to the same result."""
        estimates, start = [], 0
        for end in np.asarray(ends, int).tolist():
            self.process_imu(t_s[start:end], gyro_rad_s[start:end], accel_m_s2[start:end])
            estimates.append(self.process_frame(float(t_s[end - 1]), None))
            start = end
        return Estimates.of(estimates)


class SteadyPart:
    """Gives a backend's estimates the steady part of the visual rotations they fuse (`Estimate.cov_steady`):
    every backend fuses the whole covariance (a steady calibration error is no noise to average; its
    share of the estimate is that of the frames in it), and the estimate carries the latest frame's steady
    part as far as its covariance holds it (`steady_within`). A frame's steady part is the larger (by trace)
    of the calibration's (`VisualRotation.cov_steady`) and what the stream does not show varying
    (`stream_steady.steady_share`: the visual rotations carried by the image rotations), the calibration's
    alone before the stream tells or without image rotations. One per stream: `estimate = steady(estimate,
    visual)` after each `process_frame`.

    `from_stream` False: the calibration's alone, for a backend that fuses gravity beside the frames (an
    accelerometer without gyro), whose tilt does not carry the frames' shared error (real TUM fr1 rpy eval,
    learned normals, mekf with the Kinect accelerometer: aligned NEES 4.00 with the calibration's steady
    part, 0.38 with the stream's)."""

    def __init__(self, from_stream: bool = True):
        self.last: np.ndarray | None = None
        """The latest finite frame's steady part as one of `R_wc` (rad^2), None before one with it."""
        self.variation = StreamVariation() if from_stream else None

    def __call__(self, estimate: Estimate, visual: VisualRotation | None) -> Estimate:
        v = None if self.variation is None else self.variation.update(visual)
        if visual is not None and visual.is_finite():
            model = visual_R_wc_steady(visual)
            seen = None if v is None else steady_share(visual_R_wc_covariance(visual), v)
            self.last = model if seen is None or (model is not None and np.trace(model) >= np.trace(seen)) else seen
        if self.last is None or estimate.status & Status.NOT_INITIALISED:
            return estimate
        return dataclasses.replace(estimate, cov_steady=steady_within(estimate.cov, self.last))
