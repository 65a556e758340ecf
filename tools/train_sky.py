"""Train the sky classifier of `solver/sky_horizon.py` on horizon_uav's land masks (clips a and b only).

    python tools/train_sky.py [--data ../shared/data/horizon_uav] [--out uareme_fusion/solver/weights/sky_mlp.npz]

Per-pixel features (`sky_features`) at the detector's work size; label 1 where the land mask is black
(sky), pixels on the boundary (mask fraction between 0.1 and 0.9) left out; `--pixels` per image drawn
with a fixed seed. One hidden tanh layer and a logistic output, cross-entropy minimised by L-BFGS
(scipy) with a small L2 penalty. Prints the pixel accuracy on the training clips and on clip c (held
out: never used to choose anything here).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
from scipy.optimize import minimize

from uareme_fusion.solver.sky_horizon import SkyHorizonConfig, sky_features, work_image


def in_split(name: str, split: str) -> bool:
    """`split`: clip letters ("ab": clips a and b), or "even" / "odd" (the frame number after the last "_")."""
    if split in ("even", "odd"):
        return (int(name.rsplit("_", 1)[1].split(".")[0]) // 10) % 2 == (split == "odd")
    return name[0] in split


def samples(folder: Path, clips: str, pixels: int, rng) -> tuple[np.ndarray, np.ndarray]:
    xs, ys = [], []
    size = SkyHorizonConfig().work_size_px
    for img in sorted((folder / "images").glob("*.jpg")):
        if not in_split(img.name, clips):
            continue
        rgb = cv2.cvtColor(cv2.imread(str(img)), cv2.COLOR_BGR2RGB)
        small = work_image(rgb, size)
        mask = cv2.imread(str(folder / "masks_land" / (img.stem + ".png")), cv2.IMREAD_GRAYSCALE)
        land = cv2.resize(mask, small.shape[1::-1], interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
        f = sky_features(small)
        f = f.reshape(-1, f.shape[-1])
        land = land.ravel()
        keep = (land < 0.1) | (land > 0.9)
        # half the samples within 6 work pixels of the boundary, where the line is decided
        near = cv2.dilate((np.abs(land.reshape(small.shape[:2]) - 0.5) < 0.4).astype(np.uint8), np.ones((13, 13))).ravel() > 0
        pick = np.concatenate([rng.choice(idx, size=min(pixels // 2, idx.size), replace=False)
                               for idx in (np.flatnonzero(keep & near), np.flatnonzero(keep & ~near)) if idx.size])
        xs.append(f[pick])
        ys.append((land[pick] < 0.5).astype(np.float64))
    return np.concatenate(xs).astype(np.float64), np.concatenate(ys)


def unpack(theta, d, hidden):
    ends = np.cumsum([d * hidden, hidden, hidden, 1])
    W1, b1, W2, b2 = np.split(theta[: ends[-1]], ends[:-1])
    return W1.reshape(d, hidden), b1, W2.reshape(hidden, 1), b2


def loss(theta, x, y, hidden, l2):
    W1, b1, W2, b2 = unpack(theta, x.shape[1], hidden)
    h = np.tanh(x @ W1 + b1)
    z = (h @ W2 + b2)[:, 0]
    p = 1.0 / (1.0 + np.exp(-z))
    n = len(y)
    ce = np.mean(np.logaddexp(0.0, z) - y * z)
    dz = (p - y)[:, None] / n
    gW2 = h.T @ dz
    gb2 = dz.sum(0)
    dh = (dz @ W2.T) * (1 - h * h)
    gW1 = x.T @ dh
    gb1 = dh.sum(0)
    grad = np.concatenate([gW1.ravel(), gb1, gW2.ravel(), gb2])
    return ce + 0.5 * l2 * (theta @ theta), grad + l2 * theta


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", type=Path, default=Path("../shared/data/horizon_uav"))
    ap.add_argument("--out", type=Path, default=Path("uareme_fusion/solver/weights/sky_mlp.npz"))
    ap.add_argument("--pixels", type=int, default=1500)
    ap.add_argument("--train", default="ab", help="clips (letters) or even / odd frames to train on")
    ap.add_argument("--test", default="c")
    ap.add_argument("--hidden", type=int, default=12)
    ap.add_argument("--l2", type=float, default=1e-4)
    a = ap.parse_args()
    rng = np.random.default_rng(0)
    x, y = samples(a.data, a.train, a.pixels, rng)
    mean, std = x.mean(0), x.std(0) + 1e-6
    xn = (x - mean) / std
    d = x.shape[1]
    theta = rng.normal(0, 0.3, d * a.hidden + 2 * a.hidden + 1)
    res = minimize(loss, theta, args=(xn, y, a.hidden, a.l2), jac=True, method="L-BFGS-B", options={"maxiter": 600})
    W1, b1, W2, b2 = unpack(res.x, d, a.hidden)

    def accuracy(xx, yy):
        z = (np.tanh(((xx - mean) / std) @ W1 + b1) @ W2 + b2)[:, 0]
        return float(np.mean((z > 0) == (yy > 0.5)))

    xc, yc = samples(a.data, a.test, a.pixels, np.random.default_rng(1))
    print(f"train ({a.train}) {len(y)} px: accuracy {accuracy(x, y):.4f}; "
          f"held out ({a.test}) {len(yc)} px: {accuracy(xc, yc):.4f}")
    np.savez(a.out, mean=mean.astype(np.float32), std=std.astype(np.float32), W1=W1.astype(np.float32),
             b1=b1.astype(np.float32), W2=W2.astype(np.float32), b2=b2.astype(np.float32))
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
