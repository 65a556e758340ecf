"""Where the RGB error on TUM fr1 rpy comes from: the network's normals, up-axis flips between Manhattan
axes, or the stream's following. Run on the TRAINING split (the evaluation split only to report).

`cache` reads a TUM folder once: per frame the network's raw output (4, 120, 160), the line segments, the
sky boundary, the depth normals' own solve (no prior) and the mocap `R_wc`; `report` then prints, from the
cache alone:
- the Manhattan frame in the mocap world `R_wm` (the chordal mean of `R_wc_true R_cm_depth` over the frames,
  each labelled nearest the first), so that each frame's true `R_cm = R_wc_true^T R_wm`;
- per frame, for the depth solve, the RGB solve alone (no prior; normals + lines + sky as `eval` runs it) and
  the RGB normals alone: the error modulo the 24 Manhattan relabellings (what the frame's own evidence
  gets right) and the frames within 10 deg of it (`--good-deg`);
- the error of the network's normals against the depth normals, and of the image rotation between frames
  (`solver/frame_motion.py`) against the mocap;
- the stream's ARE with each frame's own RGB solve labelled by three rules: nearest the previous frame (the
  rule before `backends/labelling_track.py`), the track without and with the image rotation, and the frames
  whose ARE exceeds 10 deg but whose best labelling does not (a flip, not a wrong frame).

Usage:
  python tools/tum_rgb_diagnosis.py cache --data /work/data/rgbd_dataset_freiburg1_rpy_train --out /tmp/tum_train.pkl
  python tools/tum_rgb_diagnosis.py report --cache /tmp/tum_train.pkl
"""

from __future__ import annotations

import argparse
import pickle
import sys
import time

import numpy as np

from uareme_fusion.rotations import nearest_symmetric, project_to_so3


def cache(data: str, out: str, model: str | None, max_frames: int | None) -> None:
    """Read `data` once into the pickle `out` (see the module docstring)."""
    from uareme_fusion.drivers import open_source
    from uareme_fusion.solver.line_detection import SegmentDetector
    from uareme_fusion.normals.depth import depth_normals_for
    from uareme_fusion.normals.learned import LearnedNormals, LearnedNormalsConfig
    from uareme_fusion.solver import solve_manhattan
    from uareme_fusion.solver.sky_horizon import SkyDetector
    from uareme_fusion.types import Frame

    from uareme_fusion.solver.frame_motion import FrameMotion

    learned = LearnedNormals(model, LearnedNormalsConfig(threads=1))
    detector, sky, motion = SegmentDetector(), SkyDetector(), FrameMotion()
    rows = []
    t0 = time.time()
    with open_source(data) as source:
        depth = depth_normals_for(source.info)
        truth = source.ground_truth()
        for event in source.events():
            if not isinstance(event, Frame):
                continue
            R_true, in_span = truth.at(np.array([event.t_s]))
            row = {"t_s": event.t_s, "index": event.index, "K": event.K, "R_wc_true": R_true[0] if in_span[0] else None,
                   "net": learned.infer(event.rgb).astype(np.float16), "segments": detector.detect(event.rgb),
                   "sky": sky.detect(event.rgb), "R_cm_depth": None, "depth_small": None,
                   "step": motion.step(event.t_s, event.rgb, event.K)}
            if event.depth is not None:
                nm = depth.estimate_frame(event)
                try:
                    row["R_cm_depth"] = solve_manhattan(nm).R_cm
                except Exception:  # noqa: BLE001 - a frame without valid depth normals
                    pass
                row["depth_small"] = (nm.normals[2::4, 2::4].astype(np.float16), nm.kappa[2::4, 2::4].astype(np.float16))
            rows.append(row)
            if len(rows) % 50 == 0:
                print(f"{len(rows)} frames, {time.time() - t0:.0f} s", file=sys.stderr)
            if max_frames and len(rows) >= max_frames:
                break
    with open(out, "wb") as f:
        pickle.dump(rows, f)


def manhattan_in_world(rows: list) -> np.ndarray:
    """`R_wm`: the chordal mean of `R_wc_true @ R_cm_depth` over the frames with both, each relabelled
    nearest the running mean (the depth solves' labellings differ by the 24 symmetries)."""
    pairs = [r["R_wc_true"] @ r["R_cm_depth"] for r in rows if r["R_wc_true"] is not None and r["R_cm_depth"] is not None]
    ref = pairs[0]
    for _ in range(3):
        ref = project_to_so3(sum(nearest_symmetric(R, ref)[0] for R in pairs))
    return ref


def angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    c = (np.trace(R_a.T @ R_b) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def modulo_symmetry_deg(R_cm: np.ndarray, R_cm_true: np.ndarray) -> float:
    """The angle from `R_cm_true` to the nearest relabelling of `R_cm`."""
    return angle_deg(nearest_symmetric(R_cm, R_cm_true)[0], R_cm_true)


class CachedCues:
    """A `CueSolver` whose segments and sky come from the cache (frame index -> row)."""

    def __init__(self, rows: list, lines: bool = True, sky: bool = True):
        from uareme_fusion.solver.cues import CueSolver

        self.rows = {r["index"]: r for r in rows}
        self.solver = CueSolver(lines=lines, sky=sky, image_normals=False)  # the cache holds no image
        if lines:
            self.solver.detector = _Lookup(self.rows, "segments")
        if sky:
            self.solver.sky = _Lookup(self.rows, "sky")

    def solve(self, row: dict, normal_map, R_init=None):
        from uareme_fusion.types import Frame

        _Lookup.current = row["index"]
        frame = Frame(row["t_s"], rgb=np.zeros((480, 640, 3), np.uint8), K=row["K"], index=row["index"])
        return self.solver.solve(frame, normal_map, R_init)


class _Lookup:
    current = -1

    def __init__(self, rows: dict, key: str):
        self.rows, self.key = rows, key

    def detect(self, rgb):
        return self.rows[_Lookup.current][self.key]


def network_map(row: dict, kappa_cap: float = 75.0):
    """The network's normal map of a cached row, as `LearnedNormals` (at the network's size) and
    `CappedNormals` give it."""
    from uareme_fusion.normals.learned import LearnedNormalsConfig
    from uareme_fusion.types import NormalMap

    out = row["net"].astype(np.float32)
    hwc = out.transpose(1, 2, 0)
    normals, kappa = hwc[..., :3], hwc[..., 3]
    norm = np.linalg.norm(normals, axis=-1, keepdims=True)
    normals = (normals / np.maximum(norm, 1e-6)).astype(np.float32)
    kappa = np.clip(kappa, 0.0, kappa_cap).astype(np.float32)
    return NormalMap(normals, kappa, t_s=row["t_s"], independent_regions=LearnedNormalsConfig().independent_regions)


def pixel_error_deg(row: dict, min_depth_kappa: float = 50.0) -> float:
    """Mean angle (deg) between the network's normals and the depth normals (kappa >= `min_depth_kappa`)."""
    if row["depth_small"] is None:
        return float("nan")
    import cv2

    n_d, k_d = (a.astype(np.float32) for a in row["depth_small"])
    net = network_map(row)
    n_l = cv2.resize(net.normals, (n_d.shape[1], n_d.shape[0]), interpolation=cv2.INTER_LINEAR)
    ok = k_d >= min_depth_kappa
    if not ok.any():
        return float("nan")
    c = np.abs(np.einsum("ij,ij->i", n_l[ok], n_d[ok]) / np.maximum(np.linalg.norm(n_l[ok], axis=1), 1e-6))
    return float(np.degrees(np.arccos(np.clip(c, -1, 1))).mean())


def solves(rows: list) -> list:
    """Per frame: the RGB visual rotation (normals + lines + sky as `eval` runs them) solved alone, no prior,
    with the cached image rotation since the previous frame (`VisualRotation.R_cp`)."""
    import dataclasses

    solver = CachedCues(rows)
    out = []
    for row in rows:
        visual = solver.solve(row, network_map(row), None)
        step = row.get("step")
        out.append(visual if step is None else dataclasses.replace(visual, R_cp=step.R_cp, R_cp_std_rad=step.std_rad))
    return out


def labelled(visuals: list, t_s: np.ndarray, rule: str) -> np.ndarray:
    """The stream's `R_cm` (N, 3, 3) under a labelling `rule`: "previous" (nearest the previous frame, the
    rule before the track), "track" (`LabellingTrack` without the image rotation), "track+motion" (with it),
    "track+motion (the track itself)": the track's own rotation instead of each frame's (a filter's answer)."""
    import dataclasses

    from uareme_fusion.backends.labelling_track import LabellingTrack

    track, out = LabellingTrack(), []
    for t, v in zip(t_s, visuals):
        if rule == "previous":
            out.append(v.R_cm if not out else nearest_symmetric(v.R_cm, out[-1])[0])
            continue
        v = v if rule.startswith("track+motion") else dataclasses.replace(v, R_cp=None)
        R_cm = track.label(t, v).R_cm
        out.append(track.R_cm if rule.endswith("(the track itself)") else R_cm)
    return np.array(out)


def report(path: str, good_deg: float) -> None:
    from uareme_fusion.rotations import align_constant, are_deg

    with open(path, "rb") as f:
        rows = [r for r in pickle.load(f) if r["R_wc_true"] is not None]
    R_wm = manhattan_in_world(rows)
    truth = [r["R_wc_true"].T @ R_wm for r in rows]
    R_wc_true = np.array([r["R_wc_true"] for r in rows])
    t_s = np.array([r["t_s"] for r in rows])

    def line(name: str, errs) -> None:
        e = np.asarray([x for x in errs if np.isfinite(x)])
        print(f"{name:<52} mean {e.mean():6.2f}  median {np.median(e):6.2f}  p90 {np.percentile(e, 90):6.2f}  "
              f"<= {good_deg:g} deg: {100 * np.mean(e <= good_deg):5.1f} % of {len(e)}")

    line("depth normals alone, modulo relabelling", [modulo_symmetry_deg(r["R_cm_depth"], T) if r["R_cm_depth"] is not None
                                                      else np.nan for r, T in zip(rows, truth)])
    line("network normals vs depth normals (pixels, deg)", [pixel_error_deg(r) for r in rows])
    line("image rotation between frames vs mocap (deg)", [angle_deg(r["step"].R_cp, r["R_wc_true"].T @ p["R_wc_true"])
                                                          for p, r in zip(rows, rows[1:]) if r.get("step") is not None])
    visuals = solves(rows)
    mod = np.array([modulo_symmetry_deg(v.R_cm, T) for v, T in zip(visuals, truth)])
    line("RGB alone, modulo relabelling (best labelling)", mod)
    std = np.array([np.degrees(np.sqrt(np.trace(v.cov))) for v in visuals])
    low = std <= np.median(std)
    print(f"    its median in the lower / upper half of the reported std: {np.median(mod[low]):.2f} / {np.median(mod[~low]):.2f}")
    for rule in ("previous", "track", "track+motion", "track+motion (the track itself)"):
        R_wc = np.swapaxes(labelled(visuals, t_s, rule), 1, 2)
        A = align_constant(R_wc, R_wc_true)
        are = are_deg(A @ R_wc, R_wc_true, align=False)
        flips = (are > good_deg) & (mod <= good_deg)
        line(f"RGB stream labelled {rule}: ARE", are)
        print(f"    frames with ARE > {good_deg:g} but right in their best labelling (a flip): {int(flips.sum())}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("cache")
    c.add_argument("--data", required=True)
    c.add_argument("--out", required=True)
    c.add_argument("--model", default=None)
    c.add_argument("--max-frames", type=int, default=None)
    r = sub.add_parser("report")
    r.add_argument("--cache", required=True)
    r.add_argument("--good-deg", type=float, default=10.0)
    args = ap.parse_args()
    if args.cmd == "cache":
        cache(args.data, args.out, args.model, args.max_frames)
    else:
        report(args.cache, args.good_deg)


if __name__ == "__main__":
    main()
