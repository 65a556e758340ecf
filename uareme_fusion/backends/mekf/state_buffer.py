"""`Mekf`'s nominal state, covariance and accelerometer period: one record of named fields (`DTYPE`),
held in a one-element structured array `x`.

The compiled kernels (`kernels.py`) take `x` and read and write the record's fields by name in place
(`s = x[0]`, `s.t_state_s`, `s.P`: numba types every field, the nested arrays as C-contiguous views);
as plain Python they get the same memory as a `np.recarray` (`python_state`), whose element reads
fields by attribute too (the compiled ones get the plain array: numba's dispatcher takes about 5 us
longer a call to type a `np.recarray`). Python reads and writes the fields through attributes (`Mekf.R_wc`,
`AccelPeriod.lp_c`, ...: `BufferArray` gives a view of a field and copies an assigned value into it,
`BufferScalar` a float, int, bool or None). Nothing is packed or unpacked between the two paths.

Units and meanings as in `filter.Mekf` and `accel.AccelPeriod`. A scalar that may be absent
(`t_state_s`, `rest_since_s`, `t_visual_s`) is NaN while it is None. Every field is float64 (the
counters and flags too), so that `x.view(np.float64)` is the record as one flat array (`flat_index`).
"""

from __future__ import annotations

import numpy as np

from .state import TH

SCALARS = (
    "t_state_s",  # state time, s
    "accel_time_s", "accel_elapsed_s",  # accelerometer period: time covered, time elapsed, s
    "products",  # rotation products since the last re-orthonormalisation
    "lp_valid",  # the accelerometer low-pass is valid (0/1)
    "rest_n", "rest_since_s",  # rest samples, rest start (s)
    # the update counters the kernels keep (harvested by `Mekf.counters` under these names)
    "accel_updates", "accel_skipped", "accel_downweighted", "rest_updates",
    "accel_due",  # an accelerometer update due at a frame (0/1)
    "nonfinite_updates",  # counter
    "imu_t_s",  # the newest integrated IMU sample, s (camera clock; -inf before any)
    "t_visual_s",  # the previous visual update, s (camera clock; NaN before any)
    "rejections",  # consecutive visual rejections
    "visual_updates", "visual_rejected",  # counters
)
"""The scalar bookkeeping fields, in order."""
TRUST = (  # the camera-vertical trust (`source_trust.py`)
    ("trust_weight", ()), ("trust_count", ()), ("trust_mean", (3,)), ("trust_var", ()),
    ("visual_scale", ()),  # the share
    ("accel_info_rate", ()), ("visual_info_rate", ()),  # each source's tilt information per second
    ("trust_square", ()), ("trust_persistent", ()),
    ("accel_var_rate", ()),  # the accelerometer's variance rate
    ("trust_frames", ()),  # frames seen
    # the block moments: the open block's sum and frames, the running mean and mean square of the
    # block means, their weight and count
    ("block_sum", (3,)), ("block_n", ()), ("block_mean", (3,)), ("block_square", ()), ("block_weight", ()),
    ("block_count", ()),
)
GAPS = (("in_gap", ()),  # frames extrapolated past an IMU gap (0/1)
        ("imu_gaps", ()))  # counter
ARRAYS = (("R_wc", (3, 3)), ("R_wm", (3, 3)), ("b_c", (3,)), ("P", (12, 12)),
          ("last_gyro", (3,)),  # the previous gyro reading, rad/s (camera frame)
          ("accel_sum", (3,)), ("lp", (2, 3)), ("lp_J", (2, 3, 3)), ("rest_sums", (8,)),
          ("omega_c", (3,)))  # the visual-only model's rate, rad/s
"""The array fields, with their shapes, in order (after the scalars)."""
FIELDS = tuple((name, ()) for name in SCALARS) + TRUST + GAPS + ARRAYS
"""Every field of the record in order, with its shape."""
DTYPE = np.dtype([(name, np.float64, shape) for name, shape in FIELDS], align=True)
"""The record's dtype (aligned: numba types it as such)."""


def new_state_buffer() -> np.ndarray:
    """A fresh `x` (1,) `DTYPE`: identity rotations, everything else zero, `t_state_s`, `rest_since_s`
    and `t_visual_s` None, `imu_t_s` -inf, the visual share 1."""
    x = np.zeros(1, DTYPE)
    x["R_wc"] = x["R_wm"] = np.eye(3)
    x["t_state_s"] = x["rest_since_s"] = x["t_visual_s"] = np.nan
    x["imu_t_s"] = -np.inf
    x["visual_scale"] = 1.0
    return x


def python_state(x: np.ndarray) -> np.ndarray:
    """`x` as a `np.recarray` (the same memory), whose element reads and writes fields by attribute as
    the compiled kernels do: what the plain-Python kernels take."""
    return x.view(np.recarray)


def field_views(x: np.ndarray) -> dict[str, np.ndarray]:
    """{array field name: view of `x` with the field's shape}, under "s" the record itself (a
    `np.record` sharing `x`'s memory: fields by attribute, as the kernels read them), and under "flat"
    `x` as one flat float64 array (`flat_index`)."""
    views = {name: x[name][0] for name, _ in ARRAYS}
    views["s"] = python_state(x)[0]
    views["flat"] = x.view(np.float64)
    return views


def flat_index(field: str) -> np.ndarray:
    """Where the elements of `field` lie in `x.view(np.float64)`, in the field's shape."""
    base, offset = DTYPE.fields[field]
    return offset // 8 + np.arange(base.itemsize // 8).reshape(base.shape)


_P_TH = flat_index("P")[TH, TH]
ESTIMATE_INDEX = np.stack([flat_index("R_wc"), flat_index("R_wm"), _P_TH, _P_TH.T, np.tile(flat_index("b_c"), (3, 1))])
"""Where R_wc, R_wm, P[TH, TH], its transpose and b_c (in each row) lie in `x.view(np.float64)`,
(5, 3, 3): one `take` copies them (`Mekf`'s estimate)."""


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
    """A scalar attribute kept in field `field` of the owner's state buffer, read as `kind`; with
    `optional`, None is stored as NaN and read back as None. It reads the owner's flat view of the
    buffer (`owner.views["flat"]`) at the field's place: a `np.record` attribute costs
    about 1.5 us a read, an element of a float array 0.05 us, and Python reads a few per frame."""

    def __init__(self, field: str, kind=float, optional: bool = False):
        self.field, self.kind, self.optional = field, kind, optional
        self.index = int(flat_index(field))

    def __get__(self, obj, objtype=None):
        if obj is None:
            return self
        value = obj.views["flat"][self.index]
        return None if self.optional and value != value else self.kind(value)

    def __set__(self, obj, value) -> None:
        obj.views["flat"][self.index] = np.nan if value is None else value
