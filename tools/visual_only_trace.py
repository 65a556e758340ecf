"""Per-frame trace of a visual-only run (`eval` without an IMU): what the solver gave, what the backend did.

Runs `uareme-fusion eval SOURCE` with the given backend, normals and cues (the solver starts each frame
from the backend's prediction, as in `eval`), and saves per frame: the time, the visual `R_cm` and its
covariance, the backend's `R_wc`, covariance and status bits, and the reference `R_wc` (nearest in time).
`--replay FILE.npz` instead loads a saved trace and prints, per frame, the visual rotation's and the
estimate's error against the reference (after one constant alignment each), the innovation angle
between the estimate and the visual rotation (Manhattan symmetry resolved), and the status flags.

Usage:
  python tools/visual_only_trace.py SOURCE --backend mekf --normals learned --out trace.npz
  python tools/visual_only_trace.py --replay trace.npz [--rows 40]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from uareme_fusion.rotations import angle_between
from uareme_fusion.types import Status


class VisualTraceSink:
    """Keeps every frame's visual rotation and estimate."""

    def __init__(self):
        self.rows = []

    def write(self, result) -> None:
        v, e = result.visual, result.estimate
        nan3 = np.full((3, 3), np.nan)
        self.rows.append((result.t_s, nan3 if v is None else v.R_cm, nan3 if v is None else v.cov,
                          e.R_wc, e.cov, int(e.status)))

    def write_many(self, estimates) -> None:
        raise SystemExit("visual_only_trace: an IMU-only source has no frames to trace")

    def close(self) -> None:
        pass


def record(source: str, backend: str, normals: str, cues: str | None, out: Path) -> None:
    from uareme_fusion.drivers import open_source
    from uareme_fusion.pipeline import RunConfig
    from uareme_fusion.pipeline.session import configure_imu, run_source

    kwargs = dict(backend=backend, normals=normals)
    if cues:
        kwargs["cues"] = cues
    cfg = RunConfig(**kwargs)
    sink = VisualTraceSink()
    with tempfile.TemporaryDirectory() as tmp, open_source(source) as src:
        configure_imu(src, cfg)
        summary = run_source(src, Path(tmp), cfg, evaluate=True, extra_sinks=[sink], command="trace")
        truth = src.ground_truth()
        t = np.array([r[0] for r in sink.rows])
        R_true, _ = truth.at(t)
    print(f"ARE mean {summary['are_deg']['mean']:.2f}")
    np.savez(out, t_s=t, R_cm=np.array([r[1] for r in sink.rows]), cov_vis=np.array([r[2] for r in sink.rows]),
             R_wc=np.array([r[3] for r in sink.rows]), cov=np.array([r[4] for r in sink.rows]),
             status=np.array([r[5] for r in sink.rows]), R_wc_true=R_true)


def aligned_errors_deg(R_wc: np.ndarray, R_true: np.ndarray) -> np.ndarray:
    """Per-frame angle (deg) after one constant chordal alignment (`metrics.attitude_errors`)."""
    from uareme_fusion.scoring.metrics import attitude_errors

    ok = np.isfinite(R_wc).all(axis=(1, 2))
    err = attitude_errors(R_wc, np.tile(np.eye(3), (len(R_wc), 1, 1)), ok, R_true)
    return np.asarray(err["are_deg"])


def replay(path: Path, rows: int | None) -> None:
    from uareme_fusion.types import VisualRotation

    z = np.load(path)
    R_wc, R_cm, R_true = z["R_wc"], z["R_cm"], z["R_wc_true"]
    # The visual rotation labelled nearest the estimate (world = first Manhattan frame).
    R_vis = np.full_like(R_wc, np.nan)
    for k in range(len(R_wc)):
        if np.isfinite(R_cm[k]).all():
            R_vis[k] = VisualRotation(R_cm[k], np.eye(3), 0.0, 0, 1).symmetric_to(R_wc[k].T).R_cm.T
    e_est = aligned_errors_deg(R_wc, R_true)
    e_vis = aligned_errors_deg(R_vis, R_true)
    innov = np.full(len(R_wc), np.nan)
    seen = np.isfinite(R_vis).all(axis=(1, 2))
    innov[seen] = np.degrees(angle_between(R_wc[seen], R_vis[seen]))
    speed = np.r_[np.nan, np.degrees(angle_between(R_true[:-1], R_true[1:])) / np.diff(z["t_s"])]
    print(f"ARE mean: estimate {np.nanmean(e_est):.2f}, visual labelled at the estimate {np.nanmean(e_vis):.2f}")
    print(" k     t_s  speed_dps  err_est  err_vis  innov_deg  std_deg  flags")
    for k in range(len(R_wc) if rows is None else min(rows, len(R_wc))):
        flags = "|".join(f.name for f in Status if f and z["status"][k] & int(f))
        std = np.degrees(np.sqrt(np.trace(z["cov"][k])))
        print(f"{k:3d} {z['t_s'][k] - z['t_s'][0]:7.3f} {speed[k]:9.1f} {e_est[k]:8.2f} {e_vis[k]:8.2f} "
              f"{innov[k]:9.2f} {std:8.2f}  {flags}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("source", nargs="?")
    p.add_argument("--backend", default="mekf")
    p.add_argument("--normals", default="learned")
    p.add_argument("--cues", default=None)
    p.add_argument("--out", type=Path)
    p.add_argument("--replay", type=Path)
    p.add_argument("--rows", type=int)
    a = p.parse_args()
    if a.replay:
        replay(a.replay, a.rows)
    else:
        record(a.source, a.backend, a.normals, a.cues, a.out)


if __name__ == "__main__":
    main()
