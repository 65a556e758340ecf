"""Real-image accuracy of the RGB-only estimate: ECD horizons, ICSL and ICL-NUIM rotations, focal lengths.
Open country (horizon_uav) and whether indoor frames keep their horizon: `benchmarks/horizon_uav.py`
(`bench horizon --uav-only` for those rows alone).

Each figure is printed beside its goal (issue 12) and its baseline:
- ECD (Eurasian Cities, Barinova et al. 2010; academic use): horizon error = the largest vertical
  distance between the estimated and true horizon lines over the image width, divided by the image
  height; AUC of its cumulative distribution up to 0.25, in %. Baseline: a level camera (the
  horizon through the image centre). Also on the odd- and even-numbered images apart (NNN.jpg):
  tune a parameter on one half, report the other, so that 103 images are not overfitted.
- ICSL corridor (LPVO repository, MIT): the RGB-only rotation against the depth-normal rotation of
  the same frame (with the published intrinsics), after the 24-fold Manhattan symmetry; NEES of the
  RGB-only covariance against it; the estimated horizontal FOV against fx = 537.6. Twice: without
  intrinsics (focal length from the lines, principal point at the image centre), and with the
  intrinsics the dataset publishes (`--camera`; the principal point is 3 px left of and 6 px below
  the centre, which a single frame cannot tell).
  The reference takes an inverse-depth offset of 0.014 / m off the depth first (z = 1 / (1 / z_png -
  0.014); 3.0 m reads 2.88 m): the offset a structured-light sensor's disparity calibration leaves
  (its depth is 1 / (a d + b) of the disparity d; an error in b), fitted from the depth alone. Checked on
  110 frames with `tools/check_icsl_reference.py`, no RGB estimate taking part:
  - the depth is registered to the colour image: depth jumps sit on colour edges best at a shift of
    (-1, -1) px, a scale of 1.00 and a radial k1 of +0.025, 0 next (searched +-12 px, 0.98-1.02,
    k1 -0.15..0.15), so it has the colour camera's pixels and K;
  - an offset b tilts a plane at distance d by about b d towards the optical axis, so parallel planes
    (left and right walls, floor and ceiling) stop being parallel; no K can do that (a K maps space
    linearly: parallel planes stay parallel), so this fits b alone. Whole planes fitted in each frame
    (trimmed least squares): parallel pairs are 2.92 deg apart (median 2.41) as read, 1.82 (1.28) with
    0.014 / m taken off, 2.02 (1.46) at 0.02; perpendicular pairs barely move (median 0.92 -> 0.87).
    Each folder alone has its best there too (means 2.58 -> 1.48 and 3.36 -> 2.27; worse at 0.01, 0.02);
  - f and the principal point cannot be fitted from the depth's Manhattan-ness: what is left of its
    distortion (parallel planes 1.3 deg apart) dominates, and fits ran to f 445 px. In the 35 frames
    turned 12+ deg from the corridor, where f sets the walls' angle, the walls meet at 90 deg best for
    f 520 px as read and for f 505 px or less with the offset taken off (2.4 deg off 90 at 537.6), while
    the lines pool f at 557-563 px: the published 537.6 is kept;
  - the rotation also moves with the plane-fit window (on the depth as read, 9 px is 1.5 deg per frame
    from 21 px; from 15 px on, steps of 0.1 deg), but no window's axes are nearer the whole-plane
    fits (1.6 deg pixel-weighted at every window), so `DepthNormals`' default 9 px is kept.
  Before the offset was taken off: per image 2.29 deg, K given 1.80 (NEES 78.7), K pooled 2.16.
- ICL-NUIM kt3 (Handa et al. 2014, CC BY 3.0): `eval` ARE and NEES of the RGB-only single-frame
  backend; the estimated FOV against fx = 481.2.
- Backends on real sequences, RGB only (no IMU): `single`, `mekf` and `smoother` on the same
  per-frame visual rotations (`evaluation.compare`), ARE and NEES on ICL kt3 (ground truth) and on
  `icsl_corridor_more` (the depth-normal rotations as the reference, their Manhattan symmetry chained
  frame to frame); goal: no backend worse than `single` (ARE mean). Beside each, the mean of the
  per-frame ARE differences from `single` with its 95 % block-bootstrap interval
  (`evaluation/paired_difference.py`): on the same frames the backends differ by thousandths of a
  degree, far less than the frames' errors vary.
"""

from __future__ import annotations

import functools
import math
import time
from pathlib import Path

import numpy as np
import scipy.io
from rich.console import Console
from rich.table import Table

from ..errors import InputError
from ..formats.datasets import ICL_NUIM_K_OPENCV, ICSL_CORRIDOR_K, read_icsl_depth
from ..formats.images import natural_key
from ..pinhole import focal_from_hfov
from ..rotations import log_so3, nearest_symmetric
from ..scoring.horizon import horizon_error
from .realdata import BACKENDS

AUC_CUTOFF = 0.25
CPU_TIME_NOTE = "CPU: what a photo costs on an idle core (process time); wall grows with the machine's load"
ICSL_FX = float(ICSL_CORRIDOR_K[0, 0])
ICL_FX = float(ICL_NUIM_K_OPENCV[0, 0])
ICL_CENTRE = (float(ICL_NUIM_K_OPENCV[0, 2]), float(ICL_NUIM_K_OPENCV[1, 2]))


def auc_percent(errors, cutoff: float = AUC_CUTOFF) -> float:
    """Area under the cumulative error curve on [0, cutoff], divided by cutoff, in %."""
    e = np.sort(np.asarray(errors, float))
    grid = np.linspace(0.0, cutoff, 2001)
    cdf = np.searchsorted(e, grid, side="right") / len(e)
    return float(100.0 * np.trapezoid(cdf, grid) / cutoff)


def parity_auc_percent(names: list[str], errors) -> dict:
    """AUC (`auc_percent`) over the images whose number (the name's digits) is odd and even."""
    numbers = np.array([int("".join(ch for ch in name if ch.isdigit()) or "0") for name in names])
    errors = np.asarray(errors, float)
    return {f"auc_{half}_percent": auc_percent(errors[numbers % 2 == rest]) if np.any(numbers % 2 == rest)
            else float("nan") for half, rest in (("odd", 1), ("even", 0))}


def level_horizon(height: int, width: int) -> np.ndarray:
    """The horizon of a level camera: y = (height - 1) / 2, sky above."""
    return np.array([0.0, -1.0, (height - 1) / 2.0])


LABEL_FOCAL_MAX_STD = 0.05
"""ECD photos whose labels fix f to this relative std take part in the focal error (`label_focal`)."""
LABEL_HORIZON_STD_PX = 3.0
LABEL_ZENITH_STD_RAD = 0.0035
"""The label errors assumed: the labelled horizon's height (px) and the labelled zenith's direction
from the camera (rad, 0.2 deg: dozens of hand-labelled vertical lines)."""


def label_focal(path: Path, height: int, width: int, horizon: np.ndarray | None = None) -> tuple[float, float]:
    """(f px, its relative std) that an ECD photo's labels imply: the labelled zenith z (NNNVP.mat) and
    horizon (NNNhor.mat) are orthogonal VPs, f^2 = d_h d_z with d_h, d_z their distances from the image
    centre (principal point there, square pixels). The std from `LABEL_HORIZON_STD_PX` on d_h and
    `LABEL_ZENITH_STD_RAD` on z's direction (d_z moves by d_z^2 / f of it), halved, in quadrature; a
    horizon through the centre or a zenith near infinity leaves f open. `horizon`: the labelled line
    (a, b, c) when the caller has read NNNhor.mat already."""
    zenith = scipy.io.loadmat(path.with_name(path.stem + "VP.mat"))["zenith"].ravel()
    line = scipy.io.loadmat(path.with_name(path.stem + "hor.mat"))["horizon"].ravel() if horizon is None else horizon
    c = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    d_h = abs(float(line[:2] @ c + line[2])) / float(np.hypot(*line[:2]))
    d_z = float(np.linalg.norm(zenith - c))
    f = math.sqrt(d_h * d_z)
    return f, 0.5 * math.hypot(LABEL_HORIZON_STD_PX / max(d_h, 1e-9), LABEL_ZENITH_STD_RAD * d_z / f)


def focal_errors(label: list[tuple[float, float]], estimated: list[float]) -> dict:
    """Percent errors |f / f_label - 1| over the photos whose label fixes f (`LABEL_FOCAL_MAX_STD`):
    their number, median and 90th percentile."""
    e = np.array([100.0 * abs(f / fl - 1.0) for (fl, std), f in zip(label, estimated) if std <= LABEL_FOCAL_MAX_STD])
    if not len(e):
        return {"photos": 0, "median_percent": float("nan"), "p90_percent": float("nan")}
    return {"photos": int(len(e)), "median_percent": float(np.median(e)), "p90_percent": float(np.percentile(e, 90))}


def ecd_scores(folder: Path, analyser, limit: int | None = None) -> dict:
    """Horizon errors of `analyser` (an `ImageAnalyser`) and of the level camera on ECD."""
    images = sorted(folder.glob("*.jpg"))[:limit]
    if not images:
        raise InputError(f"{folder}: no ECD images (NNN.jpg with NNNhor.mat)")
    est, level, hfov, sources, ms, cpu_ms, f_label, f_est, f_assumed = [], [], [], [], [], [], [], [], []
    for path in images:
        truth = scipy.io.loadmat(path.with_name(path.stem + "hor.mat"))["horizon"].ravel()
        t0, c0 = time.perf_counter(), time.process_time()
        result = analyser.analyse(path)
        ms.append(1e3 * (time.perf_counter() - t0))
        cpu_ms.append(1e3 * (time.process_time() - c0))
        h, w = result.rgb.shape[:2]
        est.append(horizon_error(result.horizon, truth, h, w))
        level.append(horizon_error(level_horizon(h, w), truth, h, w))
        hfov.append(result.focal.hfov_deg)
        sources.append(result.focal.source)
        f_label.append(label_focal(path, h, w, truth))
        f_est.append(result.focal.f_px)
        f_assumed.append(focal_from_hfov(w, analyser.focal_config.assumed_fov_deg))
    return {"images": len(images), "auc_percent": auc_percent(est), "level_auc_percent": auc_percent(level),
            "focal_error": focal_errors(f_label, f_est), "assumed_focal_error": focal_errors(f_label, f_assumed),
            **parity_auc_percent([p.stem for p in images], est), "median_error": float(np.median(est)), "errors": est,
            "estimated_focal_fraction": float(np.mean([s == "estimated" for s in sources])),
            "median_hfov_deg": float(np.median(hfov)), "ms_per_image": float(np.median(ms)),
            "cpu_ms_per_image": float(np.median(cpu_ms))}


@functools.cache
def icsl_depth_reference(rgb_path: Path):
    """The depth-normal rotation and its covariance for one ICSL frame (published intrinsics, the depth's
    inverse-depth offset taken off); once per frame (both ICSL scorings and the ICSL-more sequence use
    them)."""
    from ..normals.depth import DepthNormals
    from ..solver import solve_manhattan
    from ..types import Frame

    depth = read_icsl_depth(rgb_path.parent.parent / "depth" / rgb_path.name)
    nm = DepthNormals().estimate_frame(Frame(0.0, depth=depth, K=ICSL_CORRIDOR_K))
    return solve_manhattan(nm)


def rotation_nees(R_est, cov_est, R_ref) -> tuple[float, float]:
    """(angle deg, NEES) of `R_est` against `R_ref` after the Manhattan symmetry nearest the reference."""
    R_sym, P = nearest_symmetric(R_est, R_ref)
    d = log_so3(R_sym.T @ R_ref)
    cov = P.T @ cov_est @ P
    return float(np.degrees(np.linalg.norm(d))), float(d @ np.linalg.solve(cov, d))


def icsl_scores(folders: list[Path], analyser, stride: int = 1) -> dict:
    """RGB-only rotation vs the depth-normal rotation on ICSL frames, and the estimated FOV."""
    paths = [p for f in folders for p in sorted((f / "rgb").glob("*.png"))][::stride]
    angles, nees, hfov, sources = [], [], [], []
    for path in paths:
        ref = icsl_depth_reference(path)
        result = analyser.analyse(path)
        a, n = rotation_nees(result.visual.R_cm, result.visual.cov, ref.R_cm)
        angles.append(a)
        nees.append(n)
        hfov.append(result.focal.hfov_deg)
        sources.append(result.focal.source)
    true_hfov = math.degrees(2 * math.atan2(640 / 2, ICSL_FX))
    est = [h for h, s in zip(hfov, sources) if s == "estimated"]
    return {"frames": len(paths), "mean_angle_deg": float(np.mean(angles)), "median_angle_deg": float(np.median(angles)),
            "nees_mean": float(np.mean(nees)), "nees_median": float(np.median(nees)),
            "true_hfov_deg": true_hfov, "estimated_focal_fraction": len(est) / max(len(paths), 1),
            "median_hfov_deg": float(np.median(est)) if est else float("nan"),
            "hfov_error_percent": 100.0 * abs(np.median(est) - true_hfov) / true_hfov if est else float("nan")}


def pooled_scores(folders: list[Path], analyser, stride: int = 1, reference=icsl_depth_reference,
                  fx_true: float = ICSL_FX, centre_true: tuple[float, float] | None = None) -> dict:
    """The frames of each folder (one camera, no intrinsics) through `analyser.analyse_same_camera`: K pooled
    over the folder, each frame solved again with it. Against `reference(path)` (a rotation R_cm, or None
    to score K only): angle and NEES as `icsl_scores`; the pooled K's HFOV error against `fx_true` and
    its principal point's distance from `centre_true` (when known)."""
    angles, nees, sequences = [], [], []
    for folder in folders:
        paths = sorted((folder / "rgb").glob("*.png"), key=natural_key)[::stride]
        results = list(analyser.analyse_same_camera(paths))
        if not results:
            raise InputError(f"{folder / 'rgb'}: no PNG frames to pool a K over")
        for result in results:
            if reference is not None:
                a, n = rotation_nees(result.visual.R_cm, result.visual.cov, reference(result.path).R_cm)
                angles.append(a)
                nees.append(n)
        focal = results[-1].focal
        w = results[-1].rgb.shape[1]
        true_hfov = math.degrees(2 * math.atan2(w / 2, fx_true))
        pp = focal.K[:2, 2]
        sequences.append({"folder": folder.name, "frames": len(paths), "origin": focal.origin or focal.source,
                          "f_px": focal.f_px, "f_std_px": focal.std_px, "principal_point_px": pp.tolist(),
                          "principal_point_std_px": focal.principal_point_std_px,
                          "principal_point_error_px": None if centre_true is None
                          else float(np.linalg.norm(pp - np.asarray(centre_true))),
                          "hfov_error_percent": 100.0 * abs(focal.hfov_deg - true_hfov) / true_hfov})
    out = {"sequences": sequences, "frames": sum(s["frames"] for s in sequences),
           "hfov_error_percent": float(np.mean([s["hfov_error_percent"] for s in sequences]))}
    if angles:
        out.update({"mean_angle_deg": float(np.mean(angles)), "median_angle_deg": float(np.median(angles)),
                    "nees_mean": float(np.mean(nees))})
    return out


def icl_scores(folder: Path, cues: str) -> dict:
    """`eval` of the RGB-only single-frame backend on ICL-NUIM kt3 (learned normals), and the FOV
    estimated from the first frames without the dataset's intrinsics."""
    import tempfile

    from ..pipeline import RunConfig
    from ..pipeline.session import run_to_folder
    from .. import pipeline  # noqa: F401

    with tempfile.TemporaryDirectory() as out:
        summary = run_to_folder(str(folder), out, RunConfig(backend="single", normals="learned", cues=cues),
                                evaluate=True, command="bench horizon")
    from ..pipeline.single_image import ImageAnalyser

    analyser = ImageAnalyser(cues=cues)
    hfov = [analyser.analyse(p).focal for p in sorted((folder / "rgb").glob("*.png"),
                                                          key=lambda p: int(p.stem))[:100:10]]
    est = [f.hfov_deg for f in hfov if f.source == "estimated"]
    true_hfov = math.degrees(2 * math.atan2(640 / 2, ICL_FX))
    return {"are_mean_deg": summary["are_deg"]["mean"], "nees_mean": summary["nees"]["mean"],
            "fps": summary["fps"], "true_hfov_deg": true_hfov, "median_hfov_deg": float(np.median(est)) if est else float("nan"),
            "hfov_error_percent": 100.0 * abs(np.median(est) - true_hfov) / true_hfov if est else float("nan")}


BACKENDS_COMPARED = BACKENDS
"""The backends scored on the RGB-only sequences: `bench realdata`'s."""


def backend_errors(sequence, info=None) -> tuple[dict, dict]:
    """Each of `BACKENDS_COMPARED` run on one `VisualSequence` with a reference: its per-frame errors
    (`errors_over_time`) by name, and a note for each backend that could not be made. With the source's
    `info`, each backend is made as `run --normals learned` makes it for that source
    (`realdata.backend_errors`, through `stages.backend_for_run`: for ICSL, K from the scene, no visual bias
    state); without, with its defaults (`compare.make_backends`)."""
    from ..evaluation.compare import errors_over_time, make_backends, run_backend
    from .realdata import backend_errors as backend_errors_for_run

    if info is not None:
        return backend_errors_for_run(sequence, info, "learned"), {}
    backends, notes = make_backends(BACKENDS_COMPARED)
    return {name: errors_over_time(run_backend(backend, sequence), sequence.R_wc_true)
            for name, backend in backends.items()}, notes


def backend_rows(errors: dict, notes: dict) -> dict:
    """ARE and NEES means of each backend from `backend_errors`, and each one's per-frame ARE minus
    `single`'s (`are_vs_single_deg`: `paired_difference`); a backend that could not run has its note."""
    from ..evaluation.compare import error_columns
    from ..evaluation.paired_difference import paired_difference

    rows = {}
    for name in BACKENDS_COMPARED:
        if name in notes:
            rows[name] = {"note": notes[name]}
            continue
        summary = error_columns(errors[name])
        rows[name] = {"are_mean_deg": summary["are_deg_mean"], "nees_mean": summary["nees_mean"]}
        if name != "single" and "single" in errors:
            rows[name]["are_vs_single_deg"] = paired_difference(errors[name]["are_deg"], errors["single"]["are_deg"])
    return rows


def backend_scores(sequence, info=None) -> dict:
    """`backend_rows` of `backend_errors` on one `VisualSequence` with a reference (and its source's `info`)."""
    return backend_rows(*backend_errors(sequence, info))


def rgb_sequence(spec: Path, cues: str, R_wc_reference: np.ndarray | None = None):
    """The RGB-only `VisualSequence` of a dataset folder (learned normals and/or segments, no depth, no
    intrinsics unless the dataset gives them), with `R_wc_reference` replacing its ground truth when given,
    and the source's `SourceInfo`."""
    import dataclasses

    from ..drivers.registry import open_source
    from ..evaluation.source_sequence import source_sequence
    from ..pipeline import RunConfig

    with open_source(str(spec)) as source:
        seq = source_sequence(source, RunConfig(normals="learned", cues=cues))
        info = source.info
    return (seq if R_wc_reference is None else dataclasses.replace(seq, R_wc_true=R_wc_reference)), info


def chained_reference(R_cm: list[np.ndarray]) -> np.ndarray:
    """Camera-to-Manhattan-world rotations (N, 3, 3) from per-frame depth rotations `R_cm`, each one's
    Manhattan symmetry taken nearest the previous frame's (a slowly moving camera)."""
    out = [np.asarray(R_cm[0], float)]
    for R in R_cm[1:]:
        out.append(nearest_symmetric(np.asarray(R, float), out[-1])[0])
    return np.swapaxes(np.array(out), 1, 2)


def icsl_more_reference(data: Path) -> np.ndarray:
    """`chained_reference` of the depth rotations of `data`/icsl_corridor_more's frames (N, 3, 3)."""
    rgb = sorted((data / "icsl_corridor_more" / "rgb").glob("*.png"))
    return chained_reference([icsl_depth_reference(p).R_cm for p in rgb])


def real_sequences(data: Path, cues: str, icsl_reference: np.ndarray | None = None) -> dict:
    """The RGB-only sequences the backends are scored on, by name: ICL kt3 (its ground truth) and
    ICSL-more (against `icsl_reference`, by default `icsl_more_reference`), each with its `SourceInfo`."""
    reference = icsl_more_reference(data) if icsl_reference is None else icsl_reference
    return {"ICL kt3": rgb_sequence(data / "icl_nuim_office_kt3", cues),
            "ICSL more": rgb_sequence(data / "icsl_corridor_more" / "rgb", cues, reference)}


def run(data: Path, cues: str = "normals,lines,sky", ecd_limit: int | None = None, icsl_stride: int = 2,
        console: Console | None = None, ecd_only: bool = False, uav_only: bool = False) -> dict:
    """Every figure of the module docstring beside its goal and baseline (only ECD's with `ecd_only`,
    only horizon_uav's with `uav_only`: `benchmarks/horizon_uav.py`); returns them as a dict."""
    from ..drivers.intrinsics import CameraModel
    from ..pipeline.single_image import ImageAnalyser
    from . import horizon_uav

    console = console or Console()
    analyser = ImageAnalyser(cues=cues)
    uav = (horizon_uav.uav_scores(data / "horizon_uav", analyser)
           if not ecd_only and (data / "horizon_uav").is_dir() else None)
    if uav_only:
        table = _table(f"bench horizon, horizon_uav only (cues {cues}; data under {data})")
        if uav is not None:
            horizon_uav.uav_rows(table, uav)
        console.print(table)
        return {"horizon_uav": uav}
    ecd = ecd_scores(data / "eurasian_cities", analyser, ecd_limit)
    ecd.pop("errors")
    if ecd_only:
        table = _table(f"bench horizon, ECD only (cues {cues}; data under {data})")
        _ecd_rows(table, ecd)
        console.print(table)
        return {"ecd": ecd}
    icsl_folders = [data / "icsl_corridor", data / "icsl_corridor_more"]
    icsl = icsl_scores(icsl_folders, analyser, icsl_stride)
    icsl_given = icsl_scores(icsl_folders, ImageAnalyser(cues=cues, camera=CameraModel(
        ICSL_CORRIDOR_K, np.zeros(0), origin="the dataset's published intrinsics")), icsl_stride)
    icsl_pooled = pooled_scores(icsl_folders, analyser, icsl_stride)
    icl_pooled = pooled_scores([data / "icl_nuim_office_kt3"], analyser, icsl_stride, reference=None, fx_true=ICL_FX,
                               centre_true=ICL_CENTRE)
    icl = icl_scores(data / "icl_nuim_office_kt3", cues)
    backends = {name: backend_scores(seq, info) for name, (seq, info) in real_sequences(data, cues).items()}
    indoor = horizon_uav.indoor_known(data, analyser, icsl_stride)
    table = _table(f"bench horizon (cues {cues}; data under {data})")
    _ecd_rows(table, ecd)
    if uav is not None:
        horizon_uav.uav_rows(table, uav)
    horizon_uav.indoor_rows(table, indoor)
    for how, scores in (("no intrinsics", icsl), ("dataset K given", icsl_given)):
        table.add_row(f"ICSL RGB vs depth rotation, {how}, mean ({scores['frames']} frames)",
                      f"{scores['mean_angle_deg']:.2f} deg", "<= 2 deg", f"median {scores['median_angle_deg']:.2f} deg")
        table.add_row(f"ICSL RGB-only NEES mean, {how}", f"{scores['nees_mean']:.2f}", "<= 6", "")
    table.add_row("ICSL HFOV error", f"{icsl['hfov_error_percent']:.1f} % ({icsl['median_hfov_deg']:.1f} deg)",
                  "<= 5 %", f"true {icsl['true_hfov_deg']:.1f} deg")
    _pooled_rows(table, "ICSL", icsl_pooled, f"per image {icsl['mean_angle_deg']:.2f} deg")
    _pooled_rows(table, "ICL kt3", icl_pooled, "")
    table.add_row("ICL kt3 RGB-only ARE mean", f"{icl['are_mean_deg']:.2f} deg", "<= 1.5 deg", "paper 2.72 deg")
    table.add_row("ICL kt3 RGB-only NEES mean", f"{icl['nees_mean']:.2f}", "1.5 .. 6", "")
    table.add_row("ICL kt3 HFOV error", f"{icl['hfov_error_percent']:.1f} % ({icl['median_hfov_deg']:.1f} deg)",
                  "<= 5 %", f"true {icl['true_hfov_deg']:.1f} deg")
    for seq_name, rows in backends.items():
        single = rows["single"].get("are_mean_deg", float("nan"))
        for name, row in rows.items():
            if "note" in row:
                table.add_row(f"{seq_name} RGB-only {name}", row["note"], "", "")
                continue
            vs = row.get("are_vs_single_deg")
            table.add_row(f"{seq_name} RGB-only {name}: ARE mean / NEES mean",
                          f"{row['are_mean_deg']:.4f} deg / {row['nees_mean']:.2f}",
                          "" if name == "single" else f"ARE <= single ({single:.4f})",
                          "" if vs is None else f"{vs['mean']:+.4f} deg vs single, paired per frame "
                          f"(95 % {vs['low']:+.4f} .. {vs['high']:+.4f})")
    console.print(table)
    return {"ecd": ecd, "horizon_uav": uav, "indoor_horizon_known": indoor, "icsl": icsl, "icsl_given_K": icsl_given,
            "icsl_pooled_K": icsl_pooled, "icl_kt3": icl,
            "icl_kt3_pooled_K": icl_pooled, "backends_rgb_only": backends}


def _pooled_rows(table: Table, name: str, scores: dict, baseline: str) -> None:
    """The rows of one `pooled_scores`: the rotations (when scored) and each sequence's pooled K."""
    if "mean_angle_deg" in scores:
        table.add_row(f"{name} RGB vs depth rotation, no intrinsics, K pooled over each sequence, mean "
                      f"({scores['frames']} frames)", f"{scores['mean_angle_deg']:.2f} deg", "<= 2 deg",
                      f"median {scores['median_angle_deg']:.2f} deg; {baseline}")
        table.add_row(f"{name} RGB-only NEES mean, K pooled", f"{scores['nees_mean']:.2f}", "<= 6", "")
    for seq in scores["sequences"]:
        std = seq["principal_point_std_px"]
        pp = (f"c ({seq['principal_point_px'][0]:.1f}, {seq['principal_point_px'][1]:.1f})"
              + (f" +- ({std[0]:.1f}, {std[1]:.1f})" if std else "") + " px")
        error = "" if seq["principal_point_error_px"] is None else f", {seq['principal_point_error_px']:.1f} px off"
        table.add_row(f"{name} {seq['folder']}: HFOV error of the pooled K",
                      f"{seq['hfov_error_percent']:.1f} % (f {seq['f_px']:.1f} +- {seq['f_std_px']:.1f} px)", "<= 5 %",
                      f"{pp}{error}; {seq['origin']}")


def _table(title: str) -> Table:
    table = Table(title=title)
    for col in ("figure", "measured", "goal", "baseline"):
        table.add_column(col)
    return table


def _ecd_rows(table: Table, ecd: dict) -> None:
    table.add_row(f"ECD horizon AUC@0.25 ({ecd['images']} images)", f"{ecd['auc_percent']:.1f} %", ">= 90 %",
                  f"level camera {ecd['level_auc_percent']:.1f} %")
    table.add_row("ECD horizon AUC@0.25, odd / even-numbered images",
                  f"{ecd['auc_odd_percent']:.1f} % / {ecd['auc_even_percent']:.1f} %", "", "")
    table.add_row("ECD focal estimated / median HFOV", f"{100 * ecd['estimated_focal_fraction']:.0f} % / "
                  f"{ecd['median_hfov_deg']:.1f} deg", "", "")
    fe, fa = ecd["focal_error"], ecd["assumed_focal_error"]
    table.add_row(f"ECD focal error vs the labels' f ({fe['photos']} photos whose labelled zenith and horizon fix f "
                  f"to {100 * LABEL_FOCAL_MAX_STD:.0f} %): median / 90th percentile",
                  f"{fe['median_percent']:.1f} % / {fe['p90_percent']:.1f} %", "p90 <= 23.5 %",
                  f"assumed FOV {fa['median_percent']:.1f} % / {fa['p90_percent']:.1f} %")
    table.add_row("ECD time per image (image, median): CPU / wall", f"{ecd['cpu_ms_per_image']:.0f} ms / "
                  f"{ecd['ms_per_image']:.0f} ms", "", CPU_TIME_NOTE)
