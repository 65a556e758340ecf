"""The paper's training loss for normals with confidence kappa (eq. 2-3), differentiable in torch.

The density of the true normal around a predicted one, at angular error theta (eq. 3):
    p(theta) = D(kappa) exp(-kappa sin^2(theta) cos^2(theta))   for theta < pi/4,
    p(theta) = D(kappa) exp(-kappa / 4)                        beyond,
normalised over the sphere, and the loss is its negative log-likelihood (eq. 2):
    L = C(kappa) + kappa sin^2 cos^2 (theta < pi/4),   C(kappa) + kappa / 4 (beyond),   C = -log D.
With x = cos(theta), dOmega = 2 pi sin(theta) dtheta and sin^2 cos^2 = x^2 (1 - x^2):
    1 / D = 2 pi [ int_{1/sqrt 2}^1 exp(-kappa x^2 (1 - x^2)) dx + (1 + 1/sqrt 2) exp(-kappa / 4) ].
No closed form is known, so we integrate numerically (composite Gauss-Legendre on panels that
shrink geometrically towards x = 1, where the integrand's width is 1 / (2 kappa)), and fit C with a
natural cubic spline in s = log(1 + kappa) on kappa in [0, 1e5], as the paper does. The spline's
coefficient table is computed at import (a few milliseconds, numpy and scipy only); torch is imported
only by the torch functions, which evaluate the same piecewise cubic with torch ops so autograd works.
Above KAPPA_MAX, C is held constant (kappa is capped long before that in practice).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.interpolate import CubicSpline

from ..errors import InputError

KAPPA_MAX = 1e5
"""Upper end of the spline's range (the paper's)."""
SPLINE_KNOTS = 320
"""Knots uniform in log(1 + kappa) over [0, KAPPA_MAX], plus 5 geometrically closer ones at each
end, where the natural boundary condition (zero curvature) would otherwise cost accuracy; the
spline then matches the quadrature to 2e-7 in C everywhere."""

_COS_QUARTER_PI = 1.0 / np.sqrt(2.0)
_TAIL_SOLID_ANGLE = 2.0 * np.pi * (1.0 + _COS_QUARTER_PI)  # sphere area at theta >= pi/4


def _quadrature_nodes(order: int = 24, panels: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Nodes in s = 1 - x on [0, 1 - 1/sqrt 2] and their weights: Gauss-Legendre on panels whose
    edges shrink by 2.5x per panel towards s = 0, so widths down to 1e-10 are resolved."""
    top = 1.0 - _COS_QUARTER_PI
    edges = np.concatenate([[0.0], top * 2.5 ** -np.arange(panels - 1, -1, -1.0)])
    g, w = np.polynomial.legendre.leggauss(order)
    lo, hi = edges[:-1, None], edges[1:, None]
    nodes = (0.5 * (hi - lo) * g + 0.5 * (hi + lo)).ravel()
    weights = (0.5 * (hi - lo) * w).ravel()
    return nodes, weights


def normaliser_quadrature(kappa) -> np.ndarray:
    """D(kappa) of eq. 3 by direct quadrature, float64, for kappa >= 0 (any shape)."""
    kappa = np.asarray(kappa, dtype=float)
    if np.any(~np.isfinite(kappa)) or np.any(kappa < 0):
        raise InputError("kappa must be finite and >= 0 for the normaliser D(kappa)")
    s, w = _quadrature_nodes()
    x = 1.0 - s
    energy = x * x * s * (2.0 - s)  # x^2 (1 - x^2) with 1 - x^2 = s (2 - s), no cancellation near x = 1
    inner = np.exp(-kappa[..., None] * energy) @ w
    return 1.0 / (2.0 * np.pi * inner + _TAIL_SOLID_ANGLE * np.exp(-kappa / 4.0))


@lru_cache(maxsize=1)
def spline_table() -> tuple[np.ndarray, np.ndarray]:
    """(knots (K,), coefficients (K - 1, 4)) of the natural cubic spline of C(kappa) = -log D(kappa)
    in s = log(1 + kappa): on [knots[i], knots[i+1]], C = sum_j coef[i, j] (s - knots[i])^j."""
    uniform = np.linspace(0.0, np.log1p(KAPPA_MAX), SPLINE_KNOTS)
    near_ends = np.geomspace(1e-3, uniform[1], 6)[:-1]
    knots = np.union1d(uniform, np.concatenate([near_ends, uniform[-1] - near_ends]))
    C = -np.log(normaliser_quadrature(np.expm1(knots)))
    spline = CubicSpline(knots, C, bc_type="natural")
    coef = spline.c[::-1].T.copy()  # scipy stores the highest power first
    knots.setflags(write=False)
    coef.setflags(write=False)
    return knots, coef


def log_normaliser_numpy(kappa) -> np.ndarray:
    """C(kappa) = -log D(kappa) from the spline (numpy, float64); kappa clipped to [0, KAPPA_MAX]."""
    knots, coef = spline_table()
    s = np.log1p(np.clip(np.asarray(kappa, dtype=float), 0.0, KAPPA_MAX))
    i = np.clip(np.searchsorted(knots, s, side="right") - 1, 0, len(knots) - 2)
    ds = s - knots[i]
    c = coef[i]
    return c[..., 0] + ds * (c[..., 1] + ds * (c[..., 2] + ds * c[..., 3]))


def energy_from_cosine(cos_theta):
    """The per-pixel energy of eq. 3: sin^2 cos^2 = c^2 (1 - c^2) for theta < pi/4, else 1/4.
    Works on numpy arrays and torch tensors alike."""
    c2 = cos_theta * cos_theta
    inside = cos_theta > _COS_QUARTER_PI
    energy = c2 * (1.0 - c2)
    if isinstance(energy, np.ndarray) or np.isscalar(energy):
        return np.where(inside, energy, 0.25)
    return energy.where(inside, energy.new_tensor(0.25))


def density(theta, kappa) -> np.ndarray:
    """p(theta) of eq. 3 per steradian (numpy): the density of the true normal at angle theta (rad)
    from the prediction; integrates to 1 over the sphere."""
    return np.exp(-log_normaliser_numpy(kappa) - np.asarray(kappa, float) * energy_from_cosine(np.cos(theta)))


def log_normaliser(kappa):
    """C(kappa) = -log D(kappa) in torch, differentiable; kappa (any shape) is clamped to
    [0, KAPPA_MAX], so the gradient is 0 outside that range."""
    import torch

    knots, coef = _torch_table(kappa.dtype, kappa.device)
    s = torch.log1p(kappa.clamp(0.0, KAPPA_MAX))
    i = (torch.searchsorted(knots, s.detach().contiguous(), right=True) - 1).clamp(0, len(knots) - 2)
    ds = s - knots[i]
    c = coef[i]
    return c[..., 0] + ds * (c[..., 1] + ds * (c[..., 2] + ds * c[..., 3]))


@lru_cache(maxsize=8)
def _torch_table(dtype, device):
    import torch

    knots, coef = spline_table()
    return torch.tensor(knots, dtype=dtype, device=device), torch.tensor(coef, dtype=dtype, device=device)


def kappa_nll(pred_normals, kappa, true_normals, mask=None, channel_dim: int = 1):
    """Mean negative log-likelihood of eq. 2 over pixels (torch, differentiable).

    `pred_normals`, `true_normals`: tensors with 3 channels on `channel_dim` (e.g. (B, 3, H, W));
    the prediction need not be unit length (normalised here). `kappa`: the same shape without the
    channel dimension (or with a singleton channel), >= 0. `mask`: optional bool tensor of that shape,
    True where the ground truth is valid. Returns a scalar tensor.
    """
    import torch

    if pred_normals.shape != true_normals.shape or pred_normals.shape[channel_dim] != 3:
        raise InputError(
            f"Expected predicted and true normals of the same shape with 3 channels on dim {channel_dim}, "
            f"got {tuple(pred_normals.shape)} and {tuple(true_normals.shape)}"
        )
    if kappa.dim() == pred_normals.dim():
        kappa = kappa.squeeze(channel_dim)
    pred = torch.nn.functional.normalize(pred_normals, dim=channel_dim, eps=1e-8)
    true = torch.nn.functional.normalize(true_normals, dim=channel_dim, eps=1e-8)
    cos_theta = (pred * true).sum(dim=channel_dim).clamp(-1.0, 1.0)
    if kappa.shape != cos_theta.shape:
        raise InputError(f"Expected kappa of shape {tuple(cos_theta.shape)}, got {tuple(kappa.shape)}")
    loss = log_normaliser(kappa) + kappa * energy_from_cosine(cos_theta)  # paper eq. 2
    if mask is None:
        return loss.mean()
    mask = mask.to(loss.dtype)
    return (loss * mask).sum() / mask.sum().clamp(min=1.0)
