"""Rendering speed of the synthetic scenes: frames per second at a given size (target: room at
320x240 >= 30 frames/s on the 2-core development machine). Prints the median over repeats.

    python tools/bench_render.py [--scenes room office corridor street bus] [--size 320x240] [--frames 30]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from uareme_fusion.sim.render import Renderer, intrinsics_from_fov
from uareme_fusion.sim.scenarios import build_scenario

TARGET_FPS = 30.0


def bench(scenario: str, width: int, height: int, frames: int, repeats: int) -> float:
    world = build_scenario(scenario, 10.0, seed=0)
    renderer = Renderer(world.scene, intrinsics_from_fov(width, height, world.spec.hfov_deg), width, height)
    times = np.linspace(0.0, 10.0, frames)
    world.render_radiance(renderer, 0.0)  # warm-up
    per_frame = []
    for _ in range(repeats):
        start = time.perf_counter()
        for t in times:
            radiance = world.render_radiance(renderer, t)[0]
            Renderer.to_uint8(radiance)
        per_frame.append((time.perf_counter() - start) / frames)
    return float(np.median(per_frame))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["room", "office", "corridor", "street", "bus"])
    parser.add_argument("--size", default="320x240")
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.lower().split("x"))
    print(f"render benchmark at {width}x{height}, {args.frames} frames x {args.repeats} repeats (median)")
    for scenario in args.scenes:
        seconds = bench(scenario, width, height, args.frames, args.repeats)
        fps = 1.0 / seconds
        print(f"{scenario:10s} {seconds * 1e3:7.1f} ms/frame {fps:7.1f} frames/s "
              f"({fps / TARGET_FPS:.2f} x the {TARGET_FPS:.0f} frames/s target)")


if __name__ == "__main__":
    main()
