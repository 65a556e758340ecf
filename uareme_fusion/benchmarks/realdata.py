"""Every real development sequence, each cue set and backend beside its goal and its best single input
(issues 29 and 30): `uareme-fusion bench realdata`.

Sequences (skipped with a line when absent): the TUM fr1 rpy evaluation frames (the last 207, never
trained on; `formats.fetched`), EuRoC V1_01 micro (camera + IMU, drone standing still), the ICSL
corridor and corridor_more (against the depth-normal rotations, Manhattan symmetry chained frame to
frame, as `bench horizon` scores them: `horizon.icsl_depth_reference`, `horizon.chained_reference`) and
ICL-NUIM kt3.

Two ways of running, both the library's own:
- cue sets and backends: each cue set's per-frame visual rotations are solved once
  (`evaluation.source_sequence`: learned normals + lines, learned normals alone, lines alone; depth
  normals + lines where the source has depth), then `single`, `mekf` and `smoother` run on the same
  rotations (`evaluation.compare.run_backend`, each backend made as `run` makes it:
  `pipeline.stages.backend_for_run`), so a paired per-frame difference isolates the backend or the cue;
- `eval` runs: what a user's `uareme-fusion eval` gives (`pipeline.session.run_source`): ICL kt3 with
  default options (no --normals), EuRoC micro with default options against the IMU log alone
  (`eval mav0/imu0/data.csv --gt ...`) over the same frames, TUM with and without its accelerometer
  (`--no-accel`), with depth and with learned normals.
  A run's solver starts each frame from the backend's prediction, the cue-set rows' from the previous
  frame's rotation, so the two differ where the backend's prediction does (EuRoC micro, mekf: visual
  rotations 5.9 deg apart on average; fused tilt 3.94 in `eval` against 2.32 on the cue-set rotations,
  and 3.94 again when mekf is run here on the rotations `eval` solved: the same filter).

Figures: ARE mean (deg, after one constant alignment), NEES mean ("aligned": after the same alignment,
against each frame's own covariance plus what the alignment leaves of its steady part, the calibration's
error shared by every frame, `metrics.aligned_covariance`; "yaw-aligned": a backend that knows gravity,
after a rotation about up only, against the whole covariance), tilt mean where the reference is
gravity-aligned; "no worse beyond a paired 95 % interval": the mean per-frame difference (A - B) with
its moving-block bootstrap interval (`evaluation.paired_difference`), passing while the interval's low
end is <= 0; the std separation: median ARE of the frames in the lower half of the reported std
(sqrt of the covariance's trace) over that of the upper half, goal <= 0.5, printed beside the oracle's
ratio (the frames ranked by their true error: what a perfect std would reach; where the errors are
homogeneous it lies above the goal, and the goal cannot be met there).
"""

from __future__ import annotations

import dataclasses
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from ..evaluation.paired_difference import paired_difference
from .realdata_rows import COLUMNS, JOINT, figure_rows

CUE_SETS = {"RGB normals+lines": ("learned", "normals,lines"), "RGB normals": ("learned", "normals"),
            "RGB lines": ("learned", "lines"), "depth": ("depth", "normals,lines")}
"""Row name -> (--normals, --cues) of each cue set."""
RGB_SINGLE_CUES = ("RGB normals", "RGB lines")
BACKENDS = ("single", "mekf", "smoother")
SEQUENCES = ("tum", "euroc", "icsl", "icsl_more", "kt3")
NEES_ALIGNED = "aligned"
"""A row's NEES after the constant alignment: the per-frame covariance plus what the alignment leaves of
its steady part (`metrics.aligned_covariance`)."""
NEES_YAW = "yaw-aligned"
"""A row's NEES after a rotation about up only (the backend knows gravity): the whole covariance."""
QUICK_FRAMES = 20
"""Frames per sequence with `--quick` (not the reported figures)."""


def std_separation(std: np.ndarray, errors: np.ndarray) -> dict:
    """Median error of the frames in the lower half of `std` over that of the upper half (finite pairs
    only; an odd middle frame goes to the upper half): `{"low_std_median", "high_std_median", "ratio",
    "frames"}` (NaN with fewer than 2 frames)."""
    std, errors = np.asarray(std, float), np.asarray(errors, float)
    ok = np.isfinite(std) & np.isfinite(errors)
    std, errors = std[ok], errors[ok]
    if len(std) < 2:
        return {"low_std_median": float("nan"), "high_std_median": float("nan"), "ratio": float("nan"),
                "frames": int(len(std))}
    order = np.argsort(std, kind="stable")
    half = len(order) // 2
    low, high = float(np.median(errors[order[:half]])), float(np.median(errors[order[half:]]))
    return {"low_std_median": low, "high_std_median": high, "ratio": low / high if high > 0 else float("inf"),
            "frames": int(len(std))}


def total_std_deg(cov_rad2: np.ndarray) -> np.ndarray:
    """sqrt(trace) of covariances (N, 3, 3) in rad^2, in degrees (N,)."""
    return np.degrees(np.sqrt(np.trace(np.asarray(cov_rad2, float), axis1=1, axis2=2)))


# ---------------------------------------------------------------- sequences


@dataclasses.dataclass
class RealSequence:
    """One real development sequence: what to open, its reference, what it has."""

    key: str
    name: str
    spec: str
    reference: Callable[[], np.ndarray] | None = None
    """Per-frame reference `R_wc` (N, 3, 3) in place of the source's ground truth (ICSL), or None."""
    has_depth: bool = False
    eval_rows: tuple = ()


def sequences(data: Path, tum_dir: Path | None, wanted=SEQUENCES, quick: bool = False) -> tuple[list, list]:
    """(the `RealSequence`s present among `wanted`, a line for each one skipped)."""
    from . import horizon

    found, skipped = [], []

    def icsl(folder: str):
        return lambda: horizon.chained_reference(
            [horizon.icsl_depth_reference(p).R_cm for p in sorted((data / folder / "rgb").glob("*.png"))])

    candidates = {
        "tum": (tum_dir, lambda p: RealSequence("tum", "TUM fr1 rpy eval", str(p), has_depth=True,
                                                  eval_rows=("accelerometer",)),
                "not fetched (formats.fetched.tum_rpy_root: $UAREME_TUM_RPY or ../data/rgbd_dataset_freiburg1_rpy)"),
        "euroc": (data / "euroc_v1_01_micro", lambda p: RealSequence("euroc", "EuRoC V1_01 micro", str(p),
                                                                       eval_rows=("imu",)), "absent"),
        "icsl": (data / "icsl_corridor", lambda p: RealSequence("icsl", "ICSL corridor", str(p / "rgb"),
                                                                  reference=icsl("icsl_corridor")), "absent"),
        "icsl_more": (data / "icsl_corridor_more", lambda p: RealSequence(
            "icsl_more", "ICSL corridor_more", str(p / "rgb"), reference=icsl("icsl_corridor_more")), "absent"),
        "kt3": (data / "icl_nuim_office_kt3", lambda p: RealSequence("kt3", "ICL kt3", str(p), has_depth=True,
                                                                       eval_rows=("default",)), "absent"),
    }
    for key in wanted:
        path, make, why = candidates[key]
        if quick and key == "icsl_more":
            continue
        if path is None or not Path(path).exists():
            skipped.append(f"{key}: skipped, {why}" + (f" ({path})" if path is not None else ""))
        else:
            found.append(make(Path(path)))
    return found, skipped


# ---------------------------------------------------------------- runs


class Steps:
    """A rich progress bar over the benchmark's steps (one task per step, frames as its total)."""

    def __init__(self, console: Console):
        self.progress = Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                                 TimeElapsedColumn(), console=console, transient=True)

    def __enter__(self):
        self.progress.start()
        return self

    def __exit__(self, *exc):
        self.progress.stop()

    def step(self, description: str, total: int | None):
        task = self.progress.add_task(description, total=total)

        def advance(done: int, _total=None) -> None:
            self.progress.update(task, completed=done)
        return advance


def cue_set_sequence(seq: RealSequence, normals: str, cues: str, max_frames: int | None, progress):
    """The `VisualSequence` of one cue set (`evaluation.source_sequence`), with `seq.reference` as its
    ground truth when given; returns it and whether its reference is gravity-aligned."""
    from ..drivers import open_source
    from ..evaluation.source_sequence import source_sequence
    from ..pipeline import RunConfig

    cfg = RunConfig(normals=normals, cues=cues, max_frames=max_frames)
    with open_source(seq.spec) as source:
        visual = source_sequence(source, cfg, progress)
        truth = source.ground_truth()
        info = source.info
    if seq.reference is not None:
        visual = dataclasses.replace(visual, R_wc_true=seq.reference()[:len(visual.t_frame_s)])
    return visual, info, bool(truth is not None and truth.gravity_aligned and seq.reference is None)


def backend_errors(visual, info, normals: str, mekf: dict | None = None, smoother: dict | None = None) -> dict:
    """Per-frame errors (`compare.errors_over_time`) of each of `BACKENDS` on one `VisualSequence`,
    each made as `run` makes it for this source and `--normals normals` (`stages.backend_for_run`; the
    sequence's IMU is already in camera axes and on the camera clock), with `RunConfig.mekf` / `.smoother`
    keys `mekf` / `smoother` (tools/visual_only_replay.py)."""
    from ..backends.factory import backend_kind, knows_gravity
    from ..evaluation.compare import errors_over_time, run_backend
    from ..pipeline import RunConfig
    from ..pipeline.stages import backend_for_run

    camera_axes = dataclasses.replace(info, R_ci=np.eye(3), imu_time_offset_s=0.0, has_imu=visual.has_imu)
    out = {}
    for name in BACKENDS:
        cfg = RunConfig(backend=name, normals=normals, mekf=mekf or {}, smoother=smoother or {})
        run = run_backend(backend_for_run(cfg, camera_axes), visual)
        kind = backend_kind(name, visual.has_imu).name
        gravity = knows_gravity(kind, visual.has_imu)
        err = errors_over_time(run, visual.R_wc_true, yaw_only_nees=gravity)
        err["nees_kind"] = NEES_YAW if gravity else NEES_ALIGNED
        err["std_deg"] = total_std_deg(np.array([e.cov for e in run.estimates]))
        out[name] = err
    out["single"]["no_information"] = np.array([claims_no_information(v) for v in visual.visuals])
    return out


def claims_no_information(visual) -> bool:
    """Whether a frame's visual rotation says it knows nothing: none, a reason given
    (`VisualRotation.reason`), or the solver's cap on every axis."""
    from ..solver.manhattan import SolverConfig

    return visual is None or bool(visual.reason) or bool(
        np.linalg.eigvalsh(visual.cov)[0] >= 0.99 * SolverConfig().max_variance_rad2)


def eval_run(spec: str, cfg, progress=None, gt: Path | None = None) -> dict:
    """`uareme-fusion eval SPEC` with `cfg` (and `--gt` when given) in a temporary folder: its summary
    and per-estimate errors (`session.evaluation_errors`): `{"summary", "t_s", "errors", "notes",
    "has_imu"}`."""
    from ..drivers import open_source
    from ..drivers.ground_truth_file import with_ground_truth_file
    from ..backends.factory import backend_kind, knows_gravity
    from ..pipeline.session import configure_imu, evaluation_errors, run_source
    from ..sinks.estimate_files import EstimateLog

    log = EstimateLog()
    with tempfile.TemporaryDirectory() as out, open_source(spec) as source:
        configure_imu(source, cfg)
        if gt is not None:
            with_ground_truth_file(source, gt)
        has_imu = source.info.has_imu
        notes = source.report()[0]
        on_result = None if progress is None else (lambda result, stats: progress(stats.estimates))
        summary = run_source(source, Path(out), cfg, evaluate=True, extra_sinks=[log], on_result=on_result,
                             command="bench realdata")
        gravity = knows_gravity(backend_kind(cfg.backend, has_imu).name, has_imu)
        t, errors, _, _ = evaluation_errors(log, source.ground_truth(), gravity)
    return {"summary": summary, "t_s": t, "errors": errors, "notes": notes, "has_imu": has_imu}


def _nearest(t_from: np.ndarray, t_to: np.ndarray) -> np.ndarray:
    """Index into sorted `t_from` of the time nearest each of `t_to`."""
    idx = np.clip(np.searchsorted(t_from, t_to), 1, len(t_from) - 1)
    return np.where(np.abs(t_from[idx - 1] - t_to) <= np.abs(t_from[idx] - t_to), idx - 1, idx)


# ---------------------------------------------------------------- figures


def _mean(values) -> float:
    values = np.asarray(values, float)
    values = values[np.isfinite(values)]
    return float(values.mean()) if values.size else float("nan")


def cue_backend_figures(errors_by_cue: dict, gravity_aligned: bool) -> dict:
    """The figures of one sequence's cue sets x backends (means, paired intervals, std separation)."""
    out = {}
    for cue, errs in errors_by_cue.items():
        rows = {}
        for name, err in errs.items():
            ok = err["initialised"]
            row = {"are_mean_deg": _mean(err["are_deg"][ok]), "nees_mean": _mean(err["nees"][ok]),
                   "frames": int(ok.sum()), "nees_kind": err.get("nees_kind", NEES_ALIGNED)}
            if gravity_aligned:
                row["tilt_mean_deg"] = _mean(err["tilt_deg"][ok])
            if name != "single":
                row["are_vs_single_deg"] = paired_difference(err["are_deg"], errs["single"]["are_deg"])
            rows[name] = row
        if "no_information" in errs["single"]:
            rows["single"]["no_information_fraction"] = _mean(errs["single"]["no_information"][errs["single"]["initialised"]])
        rows["single"]["std_separation"] = std_separation(errs["single"]["std_deg"], errs["single"]["are_deg"])
        rows["single"]["std_separation"]["oracle_ratio"] = std_separation(  # the best any std can do
            errs["single"]["are_deg"], errs["single"]["are_deg"])["ratio"]
        out[cue] = rows
    singles = [c for c in RGB_SINGLE_CUES if c in out]
    if JOINT in out and singles:
        best = min(singles, key=lambda c: out[c]["single"]["are_mean_deg"])
        out[JOINT]["single"]["best_single_cue"] = best
        out[JOINT]["single"]["are_vs_best_single_cue_deg"] = paired_difference(
            errors_by_cue[JOINT]["single"]["are_deg"], errors_by_cue[best]["single"]["are_deg"])
    return out


def imu_tilt_at(imu: dict, t_s: np.ndarray) -> np.ndarray:
    """The tilt error (deg) of an IMU-only `eval_run` at times `t_s` (its nearest estimate; NaN where
    not scored)."""
    idx = _nearest(imu["t_s"], np.asarray(t_s, float))
    return np.where(imu["errors"]["valid"][idx], imu["errors"]["tilt_deg"][idx], np.nan)


def imu_figures(fused: dict, imu: dict) -> dict:
    """Fused tilt (an `eval_run` of the camera + IMU folder) against the IMU-only run's tilt at the same
    frame times (its nearest estimate), paired per frame."""
    ok = fused["errors"]["valid"]
    imu_tilt = imu_tilt_at(imu, fused["t_s"])
    fused_tilt = np.where(ok, fused["errors"]["tilt_deg"], np.nan)
    return {"fused_tilt_mean_deg": _mean(fused_tilt), "fused_nees_mean": _mean(fused["errors"]["nees"][ok]),
            "fused_are_mean_deg": _mean(fused["errors"]["are_deg"][ok]),
            "imu_tilt_same_frames_mean_deg": _mean(imu_tilt),
            "imu_tilt_whole_log_mean_deg": imu["summary"]["tilt_deg"].get("mean", float("nan")),
            "fused_vs_imu_tilt_deg": paired_difference(fused_tilt, imu_tilt),
            "frames": int(np.isfinite(fused_tilt).sum()), "normals": fused["summary"]["normals"],
            "backend": fused["summary"]["backend"]}


def run(data: Path, tum_root: Path | None = None, quick: bool = False, wanted=SEQUENCES,
        console: Console | None = None) -> dict:
    """Every figure of the module docstring for the sequences present among `wanted`, printed as one
    table; returns `{"sequences": {key: figures}, "rows": [...], "skipped": [...]}`."""
    from ..formats.fetched import tum_rpy_root, tum_rpy_split

    if console is None:
        console = Console()
        console = console if console.is_terminal else Console(width=220)  # a log file: rows unwrapped
    max_frames = QUICK_FRAMES if quick else None
    tum_root = tum_root if tum_root is not None else tum_rpy_root()
    with tempfile.TemporaryDirectory() as tmp:
        tum_dir = tum_rpy_split(tum_root, "eval", Path(tmp)) if tum_root is not None and "tum" in wanted else None
        found, skipped = sequences(data, tum_dir, wanted, quick)
        figures = {}
        with Steps(console) as steps:
            for seq in found:
                figures[seq.key] = sequence_figures(seq, steps, max_frames, Path(tmp))
    rows = []
    for seq in found:
        rows += figure_rows(seq.name, figures[seq.key])
    _print(console, rows, skipped, quick)
    return {"quick": quick, "max_frames": max_frames, "skipped": skipped,
            "sequences": {seq.key: {"name": seq.name, **figures[seq.key]} for seq in found}, "rows": rows}


def sequence_figures(seq: RealSequence, steps: Steps, max_frames: int | None, tmp: Path) -> dict:
    """The cue sets x backends and the `eval` rows of one sequence."""
    from ..pipeline import RunConfig

    errors_by_cue, gravity_aligned, has_imu = {}, False, False
    for cue, (normals, cues) in CUE_SETS.items():
        if normals == "depth" and not seq.has_depth:
            continue
        visual, info, gravity_aligned = cue_set_sequence(
            seq, normals, cues, max_frames, steps.step(f"{seq.name}: {cue}", max_frames or None))
        has_imu = visual.has_imu
        errors_by_cue[cue] = backend_errors(visual, info, normals)
        t_frames = visual.t_frame_s
    out = {"gravity_aligned_reference": gravity_aligned, "has_imu": has_imu,
           "cue_sets": cue_backend_figures(errors_by_cue, gravity_aligned)}
    if "default" in seq.eval_rows:
        run_ = eval_run(seq.spec, RunConfig(max_frames=max_frames), steps.step(f"{seq.name}: eval", max_frames))
        s = run_["summary"]
        out["eval_default"] = {"normals": s["normals"], "backend": s["backend"], "frames": s["frames_scored"],
                               "are_mean_deg": s["are_deg"].get("mean", float("nan")),
                               "nees_mean": s["nees"].get("mean", float("nan"))}
    if "imu" in seq.eval_rows:
        mav0 = Path(seq.spec) / "mav0"
        fused = eval_run(seq.spec, RunConfig(max_frames=max_frames), steps.step(f"{seq.name}: eval", max_frames))
        imu = eval_run(str(mav0 / "imu0" / "data.csv"), RunConfig(), steps.step(f"{seq.name}: IMU only", None),
                       gt=mav0 / "state_groundtruth_estimate0" / "data.csv")
        out["eval_with_imu"] = imu_figures(fused, imu)
        imu_tilt = imu_tilt_at(imu, t_frames)
        for cue, backends in out["cue_sets"].items():
            for name, row in backends.items():
                row["tilt_vs_imu_deg"] = paired_difference(errors_by_cue[cue][name]["tilt_deg"], imu_tilt)
    if "accelerometer" in seq.eval_rows:
        out["accelerometer"] = accelerometer_figures(seq, steps, max_frames, tmp)
    return out


ACCELEROMETER_NORMALS = ("depth", "learned")
"""The normals of the `eval` runs of a TUM folder with and without its accelerometer (`--no-accel`)."""


def accelerometer_figures(seq: RealSequence, steps: Steps, max_frames: int | None, tmp: Path) -> dict:
    """`eval --normals N` of a TUM folder with its accelerometer without gyro (gravity only) and with
    `--no-accel`, for each of `ACCELEROMETER_NORMALS`: tilt (after the alignment, as eval reports it)
    and ARE, the tilt paired per frame; n/a with the reason when the run did not use the accelerometer."""
    from ..pipeline import RunConfig

    out = {}
    for normals in ACCELEROMETER_NORMALS:
        runs = {}
        for used in (False, True):
            cfg = RunConfig(max_frames=max_frames, normals=normals, accelerometer=used)
            label = f"{seq.name}: eval --normals {normals}" + ("" if used else " --no-accel")
            runs[used] = eval_run(seq.spec, cfg, steps.step(label, max_frames))
        base, with_acc = runs[False], runs[True]
        figures = {"without": _eval_figures(base)}
        if not with_acc["summary"]["source_info"].get("accelerometer_used"):
            why = [n for n in with_acc["notes"] if "accelerometer" in n]
            figures["with"] = {"note": "n/a: " + (why[0].rsplit(": ", 1)[-1] if why else "no accelerometer without gyro")}
        else:
            figures["with"] = _eval_figures(with_acc)
            figures["with"]["tilt_vs_without_deg"] = paired_difference(with_acc["errors"]["tilt_deg"],
                                                                       base["errors"]["tilt_deg"])
            figures["with"]["are_vs_without_deg"] = paired_difference(with_acc["errors"]["are_deg"],
                                                                      base["errors"]["are_deg"])
        out[normals] = figures
    return out


def _eval_figures(run_: dict) -> dict:
    s = run_["summary"]
    return {"normals": s["normals"], "backend": s["backend"], "frames": s["frames_scored"],
            "are_mean_deg": s["are_deg"].get("mean", float("nan")), "tilt_mean_deg": s["tilt_deg"].get("mean", float("nan")),
            "nees_mean": s["nees"].get("mean", float("nan")), "tilt_note": s.get("evaluation_note", "")}


def _print(console: Console, rows: list[dict], skipped: list[str], quick: bool) -> None:
    table = Table(title="bench realdata: real development sequences" + (" (--quick: first "
                  f"{QUICK_FRAMES} frames, not the reported figures)" if quick else "") +
                  "; angles in deg, ARE after one constant alignment")
    for _, title in COLUMNS:
        table.add_column(title)
    for row in rows:
        table.add_row(*(row[key] for key, _ in COLUMNS))
    console.print(table)
    for line in skipped:
        console.print(line, markup=False)
