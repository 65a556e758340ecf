"""Benchmark of the GTSAM smoother (issue 6 numbers).

1. Accuracy: gyro-aided vs paper mode (and single) ARE on the simulator's handheld (`walk`) and
   `shake` scenarios, 5 seeds each, with dropped and random-normal frames (`compare.synthetic_sequence`).
2. Latency: ms per frame at window 30 (median and p95) for both modes, measured on the same runs
   (IMU preintegration + graph update + marginal covariance).

Usage: python tools/bench_smoother.py [--seeds 5] [--duration-s 20] [--scenarios walk shake]
Timings are wall clock on a shared machine: report the median.
"""

from __future__ import annotations

import argparse

import numpy as np

from uareme_fusion.evaluation.compare import make_backends, run_backend, summarise
from uareme_fusion.evaluation.sequence import synthetic_sequence


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--duration-s", type=float, default=20.0)
    parser.add_argument("--scenarios", nargs="+", default=["walk", "shake"])
    args = parser.parse_args()
    names = ("single", "smoother", "smoother-gyro")
    latency = {n: [] for n in names}
    print("per backend: mean ARE deg (max ARE deg, frames with ARE > 10 deg)")
    print(f"{'scenario':8s} {'seed':>4s} " + " ".join(f"{n:>22s}" for n in names) + "   gyro/paper")
    for scenario in args.scenarios:
        means = {n: [] for n in names}
        for seed in range(args.seeds):
            seq = synthetic_sequence(scenario, seed=seed, duration_s=args.duration_s)
            backends, _ = make_backends(names)
            rows = {}
            for n in names:
                run = run_backend(backends[n], seq)
                latency[n] += run.latency_ms
                rows[n] = summarise(run, seq.R_wc_true)
                means[n].append(rows[n]["are_deg_mean"])
            ratio = rows["smoother-gyro"]["are_deg_mean"] / rows["smoother"]["are_deg_mean"]
            print(f"{scenario:8s} {seed:4d} " + " ".join(
                f"{rows[n]['are_deg_mean']:8.2f} ({rows[n]['are_deg_max']:5.1f}, {rows[n]['frames_are_over_10deg']:3d})"
                for n in names)
                + f"   {ratio:.2f}")
        wins = sum(g < p for g, p in zip(means["smoother-gyro"], means["smoother"]))
        print(f"{scenario:8s} mean " + " ".join(f"{np.mean(means[n]):22.2f}" for n in names)
              + f"   gyro beats paper on {wins}/{args.seeds} seeds")
    print("\nlatency per frame (ms, window 30; IMU + update + marginal covariance):")
    for n in names:
        lat = np.asarray(latency[n])
        print(f"  {n:14s} median {np.median(lat):6.2f}  p95 {np.percentile(lat, 95):6.2f}  "
              f"max {lat.max():6.2f}  ({lat.size} frames; goal <= 5 ms: "
              f"{'met' if np.median(lat) <= 5.0 else 'NOT met'} at the median)")


if __name__ == "__main__":
    main()
