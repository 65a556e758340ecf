"""The paper's kappa loss (eq. 2-3): normaliser, spline, torch gradients, maximum likelihood."""

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import minimize_scalar

from uareme_fusion.errors import InputError
from uareme_fusion.normals.kappa_loss import (
    KAPPA_MAX,
    density,
    energy_from_cosine,
    log_normaliser_numpy,
    normaliser_quadrature,
)

KAPPAS = [0.0, 0.5, 3.0, 20.0, 75.0, 400.0, 5e3, 1e5]
COS_45 = 1.0 / np.sqrt(2.0)


def sphere_integral(fn, kappa):
    """2 pi int_0^pi fn(theta) sin(theta) dtheta by adaptive quadrature in theta, split where the
    density changes form (pi/4) and at its width near theta = 0 (independent of the module's rule)."""
    width = min(np.pi / 4, 10.0 / np.sqrt(kappa + 1e-12))
    parts = [(0.0, width), (width, np.pi / 4), (np.pi / 4, np.pi)]
    total = sum(
        quad(lambda t: fn(t) * np.sin(t), a, b, epsabs=0, epsrel=1e-12, limit=200)[0] for a, b in parts if b > a
    )
    return 2.0 * np.pi * total


@pytest.mark.parametrize("kappa", KAPPAS)
def test_density_integrates_to_one_over_the_sphere(kappa):
    assert sphere_integral(lambda t: density(t, kappa), kappa) == pytest.approx(1.0, abs=1e-6)


def test_normaliser_limits():
    # kappa = 0: uniform on the sphere; large kappa: D ~ kappa / pi (Laplace's method at theta = 0).
    assert normaliser_quadrature(0.0) == pytest.approx(1.0 / (4.0 * np.pi), rel=1e-14)
    assert normaliser_quadrature(1e5) == pytest.approx(1e5 / np.pi, rel=1e-4)
    D = normaliser_quadrature(np.geomspace(1e-3, KAPPA_MAX, 50))
    assert np.all(np.diff(D) > 0)  # D increases with kappa (paper, after eq. 3)
    with pytest.raises(InputError, match="kappa"):
        normaliser_quadrature(-1.0)


def test_spline_matches_direct_quadrature():
    rng = np.random.default_rng(7)
    kappa = np.concatenate([[0.0, KAPPA_MAX], np.expm1(rng.uniform(0.0, np.log1p(KAPPA_MAX), 3000))])
    C_direct = -np.log(normaliser_quadrature(kappa))
    np.testing.assert_allclose(log_normaliser_numpy(kappa), C_direct, rtol=0, atol=1e-6)
    # Held constant above the range, never extrapolated.
    assert log_normaliser_numpy(1e7) == log_normaliser_numpy(KAPPA_MAX)


def expected_energy(kappa):
    """E_p[energy] by adaptive quadrature: the model's mean per-pixel energy at this kappa."""
    return sphere_integral(lambda t: density(t, kappa) * energy_from_cosine(np.cos(t)), kappa)


def sample_angles(kappa, count, rng):
    """Angles theta drawn from the density of eq. 3 by inverse transform sampling in x = cos(theta)."""
    x = np.linspace(-1.0, 1.0, 400001)
    pdf_x = np.exp(-kappa * energy_from_cosine(x))  # per unit x (the azimuth integrates out)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (pdf_x[1:] + pdf_x[:-1]) * np.diff(x))])
    return np.arccos(np.interp(rng.uniform(0.0, cdf[-1], count), cdf, x))


def test_maximum_likelihood_recovers_kappa():
    """Minimising the mean loss over kappa on errors drawn from the density returns its kappa."""
    rng = np.random.default_rng(11)
    for kappa_true in (5.0, 60.0, 2000.0):
        energy = energy_from_cosine(np.cos(sample_angles(kappa_true, 100_000, rng))).mean()
        fit = minimize_scalar(
            lambda log_k: log_normaliser_numpy(np.exp(log_k)) + np.exp(log_k) * energy,
            bounds=(-5.0, np.log(KAPPA_MAX)), method="bounded", options={"xatol": 1e-8},
        )
        assert np.exp(fit.x) == pytest.approx(kappa_true, rel=0.03)


def test_torch_log_normaliser_matches_numpy_and_its_derivative():
    torch = pytest.importorskip("torch")
    from uareme_fusion.normals.kappa_loss import log_normaliser

    kappa_np = np.array([0.0, 0.3, 4.0, 30.0, 75.0, 900.0, 2e4])
    kappa = torch.tensor(kappa_np, dtype=torch.float64, requires_grad=True)
    C = log_normaliser(kappa)
    np.testing.assert_allclose(C.detach().numpy(), log_normaliser_numpy(kappa_np), atol=1e-12)
    (grad,) = torch.autograd.grad(C.sum(), kappa)
    # C = log Z(kappa), so dC/dkappa = -E_p[energy] (exponential-family identity).
    expected = np.array([-expected_energy(k) for k in kappa_np])
    np.testing.assert_allclose(grad.numpy(), expected, rtol=2e-3, atol=1e-6)


def normals_at_angles(theta_deg):
    """(1, 3, 1, N) predicted normals at the given angles from the true normal (0, 0, -1)."""
    t = np.radians(np.asarray(theta_deg, float))
    pred = np.stack([np.sin(t), np.zeros_like(t), -np.cos(t)], axis=0)
    true = np.broadcast_to([[0.0], [0.0], [-1.0]], pred.shape)
    return pred[None, :, None, :], np.ascontiguousarray(true)[None, :, None, :]


def test_gradient_raises_kappa_on_accurate_pixels_and_lowers_it_on_wrong_ones():
    torch = pytest.importorskip("torch")
    from uareme_fusion.normals.kappa_loss import kappa_nll

    pred, true = normals_at_angles([2.0, 5.0, 40.0, 60.0, 120.0])
    kappa = torch.full((1, 1, 5), 10.0, dtype=torch.float64, requires_grad=True)
    loss = kappa_nll(torch.tensor(pred), kappa, torch.tensor(true))
    (grad,) = torch.autograd.grad(loss, kappa)
    g = grad.numpy().ravel()
    assert g[0] < 0 and g[1] < 0  # gradient descent raises kappa where the error is small
    assert g[2] > 0 and g[3] > 0 and g[4] > 0  # and lowers it where the error is large
    # dL/dkappa = (energy - E_p[energy]) / N per pixel.
    energy = energy_from_cosine(np.cos(np.radians([2.0, 5.0, 40.0, 60.0, 120.0])))
    np.testing.assert_allclose(g, (energy - expected_energy(10.0)) / 5, rtol=2e-3)


def test_loss_is_finite_at_the_ends_and_gradients_reach_the_normals():
    torch = pytest.importorskip("torch")
    from uareme_fusion.normals.kappa_loss import kappa_nll

    pred, true = normals_at_angles([0.0, 45.0, 90.0, 180.0, 10.0, 10.0])
    pred[..., 5] = 0.0  # a zero-length prediction
    pred_t = torch.tensor(pred, dtype=torch.float32, requires_grad=True)
    kappa = torch.tensor([[[0.0, 1e5, 0.0, 1e5, 1e5, 50.0]]], dtype=torch.float32, requires_grad=True)
    loss = kappa_nll(pred_t, kappa, torch.tensor(true, dtype=torch.float32))
    loss.backward()
    assert torch.isfinite(loss) and torch.all(torch.isfinite(kappa.grad)) and torch.all(torch.isfinite(pred_t.grad))
    # At theta = 10 deg with kappa = 1e5 the energy term dominates and pulls the normal to the truth.
    assert pred_t.grad[0, 0, 0, 4] > 0
    # kappa = 0 is the uniform density on the sphere: the loss is log(4 pi) whatever the error.
    zero = torch.zeros(1, 1, 1, dtype=torch.float64)
    single = kappa_nll(torch.tensor(pred[..., :1]), zero, torch.tensor(true[..., :1]))
    assert float(single) == pytest.approx(np.log(4 * np.pi), abs=1e-6)


def test_mask_and_shape_errors():
    torch = pytest.importorskip("torch")
    from uareme_fusion.normals.kappa_loss import kappa_nll

    pred, true = normals_at_angles([2.0, 60.0])
    pred_t, true_t = torch.tensor(pred), torch.tensor(true)
    kappa = torch.tensor([[[20.0, 20.0]]], dtype=torch.float64)
    only_first = kappa_nll(pred_t, kappa, true_t, mask=torch.tensor([[[True, False]]]))
    first = kappa_nll(pred_t[..., :1], kappa[..., :1], true_t[..., :1])
    assert float(only_first) == pytest.approx(float(first))
    assert float(kappa_nll(pred_t, kappa[:, None], true_t)) == pytest.approx(float(kappa_nll(pred_t, kappa, true_t)))
    with pytest.raises(InputError, match="3 channels"):
        kappa_nll(pred_t[:, :2], kappa, true_t[:, :2])
    with pytest.raises(InputError, match="kappa of shape"):
        kappa_nll(pred_t, kappa[..., :1], true_t)
