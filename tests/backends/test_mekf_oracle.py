"""The EKF's kernels (the production filter) against the oracle (`mekf_oracle`: the numpy/scipy/filterpy
reference filter, in the tests only): same estimates on seeded simulated streams, with frames, with bad
samples, gaps and saturation, R_ci not identity, a time offset, visual only; the same functions as
plain Python without numba or after a kernel failed to compile; the cache keyed by the sources."""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest

from uareme_fusion import jit
from uareme_fusion.backends.mekf import Mekf, MekfConfig, kernel_update, kernels, state, state_buffer
from uareme_fusion.config import load_config
from uareme_fusion.rotations import angle_between, exp_so3
from uareme_fusion.sim.imu import simulate_imu
from uareme_fusion.sim.trajectory import make_trajectory
from uareme_fusion.types import Status, VisualRotation

from mekf_oracle import OracleMekf  # tests/backends/mekf_oracle: pytest puts tests/backends on sys.path

needs_numba = pytest.mark.skipif(not kernels.compiled_now(),
                                 reason="numba not installed: the plain-Python kernels are too slow for these streams")


def fresh_python(code: str, timeout_s: float) -> subprocess.CompletedProcess:
    """`code` run in a new interpreter (numba loads a kernel at its first call, once per process),
    which must exit 0; its output."""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout_s)
    assert out.returncode == 0, out.stderr
    return out


def stream(seed: int, duration_s: float = 30.0, rate_hz: float = 200.0):
    traj = make_trajectory("walk", duration_s=duration_s, seed=seed)
    t, gyro, accel = simulate_imu(traj, rate_hz=rate_hz, seed=seed + 1)
    return traj, t, gyro + np.array([0.01, -0.02, 0.015]), accel  # a gyro bias to estimate


def run(make, t, gyro, accel, step: int, frames=None):
    """Feed `step` samples per call (a frame after each call when `frames` gives R_cm(t)) to the filter
    `make()`; returns the filter and its estimates."""
    filt = make()
    ests = []
    for i in range(0, t.size, step):
        filt.process_imu(t[i:i + step], gyro[i:i + step], accel[i:i + step])
        if frames is not None and i + step < t.size:
            t_f = float(t[min(i + step, t.size) - 1]) + 0.001
            ests.append(filt.process_frame(t_f, frames(t_f, filt)))
    filt.flush()
    return filt, ests


def assert_same_filters(a: Mekf, b: Mekf, ests_a=(), ests_b=()):
    assert np.degrees(angle_between(a.R_wc, b.R_wc)) < 1e-9 * 180 / np.pi
    np.testing.assert_allclose(a.P, b.P, rtol=1e-7, atol=1e-15)
    np.testing.assert_allclose(a.b_c, b.b_c, atol=1e-10)
    assert a.counters == b.counters
    assert a.stream.counts == b.stream.counts
    if a.config.record_imu_estimates:
        (ta, Ra), (tb, Rb) = a.imu_trajectory(), b.imu_trajectory()
        np.testing.assert_array_equal(ta, tb)
        assert angle_between(Ra, Rb).max() < 1e-9
        np.testing.assert_allclose(a.imu_trajectory_cov(), b.imu_trajectory_cov(), rtol=1e-7, atol=1e-15)
    for ea, eb in zip(ests_a, ests_b):
        assert ea.status == eb.status
        assert angle_between(ea.R_wc, eb.R_wc) < 1e-9
        np.testing.assert_allclose(ea.cov, eb.cov, rtol=1e-6, atol=1e-15)


def both(config: MekfConfig):
    """The production filter and the oracle, as makers for `run`."""
    return (lambda: Mekf(config)), (lambda: OracleMekf(config))


@needs_numba
def test_both_paths_re_orthonormalise_after_the_same_products():
    """After every call both paths count the same products since their last re-orthonormalisation,
    the count wraps before `ORTHONORMALISE_EVERY` (it has wrapped many times here) and R_wc stays
    orthonormal to rounding."""
    _, t, gyro, accel = stream(0, duration_s=5.0)
    compiled, reference = (make() for make in both(load_config("imu_only", MekfConfig)))
    counts = []
    for i in range(0, t.size, 7):
        for filt in (compiled, reference):
            filt.process_imu(t[i:i + 7], gyro[i:i + 7], accel[i:i + 7])
        assert compiled.products_unnormalised == reference.products_unnormalised, i
        counts.append(compiled.products_unnormalised)
    assert max(counts) == state.ORTHONORMALISE_EVERY - 1 and counts.count(0) > 5
    assert np.abs(compiled.R_wc.T @ compiled.R_wc - np.eye(3)).max() < 1e-12


@needs_numba
@pytest.mark.parametrize("step", [1, 7, 10_000])
def test_imu_only_preset_same_estimates_in_any_batch_size(step):
    _, t, gyro, accel = stream(0)
    cfg = load_config("imu_only", MekfConfig).model_copy(update={"record_imu_estimates": True})
    (a, _), (b, _) = (run(c, t, gyro, accel, step) for c in both(cfg))
    assert a.counters["rest_updates"] + a.counters["accel_updates"] > 100
    assert_same_filters(a, b)


@needs_numba
@pytest.mark.parametrize("preset", ["handheld", "vehicle"])
def test_fused_with_frames_same_estimates(preset):
    traj, t, gyro, accel = stream(1, duration_s=12.0)
    rng = np.random.default_rng(5)
    deltas = rng.normal(scale=0.01, size=(2000, 3))
    cov = 1e-4 * np.eye(3)

    def frames(t_f, filt):  # the same draws for both filters
        k = int(t_f * 1000) % 2000
        R_cm = traj.sample(np.array([t_f])).R_wc[0].T @ traj.R_wm(np.array([t_f]))[0] @ exp_so3(deltas[k])
        return VisualRotation(R_cm=R_cm, cov=cov, cost=0.01, iterations=3, n_valid=100)

    (a, ea), (b, eb) = (run(c, t, gyro, accel, 7, frames) for c in both(load_config(preset, MekfConfig)))
    assert a.counters["visual_updates"] > 100
    assert_same_filters(a, b, ea, eb)


@needs_numba
@pytest.mark.parametrize("update", [{}, {"visual_error_correlation_s": 0.3, "manhattan_vertical_max_rad": 0.002},
                                    {"gyro_bias_visual_correlation_s": 0.3}])
def test_compiled_visual_update_gates_weighs_and_reinitialises_as_the_reference(update):
    """The frame's compiled visual update (`kernels.visual_update`) against the reference
    (`Mekf._visual_update`, numpy/scipy/filterpy): rotations relabelled by random cube symmetries,
    frames with twice the noise their covariance claims (Huber-weighted), lone outliers (gated out),
    a run of 10 outliers (re-initialisation), a NaN covariance (gated out); with and without
    correlated-error scaling, the gyro bias's partial update and the vertical pseudo-measurement. Same
    estimates, counts and flags."""
    from uareme_fusion.rotations import manhattan_symmetries

    traj, t, gyro, accel = stream(7, duration_s=12.0)
    rng = np.random.default_rng(11)
    n_frames = t.size // 7
    deltas = rng.normal(scale=0.01, size=(n_frames, 3))
    deltas[rng.random(n_frames) < 0.2] *= 2.0  # beyond what the covariance says: Huber-weighted
    deltas[rng.random(n_frames) < 0.05] = [0.0, 0.5, 0.0]  # lone outliers: gated out
    deltas[250:260] = [0.4, 0.0, 0.3]  # ten in a row: re-initialised
    labels = rng.integers(0, 24, size=n_frames)
    symmetries = manhattan_symmetries()

    def frames(t_f, filt):  # the same draws for both filters
        k = min(int(round(t_f * 200.0)) // 7, n_frames - 1)
        R_cm = traj.sample(np.array([t_f])).R_wc[0].T @ traj.R_wm(np.array([t_f]))[0] @ exp_so3(deltas[k])
        cov = np.full((3, 3), np.nan) if k == 200 else 1e-4 * np.eye(3)
        return VisualRotation(R_cm=R_cm @ symmetries[labels[k]], cov=cov, cost=0.01, iterations=3, n_valid=100)

    cfg = load_config("handheld", MekfConfig).model_copy(update=update)
    (a, ea), (b, eb) = (run(c, t, gyro, accel, 7, frames) for c in both(cfg))
    assert a.counters["visual_updates"] > 250 and a.counters["visual_rejected"] > 20
    assert a.counters["reinitialised"] >= 1
    assert sum(bool(e.status & Status.VISUAL_REJECTED) for e in ea) == a.counters["visual_rejected"]
    assert_same_filters(a, b, ea, eb)


@needs_numba
def test_accelerometer_rows_stacked_into_visual_updates_same_with_rest_updates():
    """A camera held still in front of a scene: the accelerometer rows that compiled visual updates
    stack (`kernels.visual_update`, `kernels.accel_rows`) apply the at-rest update first and give the
    reference's estimates, counts and flags; each estimate owns its arrays."""
    traj, t, gyro, accel = stream(4, duration_s=8.0)
    still = np.zeros_like(gyro) + np.array([0.01, -0.02, 0.015])  # only the bias the filter should learn
    accel_still = np.tile(accel[0], (t.size, 1))
    R_cm = traj.sample(t[:1]).R_wc[0].T @ traj.R_wm(t[:1])[0]

    def frames(t_f, filt):
        return VisualRotation(R_cm=R_cm, cov=1e-4 * np.eye(3), cost=0.01, iterations=3, n_valid=100)

    cfg = load_config("handheld", MekfConfig).model_copy(update={"rest_gyro_max_rad_s": 0.05,
                                                                 "rest_min_duration_s": 0.5})
    (a, ea), (b, eb) = (run(c, t, still, accel_still, 7, frames) for c in both(cfg))
    assert a.counters["rest_updates"] > 20 and a.counters["visual_updates"] > 100
    assert_same_filters(a, b, ea, eb)
    est = ea[-1]
    est.R_wc[0, 0] = est.gyro_bias_rad_s[0] = np.nan  # a copy: the filter and the other fields keep theirs
    assert np.isfinite(a.R_wc).all() and np.isfinite(a.b_c).all() and np.isfinite(est.R_wm).all()


@needs_numba
def test_bad_samples_gaps_and_saturation_same_estimates_counts_and_flags():
    _, t, gyro, accel = stream(2, duration_s=20.0)
    gyro, accel, t = gyro.copy(), accel.copy(), t.copy()
    gyro[100:103] = np.nan
    accel[500, 1] = np.inf
    t[900] = np.nan
    gyro[1500:1504, 2] = 40.0  # beyond the 34.9 rad/s range: saturated
    keep = np.ones(t.size, bool)
    keep[2000:2100] = False  # a 0.5 s gap
    t, gyro, accel = t[keep], gyro[keep], accel[keep]
    cfg = load_config("imu_only", MekfConfig).model_copy(update={"record_imu_estimates": True})
    results = []
    for make in both(cfg):
        filt = make()
        flags = Status.OK
        for i in range(0, t.size, 20):
            filt.process_imu(t[i:i + 20], gyro[i:i + 20], accel[i:i + 20])
            flags |= filt.process_frame(float(np.nanmax(t[i:i + 20])) + 1e-4, None).status
        filt.flush()
        results.append((filt, flags))
    (a, fa), (b, fb) = results
    assert a.stream.counts.nonfinite == 5 and a.stream.counts.saturated == 4
    assert a.counters["imu_gaps"] == 1
    assert fa & Status.IMU_GAP and fa & Status.GYRO_SATURATED and fa & Status.IMU_DROPPED
    assert fa == fb
    assert_same_filters(a, b)


def test_without_numba_the_plain_python_kernels_run_after_one_warning_line():
    code = ("import sys, warnings; sys.modules['numba'] = None\n"
            "warnings.simplefilter('always')\n"
            "import numpy as np\n"
            "from uareme_fusion.backends.mekf import Mekf, MekfConfig\n"
            "from uareme_fusion.solver import normal_moments\n"
            "f = Mekf(MekfConfig(mode='imu_only')); t = np.arange(0, 1, 0.005)\n"
            "f.process_imu(t, np.zeros((t.size, 3)), np.tile([0, 0, 9.81], (t.size, 1))); f.flush()\n"
            "m = normal_moments(np.ones((4, 3)))\n"
            "print(f.counters['accel_updates'], m.n_valid)\n")
    out = fresh_python(code, timeout_s=120)
    assert out.stdout.split() == ["24", "4"]
    warnings = [line for line in out.stderr.splitlines() if "compiled kernels unavailable" in line]
    assert len(warnings) == 1



@needs_numba
def test_frame_batch_held_for_its_frame_is_a_copy_and_counted_when_read():
    """`process_imu` holds a frame's batch for the frame's single compiled call: the caller may reuse
    its arrays at once, and the stream's counts are current whenever they are read."""
    traj, t, gyro, accel = stream(3, duration_s=6.0)
    gyro = gyro.copy()
    gyro[400, 1] = np.nan
    filt, ref = (make() for make in both(load_config("handheld", MekfConfig)))
    buf_t, buf_g, buf_a = np.empty(7), np.empty((7, 3)), np.empty((7, 3))
    for i in range(0, t.size - 7, 7):  # one reused buffer; a frame after one batch or after two
        buf_t[:], buf_g[:], buf_a[:] = t[i:i + 7], gyro[i:i + 7], accel[i:i + 7]
        filt.process_imu(buf_t, buf_g, buf_a)
        ref.process_imu(t[i:i + 7], gyro[i:i + 7], accel[i:i + 7])
        if i % 21 == 14:  # read before the frame: the held batch counted like any other
            assert filt.stream.counts == ref.stream.counts
        buf_t[:] = np.nan  # reused before the frame
        if i % 21 != 7:
            t_f = float(t[i + 6]) + 0.001
            e, e_ref = filt.process_frame(t_f, None), ref.process_frame(t_f, None)
            assert e.status == e_ref.status
    assert filt.stream.counts.nonfinite == 1
    assert_same_filters(filt, ref)


@needs_numba
def test_update_due_at_a_frame_same_as_reference_with_or_without_a_rotation():
    """An accelerometer update that falls due at the end of a frame's batch waits for the frame: the
    frame's compiled visual update (`kernels.visual_update`) stacks it, a frame without a rotation
    applies it alone. Frames with and without rotation, the counts read between the propagation and
    the frame, and a propagation past a waiting update: the reference's estimates, counts and flags."""
    traj, t, gyro, accel = stream(6, duration_s=10.0)
    rng = np.random.default_rng(8)
    deltas = rng.normal(scale=0.01, size=(t.size, 3))
    filt, ref = (make() for make in both(load_config("handheld", MekfConfig)))
    ests = ([], [])
    waiting = 0
    for k, i in enumerate(range(0, t.size - 7, 7)):
        t_f = float(t[i + 6]) + 0.001
        R_cm = traj.sample(np.array([t_f])).R_wc[0].T @ traj.R_wm(np.array([t_f]))[0] @ exp_so3(deltas[i])
        visual = VisualRotation(R_cm=R_cm, cov=1e-4 * np.eye(3), cost=0.01, iterations=3, n_valid=100)
        for f in (filt, ref):
            f.process_imu(t[i:i + 7], gyro[i:i + 7], accel[i:i + 7])
            f.propagate_to(t_f - 0.0005 if k % 11 == 5 else t_f)  # now and then the frame comes later
        if filt.accel.due:
            waiting += 1
            if waiting % 2:
                _ = filt.counters  # read (and moved out of the state buffer) before the frame takes the update
        for f, out in zip((filt, ref), ests):
            out.append(f.process_frame(t_f, None if k % 4 == 1 else visual))
        assert filt.counters == ref.counters
    assert waiting > 30 and filt.counters["accel_updates"] > 40 and filt.counters["visual_updates"] > 100
    assert_same_filters(filt, ref, *ests)


def _broken_kernel(*args):
    raise RuntimeError("Failed in nopython mode pipeline (step: native lowering)")  # as a compiler failure


@needs_numba
def test_kernels_that_fail_to_compile_run_as_plain_python_after_one_warning(monkeypatch):
    """numba compiles a kernel at its first call. Should that fail (here every driver raises as a
    failed compilation does), the filter warns once and goes on with the same functions as plain
    Python, with the same estimates, counts and flags; nothing crashes."""
    from uareme_fusion.backends import imu_stream

    traj, t, gyro, accel = stream(9, duration_s=2.0)

    def frames(t_f, filt):
        R_cm = traj.sample(np.array([t_f])).R_wc[0].T @ traj.R_wm(np.array([t_f]))[0]
        return VisualRotation(R_cm=R_cm, cov=1e-4 * np.eye(3), cost=0.01, iterations=3, n_valid=100)

    cfg = load_config("handheld", MekfConfig)
    a, ea = run(lambda: Mekf(cfg), t, gyro, accel, 7, frames)  # compiled, for the figures
    for name in kernels.DRIVERS:
        monkeypatch.setattr(kernels, name, _broken_kernel)  # restored after the test
    monkeypatch.setattr(imu_stream._ROWS_IF_CLEAN, "dispatcher", _broken_kernel)
    monkeypatch.setattr(jit, "_warned", False)
    monkeypatch.delenv("UAREME_NO_JIT", raising=False)
    try:
        with pytest.warns(RuntimeWarning) as caught:
            b, eb = run(lambda: Mekf(cfg), t, gyro, accel, 7, frames)
        assert sum("compiled kernels unavailable" in str(w.message) for w in caught) == 1
        assert not kernels.compiled_now() and b.counters["visual_updates"] > 20
    finally:
        monkeypatch.undo()
        kernels._compile()  # the compiled kernels back for the other tests (loaded from the cache)
    assert_same_filters(a, b, ea, eb)


def _doubled(x):
    return 2.0 * x


@needs_numba
def test_a_kernel_compiles_where_no_cache_folder_is_writable(tmp_path, monkeypatch):
    """A read-only install with no writable cache folder anywhere: numba cannot cache, and a kernel
    asked to cache still compiles (in each process) instead of failing or falling back."""
    from numba.core import config as numba_config

    not_a_folder = tmp_path / "file"
    not_a_folder.write_text("")
    # numba looks only in NUMBA_CACHE_DIR, which cannot be created (a file is in the way)
    monkeypatch.setattr(numba_config, "CACHE_LOCATOR_CLASSES", "UserProvidedCacheLocator")
    monkeypatch.setattr(numba_config, "CACHE_DIR", str(not_a_folder))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "compiled kernels unavailable": it compiled, nothing fell back
        kernel = jit.compiled(_doubled, cache=True)
        assert kernel is not None and kernel(np.arange(3.0)).tolist() == [0.0, 2.0, 4.0]
    assert not_a_folder.is_file() and list(tmp_path.iterdir()) == [not_a_folder]  # and nothing was cached


def test_a_kernel_cache_is_keyed_by_the_sources_it_draws_on(tmp_path):
    """numba checks a cache against its own source only: `jit.key_cache_by_sources` keys it by the
    contents of every listed module instead, so an edit to any of them (a state-buffer layout) gives
    another key, and no file is deleted on the way."""
    kernels_py, layout_py = tmp_path / "kernels.py", tmp_path / "layout.py"
    kernels_py.write_text("x = 1\n")
    layout_py.write_text("N = 3\n")
    before = jit.sources_stamp([kernels_py, layout_py])
    assert jit.sources_stamp([layout_py, kernels_py]) == before  # the order does not matter
    layout_py.write_text("N = 4\n")
    jit._STAMPS.clear()  # a new process
    assert jit.sources_stamp([kernels_py, layout_py]) != before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kernels.py", "layout.py"]
    if kernels.compiled_now():  # the kernels' dispatchers carry the stamp of their sources
        stamp = jit.sources_stamp(kernels._sources())
        assert kernels.INTEGRATE._cache._cache_file._source_stamp == stamp


def test_kernels_see_the_fields_that_python_sees():
    """`kernel_update.state_views` (the kernels' array fields of the state buffer) and
    `state_buffer.field_views` (Python's) are the same views of `x`, field by field, in the order of
    `state_buffer.ARRAYS`; the record is float64 throughout, its flat view (`flat_index`) the fields."""
    x = state_buffer.new_state_buffer()
    flat = x.view(np.float64)
    flat[:] = np.arange(flat.size)
    python_views = state_buffer.field_views(x)
    kernel_views = getattr(kernel_update.state_views, "py_func", kernel_update.state_views)(state_buffer.python_state(x))
    s = state_buffer.python_state(x)[0]  # the record, as a kernel reads it (`s = x[0]`)
    assert len(kernel_views) == len(state_buffer.ARRAYS) and x.dtype.itemsize == 8 * flat.size
    for view, (name, shape) in zip(kernel_views, state_buffer.ARRAYS):
        assert view.shape == shape and np.shares_memory(view, x)
        assert np.array_equal(view, python_views[name]) and np.array_equal(view, flat[state_buffer.flat_index(name)])
    for name, shape in state_buffer.FIELDS:
        assert np.array_equal(getattr(s, name), flat[state_buffer.flat_index(name)].reshape(shape))
    assert s.t_state_s == python_views["s"].t_state_s == 0.0


@pytest.mark.slow
@needs_numba
def test_warm_up_loads_every_kernel_a_filter_with_an_imu_calls():
    """In a fresh process (numba loads a kernel at its first call), `warm_up` leaves no kernel of the
    stream to come to load: IMU-only in bulk, then with frames; without an IMU, or in visual-only
    mode, it loads nothing."""
    code = ("from uareme_fusion.backends.mekf import Mekf, MekfConfig, kernels\n"
            "from uareme_fusion.backends import imu_stream\n"
            "names = ('INTEGRATE', 'ACCEL_UPDATE', 'SEGMENTS', 'STAGE', 'INTEGRATE_STAGED', 'VISUAL_UPDATE',"
            " 'VISUAL_DISTANCE')\n"
            "loaded = lambda: ''.join(str(len(getattr(kernels, n).signatures)) for n in names)\n"
            "Mekf('handheld').warm_up(False, True); Mekf(MekfConfig(mode='visual_only')).warm_up(True, True)\n"
            "print(loaded()); Mekf('imu_only').warm_up(True, False); print(loaded())\n"
            "Mekf('handheld').warm_up(True, True); print(loaded(), len(imu_stream._ROWS_IF_CLEAN.dispatcher.signatures))\n")
    # IMU-only: integrate, segments
    assert fresh_python(code, timeout_s=300).stdout.split() == ["0000000", "1010000", "1111111", "1"]
