"""`bench normals`: the shipped network on torch and on ONNX Runtime, on real development images.

Per engine: the median and p90 ms of one map (`LearnedNormals.infer`: resize to the network's 160x120 and
the two passes of the mirror average, `LearnedNormalsConfig.mirror_average`, one thread), over the ICL-NUIM
kt3, ICSL corridor and ECD images; and the largest difference of the two engines' normals and kappa (the
ONNX path must match torch within 1e-4). The faster engine on this CPU is what `engine: auto` should pick
(`LearnedNormalsConfig.engine`).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..formats.images import read_rgb
from ..normals.learned import LearnedNormals, LearnedNormalsConfig
from ..normals.onnx_model import onnxruntime_available

REPEATS = 10
"""Timed passes per image and engine (after one untimed pass)."""


def dev_images(data_dir: Path) -> list[Path]:
    """A few real images of each development set under `data_dir`."""
    found = []
    for folder, pattern in (("icl_nuim_office_kt3/rgb", "*.png"), ("icsl_corridor/rgb", "*.png"),
                            ("eurasian_cities", "*.jpg")):
        found += sorted((data_dir / folder).glob(pattern), key=lambda p: (len(p.name), p.name))[:4]
    if not found:
        raise InputError(f"--data {data_dir}: no ICL-NUIM, ICSL or ECD images there (see shared/data/README.md)")
    return found


def run(data_dir: Path, threads: int | None = None) -> dict:
    """Print and return each engine's ms per map and the engines' largest differences."""
    if not onnxruntime_available():
        raise InputError("bench normals compares torch with ONNX Runtime: pip install 'uareme-fusion[onnx]'")
    images = [read_rgb(p) for p in dev_images(Path(data_dir))]
    engines = {name: LearnedNormals(config=LearnedNormalsConfig(engine=name, threads=threads or 1))
               for name in ("torch", "onnx")}
    figures = {"images": len(images), "threads": threads or 1}
    print(f"the shipped network on {len(images)} real images (160x120 input, {threads or 1} thread)")
    for name, estimator in engines.items():
        times_ms = []
        for rgb in images:
            estimator.infer(rgb)
            for _ in range(REPEATS):
                t0 = time.perf_counter()
                estimator.infer(rgb)
                times_ms.append(1e3 * (time.perf_counter() - t0))
        figures[name] = {"median_ms": float(np.median(times_ms)), "p90_ms": float(np.percentile(times_ms, 90))}
        print(f"{name:6s} median {figures[name]['median_ms']:6.2f} ms, p90 {figures[name]['p90_ms']:6.2f} ms")
    normals_diff, kappa_rel = 0.0, 0.0
    for rgb in images:
        a, b = (e.estimate(rgb) for e in engines.values())
        normals_diff = max(normals_diff, float(np.abs(a.normals - b.normals).max()))
        kappa_rel = max(kappa_rel, float((np.abs(a.kappa - b.kappa) / np.maximum(a.kappa, 1e-6)).max()))
    figures.update(speedup=figures["torch"]["median_ms"] / figures["onnx"]["median_ms"],
                   max_normal_diff=normals_diff, max_kappa_rel_diff=kappa_rel)
    print(f"onnx is {figures['speedup']:.2f}x torch's speed; largest difference: normals {normals_diff:.1e}, "
          f"kappa {kappa_rel:.1e} relative (goal <= 1e-4)")
    return figures
