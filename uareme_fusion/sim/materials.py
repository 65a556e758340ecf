"""Procedural material textures (albedo images) for the synthetic scenes.

Every texture is a (TEXTURE_PX, TEXTURE_PX, 3) float32 albedo in [0, 1], drawn from a seeded
`numpy.random.Generator`, so a scene's look is reproducible. Kinds: `plain` (one colour with a
faint grain), `noise` (smooth value noise between two colours, like plaster or concrete),
`stripes` (wallpaper or tiles), `wood` (rings with grain), `poster` (random shapes and bars,
stretched over one face), `sky` (bright window glass), `checker` (floor tiles).
"""

from __future__ import annotations

import cv2
import numpy as np

TEXTURE_PX = 64
"""Side of every texture image, pixels."""

MATERIAL_KINDS = ("plain", "noise", "stripes", "wood", "poster", "sky", "checker")


def random_colour(rng: np.random.Generator, lo: float = 0.15, hi: float = 0.9) -> np.ndarray:
    """A random RGB albedo (3,) with each channel in [lo, hi]."""
    return rng.uniform(lo, hi, 3).astype(np.float32)


def _smooth_noise(rng: np.random.Generator, cells: int) -> np.ndarray:
    """Tileable smooth noise in [0, 1], (TEXTURE_PX, TEXTURE_PX), from a cells x cells grid."""
    coarse = rng.random((cells, cells)).astype(np.float32)
    tiled = np.tile(coarse, (3, 3))
    big = cv2.resize(tiled, (3 * TEXTURE_PX, 3 * TEXTURE_PX), interpolation=cv2.INTER_CUBIC)
    out = big[TEXTURE_PX: 2 * TEXTURE_PX, TEXTURE_PX: 2 * TEXTURE_PX]
    out = (out - out.min()) / max(float(np.ptp(out)), 1e-6)
    return out


def make_texture(kind: str, rng: np.random.Generator, colour: np.ndarray | None = None) -> np.ndarray:
    """One albedo texture of the given kind, (TEXTURE_PX, TEXTURE_PX, 3) float32 in [0, 1]."""
    base = random_colour(rng) if colour is None else np.asarray(colour, np.float32)
    other = random_colour(rng)
    n = TEXTURE_PX
    v, u = np.mgrid[0:n, 0:n].astype(np.float32) / n
    if kind == "plain":
        grain = 0.04 * (rng.random((n, n)).astype(np.float32) - 0.5)
        tex = base + grain[..., None]
    elif kind == "noise":
        mix = 0.6 * _smooth_noise(rng, 4) + 0.4 * _smooth_noise(rng, 16)
        tex = base + (other - base) * 0.5 * mix[..., None]
    elif kind == "stripes":
        periods = int(rng.integers(2, 8))
        s = (np.sin(2 * np.pi * periods * u) > rng.uniform(-0.5, 0.5)).astype(np.float32)
        tex = base + (other - base) * s[..., None]
    elif kind == "wood":
        wood = np.array([0.55, 0.35, 0.18], np.float32) * rng.uniform(0.7, 1.3)
        rings = 0.5 + 0.5 * np.sin(2 * np.pi * (int(rng.integers(3, 7)) * v
                                                + 0.3 * _smooth_noise(rng, 4)))
        tex = wood * (0.75 + 0.25 * rings[..., None]) * (0.9 + 0.1 * _smooth_noise(rng, 32)[..., None])
    elif kind == "poster":
        img = np.ascontiguousarray(np.broadcast_to(base, (n, n, 3)))
        for _ in range(int(rng.integers(3, 8))):
            c = tuple(float(x) for x in random_colour(rng, 0.0, 1.0))
            x0, y0 = (int(a) for a in rng.integers(0, n, 2))
            if rng.random() < 0.5:
                x1, y1 = (int(a) for a in rng.integers(0, n, 2))
                cv2.rectangle(img, (x0, y0), (x1, y1), c, -1)
            else:
                cv2.circle(img, (x0, y0), int(rng.integers(3, n // 3)), c, -1)
        tex = img
    elif kind == "sky":
        tex = np.array([0.75, 0.85, 1.0], np.float32) * (0.85 + 0.15 * _smooth_noise(rng, 4))[..., None]
    elif kind == "checker":
        cells = int(rng.choice([2, 4]))
        s = ((np.floor(u * cells) + np.floor(v * cells)) % 2).astype(np.float32)
        tex = base + (other - base) * 0.6 * s[..., None]
    else:
        raise ValueError(f"unknown material kind {kind!r}; valid: {', '.join(MATERIAL_KINDS)}")
    return np.clip(tex, 0.0, 1.0).astype(np.float32)
