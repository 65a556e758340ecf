"""The EKF's kernels, the filter's one implementation: numba-compiled when numba is there, the very
same functions as plain Python otherwise (`jit.py`).

The maths live in `kernel_imu` (IMU propagation, gaps and saturation included), `kernel_update`
(Kalman update, injection and reset, accelerometer and zero-rate updates) and `kernel_visual`
(visual update with an IMU and visual only, the disagreement test, the constant-rate prediction) and
`kernel_image_rotation` (the visual-only prediction by the image rotation between frames),
with the models of `measurements`, `source_trust` and `state`. The drivers named here take the
filter's state buffer `x` (`state_buffer.py`) and its parameter record (`parameters.py`) and update
the buffer in place; `compiled.py` calls them for `Mekf`.

numba optimises and generates each compiled function with everything it calls linked in, so each
layer of calls and each extra signature (a C- against an A-layout array, a literal bool) compiles the
code beneath it again: compiling both sets (`filter.load_kernels`) takes about 60 s of one core on a
small machine. The machine code is therefore cached on disk, keyed by the
sources of every module the kernels draw on (`jit.compiled(sources=...)`): an edit anywhere there
compiles them again; nothing is deleted. Should numba fail to compile a kernel at its first call,
`use_python` puts the plain functions back everywhere (one warning line) and the call runs as Python.
"""

from __future__ import annotations

import sys
import types

from ... import jit, rotations
from .. import imu_stream
from . import accel, kernel_image_rotation, kernel_imu, kernel_update, kernel_visual, matrix3, measurements
from . import source_trust, state
from . import state_buffer, status_bits

_MODULES = (kernel_imu, kernel_update, kernel_visual, kernel_image_rotation)
"""The modules whose functions call the others by their global names (rebound to the compiled ones)."""
_HELPERS = (state.reset_jacobian, state.orthonormal, measurements.gravity_model, measurements.zero_rate_model,
            measurements.vertical_model, measurements.correlated_noise_scale, matrix3.inv3, matrix3.exp3_into,
            matrix3.matmul3_into, matrix3.log3_into, accel.chunk_bounds, imu_stream.rows_if_clean,
            source_trust.note_accel_information, source_trust.note_visual_information,
            source_trust.update_visual_trust, source_trust.vertical_variance, source_trust.visual_vertical_innovation,
            source_trust.squared_rate, source_trust.share_tilt_covariance)
_INNER = (kernel_update.state_views,
          kernel_update.matmul_into, kernel_update.solve_into, kernel_update.kalman_update,
          kernel_update.inject_and_reset, kernel_update.accel_rows,
          kernel_imu.chunk_steps, kernel_imu.propagate_chunk,
          kernel_imu.gyro_predict_in_place, kernel_imu.scratch, kernel_imu.integrate_chunks, kernel_imu.carry_lowpass_in_place,
          kernel_visual.visual_model, kernel_visual.visual_rows)
DRIVERS = dict(
    INTEGRATE=kernel_imu.integrate_batch, STAGE=kernel_imu.stage_batch, INTEGRATE_STAGED=kernel_imu.integrate_staged,
    SEGMENTS=kernel_imu.integrate_segments, ACCEL_UPDATE=kernel_update.accel_update_in_place,
    UPDATE=kernel_update.update_in_place, VISUAL_UPDATE=kernel_visual.visual_update,
    VISUAL_DISTANCE=kernel_visual.visual_distance, CONSTANT_RATE=kernel_visual.constant_rate_predict,
    IMAGE_ROTATION=kernel_image_rotation.image_rotation_predict)
"""The drivers by name: `compiled.py` calls `kernels.<NAME>`, compiled or plain."""
_PER_FRAME = {"STAGE", "INTEGRATE_STAGED", "VISUAL_UPDATE", "VISUAL_DISTANCE", "CONSTANT_RATE", "IMAGE_ROTATION"}
"""Drivers of a few microseconds called per frame: they keep the GIL (`jit.compiled(nogil=False)`)."""

INTEGRATE = STAGE = INTEGRATE_STAGED = SEGMENTS = ACCEL_UPDATE = UPDATE = VISUAL_UPDATE = None
VISUAL_DISTANCE = CONSTANT_RATE = IMAGE_ROTATION = None
_compiled = False


def _sources() -> list[str]:
    """The source files the compiled kernels are built from (their cache key)."""
    modules = {sys.modules[f.__module__] for f in (*_HELPERS, *_INNER, *DRIVERS.values())}
    return sorted({m.__file__ for m in modules} | {__file__, rotations.__file__, state_buffer.__file__,
                                                   status_bits.__file__})


def _bind(functions: dict) -> None:
    """Point every kernel module's global name of each original function at `functions[original]`,
    and the drivers of this module at theirs."""
    for module in _MODULES:
        names = vars(module)
        for name, value in list(names.items()):
            original = getattr(value, "py_func", value)
            if isinstance(original, types.FunctionType) and original in functions:
                names[name] = functions[original]
    for name, driver in DRIVERS.items():
        globals()[name] = functions[driver]


def use_python() -> None:
    """The plain-Python functions everywhere from now on (numba missing, or a kernel failed)."""
    global _compiled
    _compiled = False
    _bind({f: f for f in (*_HELPERS, *_INNER, *DRIVERS.values())})


def compiled_now() -> bool:
    """Whether the drivers are numba's (else plain Python)."""
    return _compiled


def _compile() -> None:
    global _compiled
    sources = _sources()
    table = {f: jit.compiled(f, cache=True, error_model="numpy", sources=sources) for f in (*_HELPERS, *_INNER)}
    for name, driver in DRIVERS.items():
        table[driver] = jit.compiled(driver, cache=True, error_model="numpy", nogil=name not in _PER_FRAME,
                                     sources=sources)
    _bind(table)
    _compiled = True


use_python()
if jit.available():
    try:
        _compile()
    except Exception as exc:  # noqa: BLE001 -- the plain functions run instead
        jit.disable(exc)
        use_python()
