"""Why the visual-only filters do not beat `single` on the real ICSL corridor (issue 12: "no backend may
be worse than `single` on a real sequence"); the figures behind the answer.

On the sequences `bench horizon` scores its backends on (ICSL-more against its chained depth-normal
rotations, ICL kt3 against its ground truth; RGB only, no IMU), prints:
- each filter's per-frame ARE minus `single`'s: the mean with its 95 % block-bootstrap interval
  (`evaluation/paired_difference.py`), its correlation with the reference's angular speed and its
  mean per speed quartile (lag in turns would grow with speed), its lag-one autocorrelation;
- the second differences `D_k` of the frame rotations (what `VisualNoiseShare` reads as independent
  error): their power for `single` and for the reference, and the power the two share (the camera's
  own motion; the reference's errors are independent of the RGB rotations'), along the motion and
  across it; with `--by-cue` also for the rotations from lines alone (no network, which learned from
  ICSL depth) and from the normals alone;
- the visual-only EKF's ARE with the noise share held fixed, over a grid of shares and angular-rate
  random walks: the best any such setting reaches against `single`.

Usage: python tools/backend_gap.py [--data ../shared/data] [--by-cue] [--cache FILE.pkl]
"""

from __future__ import annotations

import argparse
import pickle
import sys
from pathlib import Path

import numpy as np

from uareme_fusion.backends.visual_noise_share import VisualNoiseShare
from uareme_fusion.benchmarks.horizon import (backend_errors, backend_rows, icsl_more_reference, real_sequences,
                                              rgb_sequence)
from uareme_fusion.backends.factory import make_backend
from uareme_fusion.evaluation.compare import errors_over_time, run_backend
from uareme_fusion.rotations import log_so3

CUES = "normals,lines"
SHARES = (0.01, 0.02, 0.05, 0.1, 0.3, 1.0)
RATE_WALKS_RAD_S2_SQRT_HZ = (0.3, 1.0, 3.0, 10.0, 30.0)


class FixedShare(VisualNoiseShare):
    """A noise share that stays at `share` whatever the frames show."""

    def __init__(self, share: float):
        super().__init__(frames=1.0)
        self.share = float(share)

    def _update_share(self, t_s, visual) -> None:
        """The frames leave the share as it is (`persistent_cov` still follows them)."""


def sequences(data: Path, by_cue: bool) -> dict:
    """name -> `VisualSequence` with a reference, as `bench horizon` builds them (and ICSL-more by cue)."""
    reference = icsl_more_reference(data)
    real = real_sequences(data, CUES, reference)
    out = {name: real[name][0] for name in ("ICSL more", "ICL kt3")}
    if by_cue:
        for cues in ("lines", "normals"):
            out[f"ICSL more, {cues} only"] = rgb_sequence(data / "icsl_corridor_more" / "rgb", cues, reference)[0]
    return out


def steps_rad(R_wc: np.ndarray) -> np.ndarray:
    """(N - 1, 3) rotation vectors of each frame's rotation since the previous one, camera frame."""
    return np.array([log_so3(R_wc[k].T @ R_wc[k + 1]) for k in range(len(R_wc) - 1)])


def deg2(x) -> float:
    return float(np.degrees(np.degrees(x)))


def frame_differences(name: str, seq) -> None:
    errors, notes = backend_errors(seq)
    rows = backend_rows(errors, notes)
    are = {b: err["are_deg"] for b, err in errors.items()}
    speed = np.r_[np.nan, np.degrees(np.linalg.norm(steps_rad(seq.R_wc_true), axis=1))]
    ok = np.isfinite(speed)
    quartiles = np.quantile(speed[ok], [0, 0.25, 0.5, 0.75, 1.0])
    print(f"{name}: ARE mean single {rows['single']['are_mean_deg']:.5f} deg")
    for b in ("mekf", "smoother"):
        d = are[b] - are["single"]
        vs = rows[b]["are_vs_single_deg"]
        by_speed = [np.mean(d[ok & (speed >= lo) & (speed <= hi)]) for lo, hi in zip(quartiles[:-1], quartiles[1:])]
        print(f"  {b}: ARE {rows[b]['are_mean_deg']:.5f}; minus single {vs['mean']:+.5f} deg (95 % {vs['low']:+.5f} .. "
              f"{vs['high']:+.5f}), per-frame std {d.std():.4f}, lag-one corr {np.corrcoef(d[:-1], d[1:])[0, 1]:+.2f}, "
              f"corr with speed {np.corrcoef(d[ok], speed[ok])[0, 1]:+.2f}; by speed quartile "
              + " ".join(f"{x:+.4f}" for x in by_speed))


def second_differences(name: str, seq) -> None:
    R_single = np.array([e.R_wc for e in run_backend(make_backend("single"), seq).estimates])
    v_s, v_r = steps_rad(R_single), steps_rad(seq.R_wc_true)
    D_s, D_r = v_s[1:] - v_s[:-1], v_r[1:] - v_r[:-1]
    along = 0.5 * (v_r[1:] + v_r[:-1])
    along /= np.linalg.norm(along, axis=1, keepdims=True)
    shared = np.mean(np.sum(D_s * D_r, 1))
    shared_along = np.mean(np.sum(D_s * along, 1) * np.sum(D_r * along, 1))
    trace_c = np.mean([np.trace(v.cov) for v in seq.visuals if v is not None])
    print(f"{name}: |D|^2 single {deg2(np.mean(np.sum(D_s**2, 1))):.3f}, reference {deg2(np.mean(np.sum(D_r**2, 1))):.3f},"
          f" shared {deg2(shared):.3f} deg^2 (along the motion {deg2(shared_along):.3f}, across it "
          f"{deg2(shared - shared_along) / 2:.3f} per axis); lag-one <D_k, D_k-1> single "
          f"{deg2(np.mean(np.sum(D_s[1:] * D_s[:-1], 1))):+.3f} deg^2; frames' tr C {deg2(trace_c):.3f} deg^2")


def share_grid(name: str, seq) -> None:
    single = np.mean(errors_over_time(run_backend(make_backend("single"), seq), seq.R_wc_true)["are_deg"])
    best = (np.inf, None)
    print(f"{name}: EKF ARE with the share held fixed (rows) and rate walk rad/s^2/sqrt(Hz) (columns "
          f"{', '.join(f'{q:g}' for q in RATE_WALKS_RAD_S2_SQRT_HZ)}); single {single:.5f}")
    for share in SHARES:
        row = []
        for q in RATE_WALKS_RAD_S2_SQRT_HZ:
            backend = make_backend("mekf", overrides={"rate_rw_rad_s2_sqrt_hz": q})
            backend.noise_share = FixedShare(share)
            are = float(np.mean(errors_over_time(run_backend(backend, seq), seq.R_wc_true)["are_deg"]))
            row.append(are)
            best = min(best, (are, (share, q)))
        print(f"  share {share:4.2f}: " + " ".join(f"{a:.5f}" for a in row))
    print(f"  best {best[0]:.5f} (share {best[1][0]:g}, rate walk {best[1][1]:g}): {best[0] - single:+.5f} deg vs single")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2] / "shared" / "data")
    parser.add_argument("--by-cue", action="store_true", help="also ICSL-more from lines alone and normals alone")
    parser.add_argument("--cache", type=Path, help="pickle of the sequences: read when it exists, else written")
    args = parser.parse_args(argv)
    if args.cache and args.cache.exists():
        with open(args.cache, "rb") as f:
            seqs = pickle.load(f)
    else:
        seqs = sequences(args.data, args.by_cue)
        if args.cache:
            with open(args.cache, "wb") as f:
                pickle.dump(seqs, f)
    for name in ("ICSL more", "ICL kt3"):
        frame_differences(name, seqs[name])
    for name, seq in seqs.items():
        second_differences(name, seq)
    for name in ("ICSL more", "ICL kt3"):
        share_grid(name, seqs[name])
    return 0


if __name__ == "__main__":
    sys.exit(main())
