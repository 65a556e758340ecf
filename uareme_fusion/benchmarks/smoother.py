"""Benchmark of the GTSAM smoother (issue 6 numbers).

1. Accuracy: gyro-aided vs paper mode (and single) ARE on the simulator's handheld (`walk`) and
   `shake` scenarios, 5 seeds each, with dropped and random-normal frames (`compare.synthetic_sequence`).
2. Latency: ms per frame at window 30 (median and p95) for both modes, measured on the same runs
   (IMU preintegration + graph update + marginal covariance).

Usage: uareme-fusion bench smoother [--seeds 5]
Timings are wall clock on a shared machine: report the median.
"""

from __future__ import annotations

import numpy as np

from ..evaluation.compare import make_backends, run_backend, summarise
from ..evaluation.sequence import synthetic_sequence
from ..scoring.statistics import error_stats


def run(seeds: int = 5, duration_s: float = 20.0, scenarios=("walk", "shake")) -> dict:
    """Print the table and the latencies; returns mean ARE (deg) per scenario and backend and the
    latency statistics (ms) per backend."""
    names = ("single", "smoother", "smoother-gyro")
    latency = {n: [] for n in names}
    figures = {"are_deg_mean": {}, "latency_ms": {}}
    print("per backend: mean ARE deg (max ARE deg, frames with ARE > 10 deg)")
    print(f"{'scenario':8s} {'seed':>4s} " + " ".join(f"{n:>22s}" for n in names) + "   gyro/paper")
    for scenario in scenarios:
        means = {n: [] for n in names}
        for seed in range(seeds):
            seq = synthetic_sequence(scenario, seed=seed, duration_s=duration_s)
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
        figures["are_deg_mean"][scenario] = {n: float(np.mean(means[n])) for n in names}
        wins = sum(g < p for g, p in zip(means["smoother-gyro"], means["smoother"]))
        print(f"{scenario:8s} mean " + " ".join(f"{np.mean(means[n]):22.2f}" for n in names)
              + f"   gyro beats paper on {wins}/{seeds} seeds")
    print("\nlatency per frame (ms, window 30; IMU + update + marginal covariance):")
    for n in names:
        lat = figures["latency_ms"][n] = error_stats(latency[n], ("median", "p95", "max"))
        print(f"  {n:14s} median {lat['median']:6.2f}  p95 {lat['p95']:6.2f}  "
              f"max {lat['max']:6.2f}  ({len(latency[n])} frames; goal <= 5 ms: "
              f"{'met' if lat['median'] <= 5.0 else 'NOT met'} at the median)")
    return figures
