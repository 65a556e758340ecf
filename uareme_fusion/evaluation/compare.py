"""Side-by-side comparison of backends on the same per-frame visual rotations and IMU samples.

`compare(sequence, out_dir)` runs `single`, `smoother` (paper and gyro-aided) and `mekf` on one
`VisualSequence` and writes `compare.md` (a table), `compare.json` (the same numbers) and
`compare.png` (rotation and tilt error over time per backend). The visual rotations are computed
once per sequence, each frame's solver initialised from the previous frame's solution; each backend
then resolves the Manhattan symmetry against its own prediction.

Metrics (docs/design.md "Evaluation protocol"), over the frames where a backend is initialised:
ARE in degrees after one constant chordal alignment of the estimated `R_wc` to the true `R_wc`
(mean, median, max, the count of frames above `JUMP_DEG` and of frame-to-frame rotations wrong by
more than it); tilt error in degrees between the
estimated and true up vector in the camera frame (no alignment); NEES of the reported covariance
(right perturbation of `R_wc`, after the alignment, which does not change it); latency in ms per
frame (the backend's IMU and frame calls together, median and 95th percentile).

Sequences come from `sequence.synthetic_sequence` (simulator trajectory + IMU + `manhattan_normal_map`,
in memory), `source_sequence.load_sequence` (a dataset folder with its normals saved) or
`source_sequence.source_sequence` (any source `run` accepts).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..io.safe_files import save_figure_atomic, write_text_atomic
from ..backends.base import Backend, SteadyPart
from ..types import Status, stacked_steady
from ..backends.factory import BACKEND_NAMES, knows_gravity, make_backend
from ..scoring.metrics import JUMP_DEG, attitude_errors, jump_counts
from .sequence import VisualSequence
from ..scoring.statistics import error_stats


@dataclass
class BackendRun:
    """One backend's estimates over a sequence and its latency per frame (ms)."""

    name: str
    estimates: list = field(default_factory=list)
    latency_ms: list = field(default_factory=list)
    note: str = ""


def make_backends(names=BACKEND_NAMES) -> tuple[dict, dict]:
    """Backends by name (`backends.factory.make_backend`, EKF with its default settings), and a note for
    each that could not be made (e.g. mekf not installed)."""
    backends, notes = {}, {}
    for name in names:
        try:
            backends[name] = make_backend(name)
        except ImportError as exc:
            notes[name] = f"not available ({exc})"
    return backends, notes


def run_backend(backend: Backend, seq: VisualSequence) -> BackendRun:
    """Feed the sequence in time order: the IMU samples up to each frame, then the frame."""
    run, steady = BackendRun(backend.name), SteadyPart()
    if seq.has_imu:
        ends = np.searchsorted(seq.imu_t_s, seq.t_frame_s, side="right")
    start = 0
    for k, t in enumerate(seq.t_frame_s):
        t0 = time.perf_counter()
        if seq.has_imu and ends[k] > start:
            backend.process_imu(seq.imu_t_s[start:ends[k]], seq.imu_gyro_rad_s[start:ends[k]],
                                seq.imu_accel_m_s2[start:ends[k]])
            start = ends[k]
        run.estimates.append(steady(backend.process_frame(float(t), seq.visuals[k]), seq.visuals[k]))
        run.latency_ms.append(1e3 * (time.perf_counter() - t0))
    return run


def errors_over_time(run: BackendRun, R_wc_true: np.ndarray, yaw_only_nees: bool = False) -> dict:
    """Per-frame ARE, tilt (deg) and NEES of an initialised run (`metrics.attitude_errors`); NaN where
    not initialised. `initialised` marks the scored frames."""
    ok = np.array([not (e.status & Status.NOT_INITIALISED) for e in run.estimates])
    steady = stacked_steady(len(run.estimates), {k: e.cov_steady for k, e in enumerate(run.estimates)
                                                 if e.cov_steady is not None})
    err = attitude_errors(np.array([e.R_wc for e in run.estimates]), np.array([e.cov for e in run.estimates]),
                          ok, R_wc_true, yaw_only_nees, steady)
    err["initialised"] = err.pop("valid")
    return err


def summarise(run: BackendRun, R_wc_true: np.ndarray | None, yaw_only_nees: bool = False) -> dict:
    """The table row of one backend (numbers as plain floats for JSON)."""
    latency = error_stats(run.latency_ms, ("median", "p95"))
    row = {"frames": len(run.estimates), "latency_ms_median": latency["median"], "latency_ms_p95": latency["p95"],
           "not_initialised": int(sum(bool(e.status & Status.NOT_INITIALISED) for e in run.estimates)),
           "optimiser_failed": int(sum(bool(e.status & Status.OPTIMISER_FAILED) for e in run.estimates))}
    if R_wc_true is not None:
        row.update(error_columns(errors_over_time(run, R_wc_true, yaw_only_nees)))
    return row


def error_columns(err: dict) -> dict:
    """The error columns of `summarise`'s row (flat keys) from `errors_over_time`'s per-frame errors
    `err`, over the initialised frames; `metrics.error_summary` is a run summary's nested form."""
    ok = err["initialised"]
    row = {}
    for key, names in (("are_deg", ("mean", "median", "max")), ("tilt_deg", ("mean", "max")),
                       ("nees", ("mean", "median"))):
        row.update({f"{key}_{k}": v for k, v in error_stats(err[key][ok], names).items()})
    row.update(jump_counts({**err, "valid": ok}))
    return row


def compare(seq: VisualSequence, out_dir: str | Path, names=BACKEND_NAMES) -> dict:
    """Run the backends on `seq` and write compare.md, compare.json and compare.png into `out_dir`.

    Returns the JSON document: sequence name, notes, and one row per backend (see `summarise`);
    a backend that could not run has only a `note`.
    """
    from ..pipeline.session import make_output_folder

    out = make_output_folder(out_dir)
    backends, skipped = make_backends(names)
    rows, runs = {}, {}
    for name in names:
        if name in skipped:
            rows[name] = {"note": skipped[name]}
            continue
        if name == "smoother-gyro" and not seq.has_imu:
            rows[name] = {"note": "skipped: the sequence has no IMU"}
            continue
        runs[name] = run_backend(backends[name], seq)
        rows[name] = summarise(runs[name], seq.R_wc_true, yaw_only_nees=knows_gravity(name, seq.has_imu))
    n_missing = sum(v is None for v in seq.visuals)
    doc = {"sequence": seq.name, "frames": len(seq.t_frame_s), "frames_without_visual": n_missing,
           "has_imu": seq.has_imu, "has_ground_truth": seq.R_wc_true is not None,
           "jump_threshold_deg": JUMP_DEG, "notes": list(seq.notes), "backends": rows}
    write_text_atomic(out / "compare.json", json.dumps(doc, indent=2) + "\n")
    write_text_atomic(out / "compare.md", markdown_table(doc))
    plot_errors(runs, seq, out / "compare.png")
    return doc


_COLUMNS = [("ARE mean", "are_deg_mean", "{:.2f}"), ("ARE median", "are_deg_median", "{:.2f}"),
            ("ARE max", "are_deg_max", "{:.2f}"), ("ARE >10 deg", "frames_are_over_10deg", "{}"),
            ("jumps >10 deg", "frame_jumps_over_10deg", "{}"),
            ("tilt mean", "tilt_deg_mean", "{:.2f}"), ("tilt max", "tilt_deg_max", "{:.2f}"),
            ("NEES mean", "nees_mean", "{:.2f}"), ("ms/frame median", "latency_ms_median", "{:.2f}"),
            ("ms/frame p95", "latency_ms_p95", "{:.2f}")]


def markdown_table(doc: dict) -> str:
    """compare.md: the table (degrees, ms) with the notes under it."""
    lines = [f"# Backend comparison: {doc['sequence']}", "",
             f"{doc['frames']} frames, {doc['frames_without_visual']} without a visual rotation; "
             f"IMU: {'yes' if doc['has_imu'] else 'no'}; ground truth: {'yes' if doc['has_ground_truth'] else 'no'}. "
             "ARE after one constant alignment; tilt without alignment; angles in degrees.", "",
             "| backend | " + " | ".join(c[0] for c in _COLUMNS) + " | note |",
             "|---|" + "---:|" * len(_COLUMNS) + "---|"]
    for name, row in doc["backends"].items():
        cells = [fmt.format(row[key]) if key in row else "-" for _, key, fmt in _COLUMNS]
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {row.get('note', '')} |")
    lines += [""] + [f"- {n}" for n in doc["notes"]]
    return "\n".join(lines) + "\n"


def plot_errors(runs: dict, seq: VisualSequence, path: Path) -> None:
    """compare.png: ARE and tilt error over time per backend (or the estimated up angle without ground
    truth). Uses matplotlib's Agg canvas directly, so no global backend is changed."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 6), dpi=100)
    FigureCanvasAgg(fig)
    ax_are, ax_tilt = fig.subplots(2, 1, sharex=True)
    for name, run in runs.items():
        t = np.array([e.t_s for e in run.estimates])
        if seq.R_wc_true is not None:
            err = errors_over_time(run, seq.R_wc_true)
            ax_are.plot(t, err["are_deg"], label=name, lw=1)
            ax_tilt.plot(t, err["tilt_deg"], label=name, lw=1)
        else:
            up = np.array([e.up_c for e in run.estimates])
            ax_tilt.plot(t, np.degrees(np.arccos(np.clip(-up[:, 1], -1, 1))), label=name, lw=1)
    if seq.R_wc_true is not None:
        ax_are.axhline(JUMP_DEG, color="k", ls=":", lw=0.8)
        ax_are.set_ylabel("ARE (deg)")
        ax_tilt.set_ylabel("tilt error (deg)")
    else:
        ax_are.text(0.5, 0.5, "no ground truth", ha="center", va="center", transform=ax_are.transAxes)
        ax_tilt.set_ylabel("angle of up from image up (deg)")
    ax_are.set_title(f"Backend comparison: {seq.name}")
    ax_tilt.set_xlabel("time (s)")
    for ax in (ax_are, ax_tilt):
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    save_figure_atomic(path, fig)
