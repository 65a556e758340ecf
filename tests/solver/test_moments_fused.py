"""The compiled one-pass moments (issue 17) against the numpy reference, valid and invalid pixels."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from uareme_fusion import jit
from uareme_fusion.solver.lines import line_moments, sextic_tensor_reference
from uareme_fusion.solver.moments import BLOCK_PIXELS, check_normal_map, fused_moments, normal_moments_reference

pytestmark = pytest.mark.skipif(not jit.available(), reason="numba not installed: no compiled path to test")


def assert_same(n, k):
    ref = normal_moments_reference(n, k)
    fused = fused_moments(*check_normal_map(n, k))
    scale = max(float(np.abs(ref.G).max()), 1e-300)
    np.testing.assert_allclose(fused.G, ref.G, rtol=0, atol=1e-12 * scale)
    assert fused.total_weight == pytest.approx(ref.total_weight, rel=1e-12, abs=1e-300)
    assert (fused.n_valid, fused.n_invalid) == (ref.n_valid, ref.n_invalid)


def test_float64_map_with_every_kind_of_invalid_pixel_matches_the_reference():
    rng = np.random.default_rng(3)
    n = rng.normal(size=(120, 160, 3)) * rng.uniform(0.2, 5.0, size=(120, 160, 1))
    k = rng.uniform(0.0, 50.0, size=(120, 160))
    n[0, :10] = np.nan
    n[1, :5] = 0.0
    n[2, :3] = np.inf
    n[3, :2, 1] = -np.inf
    k[4, :7] = np.nan
    k[5, :2] = -1.0
    k[6, :4] = np.inf
    k[7, :3] = -0.0
    k[8, :6] = 0.0  # valid, weight 0: neither in n_valid nor in n_invalid
    assert_same(n, k)
    assert_same(n, None)


def test_float32_map_matches_a_float64_reference_to_float64_rounding():
    rng = np.random.default_rng(4)
    n = rng.normal(size=(50_000, 3)).astype(np.float32)
    k = rng.uniform(0.0, 75.0, size=50_000).astype(np.float32)
    fused = fused_moments(*check_normal_map(n, k))
    ref = normal_moments_reference(n.astype(np.float64), k.astype(np.float64))  # same values, exact sums
    np.testing.assert_allclose(fused.G, ref.G, rtol=1e-12)
    assert (fused.n_valid, fused.n_invalid) == (ref.n_valid, ref.n_invalid)


@settings(max_examples=60, deadline=None)
@given(arrays(np.float64, (7, 3), elements=st.one_of(st.floats(-1e6, 1e6), st.sampled_from([np.nan, np.inf, 0.0]))),
       arrays(np.float64, (7,), elements=st.one_of(st.floats(-10, 1e6), st.sampled_from([np.nan, np.inf, -0.0]))))
def test_any_small_float64_map_counts_and_sums_like_the_reference(n, k):
    assert_same(n, k)


def test_every_sequence_of_block_paths_sums_and_counts_like_the_reference():
    """Blocks without holes, with finite holes (weight select) and with NaN/Inf (full select), in
    random orders and a last partial block: the path a block takes must not change its sums."""
    B = BLOCK_PIXELS
    defects = {
        "none": lambda n, k, i: None,
        "zero normal": lambda n, k, i: n.__setitem__(i, 0.0),
        "tiny normal": lambda n, k, i: n.__setitem__(i, 1e-7),
        "NaN normal": lambda n, k, i: n.__setitem__((i, 1), np.nan),
        "Inf normal": lambda n, k, i: n.__setitem__((i, 2), -np.inf),
        "zero kappa": lambda n, k, i: k.__setitem__(i, 0.0),
        "-0 kappa": lambda n, k, i: k.__setitem__(i, -0.0),
        "negative kappa": lambda n, k, i: k.__setitem__(i, -2.0),
        "Inf kappa": lambda n, k, i: k.__setitem__(i, np.inf),
    }
    names = list(defects)
    for seed in range(12):
        rng = np.random.default_rng(seed)
        size = 6 * B + int(rng.integers(1, B))
        n = rng.normal(size=(size, 3))
        k = rng.uniform(0.5, 40.0, size=size)
        for block in range(7):
            kind = names[int(rng.integers(len(names)))] if rng.random() < 0.6 else "none"
            for i in rng.integers(block * B, min((block + 1) * B, size), size=int(rng.integers(1, 4))):
                defects[kind](n, k, i)
        assert_same(n, k)
        n32, k32 = n.astype(np.float32), k.astype(np.float32)
        fused = fused_moments(*check_normal_map(n32, k32))
        ref = normal_moments_reference(n32.astype(np.float64), k32.astype(np.float64))  # exact sums
        np.testing.assert_allclose(fused.G, ref.G, rtol=0, atol=1e-12 * np.abs(ref.G).max())
        assert (fused.n_valid, fused.n_invalid) == (ref.n_valid, ref.n_invalid)


@pytest.mark.parametrize("n_segments", [0, 1, 7, 2500])
def test_compiled_line_moments_match_the_cube_product(n_segments):
    """The line cue's sixth-order tensor from its 28 distinct sums (compiled) equals the (N, 27) cube
    product, for any number of segments; NaN planes and weights <= 0 are left out of both."""
    rng = np.random.default_rng(n_segments)
    p = rng.normal(size=(n_segments, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    w = rng.uniform(0.1, 30.0, size=n_segments)
    if n_segments > 5:
        p[2, 1] = np.nan
        w[3] = 0.0
        w[4] = -1.0
    m = line_moments(p, w)
    assert m.n_segments == n_segments - (3 if n_segments > 5 else 0)
    ref = sextic_tensor_reference(m.planes, m.weights)
    np.testing.assert_allclose(m.T, ref, rtol=0, atol=1e-12 * max(np.abs(ref).max(), 1e-300))
    np.testing.assert_array_equal(m.T, m.T.T)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_compiled_costs_and_normal_derivatives_of_one_rotation_match_numpy(seed, monkeypatch):
    """The compiled forms against the numpy paths: the quartic's cost (one rotation and a stack), gradient and
    Hessian (`quartic._fourth_kernel`, `_derivatives_kernel`) and equation (L) with its derivatives
    (`lines._form_kernel`, `_functionals_kernel`)."""
    from uareme_fusion.rotations import exp_so3
    from uareme_fusion.solver import lines, quartic
    from uareme_fusion.solver.moments import normal_moments

    rng = np.random.default_rng(seed)
    n = rng.normal(size=(30, 40, 3))
    moments = normal_moments(n / np.linalg.norm(n, axis=-1, keepdims=True), rng.uniform(0.5, 20.0, size=(30, 40)))
    p = rng.normal(size=(60, 3))
    segments = line_moments(p / np.linalg.norm(p, axis=1, keepdims=True), rng.uniform(0.1, 1.0, size=60))
    R = exp_so3(rng.normal(size=3))
    G, T, W = moments.G, moments.tensor(), moments.total_weight
    cost, line_cost = quartic.normalised_cost(G, W, R), lines.normalised_line_cost(segments, R)
    grad, hess = quartic.gradient_hessian(T, W, R)
    line_derivatives = lines.line_cost_gradient_hessian(segments, R)
    stack = exp_so3(rng.normal(size=(4, 5, 3)))
    costs, line_costs = quartic.normalised_cost(G, W, stack), lines.normalised_line_cost(segments, stack)
    assert np.ndim(cost) == 0 and np.ndim(line_cost) == 0 and costs.shape == line_costs.shape == (4, 5)
    for kernel in (quartic._fourth_kernel, quartic._derivatives_kernel, lines._form_kernel, lines._functionals_kernel):
        monkeypatch.setattr(kernel, "dispatcher", None)
    assert cost == pytest.approx(quartic.normalised_cost(G, W, R), rel=0, abs=1e-14)
    assert line_cost == pytest.approx(lines.normalised_line_cost(segments, R), rel=1e-12, abs=1e-300)
    assert line_cost == pytest.approx(lines.normalised_line_cost(segments, R[None])[0], rel=1e-12, abs=1e-300)
    np.testing.assert_allclose(costs, quartic.normalised_cost(G, W, stack), rtol=0, atol=1e-14)
    np.testing.assert_allclose(line_costs, lines.normalised_line_cost(segments, stack), rtol=1e-12, atol=0)
    grad_ref, hess_ref = quartic.gradient_hessian(T, W, R)
    np.testing.assert_allclose(grad, grad_ref, rtol=0, atol=1e-14)
    np.testing.assert_allclose(hess, hess_ref, rtol=0, atol=1e-13)
    for compiled, reference in zip(line_derivatives, lines.line_cost_gradient_hessian(segments, R)):
        np.testing.assert_allclose(compiled, reference, rtol=0, atol=1e-14)


def test_a_kernel_that_fails_falls_back_once_with_one_warning(monkeypatch):
    """`jit.Kernel`: a kernel that raises (as a failed compilation does) answers FALLBACK with one warning,
    and is not tried again; its callers' reference paths then give the same figures."""
    from uareme_fusion.solver import quartic

    calls = []

    def broken(*args):
        calls.append(1)
        raise RuntimeError("Failed in nopython mode pipeline")

    kernel = jit.Kernel(lambda out: out.fill(2.0))
    out = np.zeros(3)
    assert kernel and kernel(out) is None and out.tolist() == [2.0, 2.0, 2.0]
    monkeypatch.setattr(kernel, "dispatcher", broken)
    monkeypatch.setattr(jit, "_warned", False)
    monkeypatch.delenv("UAREME_NO_JIT", raising=False)
    with pytest.warns(RuntimeWarning, match="compiled kernels unavailable.*nopython"):
        assert kernel(out) is jit.FALLBACK
    assert kernel(out) is jit.FALLBACK and not kernel and len(calls) == 1
    G, W, R = np.eye(6), 3.0, np.eye(3)
    expected = quartic.normalised_cost(G, W, R)
    monkeypatch.setattr(quartic._fourth_kernel, "dispatcher", broken)
    monkeypatch.setattr(jit, "_warned", True)
    assert quartic.normalised_cost(G, W, R) == pytest.approx(expected, abs=1e-14) and len(calls) == 2
