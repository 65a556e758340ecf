"""The one float64 array `x` that holds `Mekf`'s nominal state, covariance and accelerometer period.

Python reads and writes it through attributes (`Mekf.R_wc`, `AccelPeriod.lp_c`, ...: `BufferArray`
gives a view into `x` and copies an assigned value into it, `BufferScalar` a float, int, bool or
None), and the compiled kernels (`kernels.py`) update it in place: a kernel call passes this one
array, and nothing is packed or unpacked between the two paths.

Layout (offsets `X_*`, shapes in `FIELDS`): `s` (S_SIZE,) scalars indexed by `S_*`, `R_wc` (3, 3),
`R_wm` (3, 3), `b_c` (3,) rad/s, `P` (12, 12), `last_gyro` (3,) rad/s (the previous gyro reading,
camera frame), `accel_sum` (3,) m/s, `lp` (2, 3) m/s^2, `lp_J` (2, 3, 3), `rest_sums` (8,), `omega_c`
(3,) rad/s (the visual-only model's rate). Units and
meanings as in `filter.Mekf` and `accel.AccelPeriod`. A scalar that may be absent (`t_state`,
`rest_since_s`, `t_visual_s`) is NaN while it is None.
"""

from __future__ import annotations

import math

import numpy as np

# Scalars in x[X_S]: state time (s), accelerometer period (time covered, time elapsed, s), products
# since the last re-orthonormalisation, low-pass valid (0/1), rest samples and rest start (s), the
# update counters the kernels keep (harvested by `Mekf.counters`), an update due at a frame (0/1), the
# time of the newest integrated IMU sample (s, camera clock; -inf before any); the time of the previous visual update
# (s, camera clock; NaN before any), the consecutive visual rejections, and the visual updates and
# rejections the compiled visual update counts (harvested as the others); the camera-vertical trust
# (`source_trust.py`: running weight, count, mean innovation (3), mean variance, the share, mean square,
# persistent variance, frames seen), each source's tilt information per second (accelerometer, camera),
# the accelerometer's variance rate, and the trust's block moments (the open block's sum (3) and frames,
# the running mean (3) and mean square of the block means, their weight and count); whether frames are
# extrapolated past an IMU gap (0/1) and the IMU gaps the kernels count (harvested as the others).
S_T_STATE, S_ACCEL_TIME, S_ACCEL_ELAPSED, S_PRODUCTS, S_LP_VALID, S_REST_N, S_REST_SINCE = range(7)
S_ACCEL_UPDATES, S_ACCEL_SKIPPED, S_ACCEL_DOWNWEIGHTED, S_REST_UPDATES, S_ACCEL_DUE, S_NONFINITE = range(7, 13)
S_IMU_T, S_T_VISUAL, S_REJECTIONS, S_VISUAL_UPDATES, S_VISUAL_REJECTED = range(13, 18)
S_TRUST_WEIGHT, S_TRUST_COUNT, S_TRUST_MEAN, S_TRUST_VAR, S_VISUAL_SCALE = 18, 19, 20, 23, 24
S_ACCEL_INFO_RATE, S_VISUAL_INFO_RATE, S_TRUST_SQUARE, S_TRUST_PERSISTENT, S_ACCEL_VAR_RATE = 25, 26, 27, 28, 29
S_TRUST_FRAMES, S_BLOCK_SUM, S_BLOCK_N, S_BLOCK_MEAN, S_BLOCK_SQUARE, S_BLOCK_WEIGHT, S_BLOCK_COUNT = 30, 31, 34, 35, 38, 39, 40
S_IN_GAP, S_IMU_GAPS = 41, 42
S_SIZE = 43

FIELDS = (("s", (S_SIZE,)), ("R_wc", (3, 3)), ("R_wm", (3, 3)), ("b_c", (3,)), ("P", (12, 12)),
          ("last_gyro", (3,)), ("accel_sum", (3,)), ("lp", (2, 3)), ("lp_J", (2, 3, 3)), ("rest_sums", (8,)),
          ("omega_c", (3,)))
"""Fields of `x` in order, with their shapes."""
_OFFSETS = np.cumsum([0] + [math.prod(shape) for _, shape in FIELDS]).tolist()
X_S, X_R_WC, X_R_WM, X_B_C, X_P, X_LAST_GYRO, X_ACCEL_SUM, X_LP, X_LP_J, X_REST_SUMS, X_OMEGA_C, X_SIZE = _OFFSETS
"""Where each field of `FIELDS` starts in `x` (Python ints: compile-time constants in the kernels), and its size."""


def new_state_buffer() -> np.ndarray:
    """A fresh `x`: identity rotations, everything else zero, `t_state` and `rest_since_s` None."""
    x = np.zeros(X_SIZE)
    x[X_R_WC:X_R_WM] = x[X_R_WM:X_B_C] = np.eye(3).ravel()
    x[S_T_STATE] = x[S_REST_SINCE] = x[S_T_VISUAL] = np.nan
    x[S_IMU_T] = -np.inf
    x[S_VISUAL_SCALE] = 1.0
    return x


def field_views(x: np.ndarray) -> dict[str, np.ndarray]:
    """{field name: view of `x` with the field's shape}."""
    return {name: x[a:b].reshape(shape) for (name, shape), a, b in zip(FIELDS, _OFFSETS[:-1], _OFFSETS[1:])}


class BufferArray:
    """An attribute kept in the owner's state buffer: reading gives the view (`owner.views[field]`),
    assigning copies the value into it."""

    def __init__(self, field: str):
        self.field = field

    def __get__(self, obj, objtype=None):
        return self if obj is None else obj.views[self.field]

    def __set__(self, obj, value) -> None:
        obj.views[self.field][...] = value


class BufferScalar:
    """A scalar attribute at `x[index]` of the owner's state buffer (`owner.x`), read as `kind`;
    with `optional`, None is stored as NaN and read back as None."""

    def __init__(self, index: int, kind=float, optional: bool = False):
        self.index, self.kind, self.optional = index, kind, optional

    def __get__(self, obj, objtype=None):
        if obj is None:
            return self
        value = obj.x[self.index]
        return None if self.optional and value != value else self.kind(value)

    def __set__(self, obj, value) -> None:
        obj.x[self.index] = np.nan if value is None else value
