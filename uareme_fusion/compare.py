"""Side-by-side comparison of backends on the same per-frame visual rotations and IMU samples.

`compare(sequence, out_dir)` runs `single`, `smoother` (paper and gyro-aided) and `mekf` on one
`VisualSequence` and writes `compare.md` (a table), `compare.json` (the same numbers) and
`compare.png` (rotation and tilt error over time per backend). The visual rotations are computed
once per sequence, each frame's solver initialised from the previous frame's solution; each backend
then resolves the Manhattan symmetry against its own prediction.

Metrics (DESIGN.md "Evaluation protocol"), over the frames where a backend is initialised:
ARE in degrees after one constant chordal alignment of the estimated `R_wc` to the true `R_wc`
(mean, median, max, the count of frames above `JUMP_DEG` and of frame-to-frame rotations wrong by
more than it); tilt error in degrees between the
estimated and true up vector in the camera frame (no alignment); NEES of the reported covariance
(right perturbation of `R_wc`, after the alignment, which does not change it); latency in ms per
frame (the backend's IMU and frame calls together, median and 95th percentile).

Sequences come from `synthetic_sequence` (simulator trajectory + IMU + `manhattan_normal_map`, in
memory) or `load_sequence` (a dataset folder written by `uareme-fusion simulate`).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from .backends.base import Backend
from .io.safe_files import write_text_atomic
from .backends.single import SingleFrame
from .backends.smoother import Smoother, SmootherConfig, SmootherMode
from .config import load_config
from .drivers.euroc_imu import read_euroc_imu
from .drivers.tum_rgbd import read_tum_list, read_tum_trajectory
from .errors import InputError
from .metrics import JUMP_DEG, attitude_errors, jump_counts
from .sim.normal_maps import manhattan_normal_map
from .solver import solve_manhattan
from .types import Status

BACKEND_NAMES = ("single", "smoother", "smoother-gyro", "mekf")


@dataclass(frozen=True)
class VisualSequence:
    """Per-frame visual rotations with the IMU samples and the ground truth when known.

    `t_frame_s` (N,) seconds; `visuals` N entries, None where a frame gave no visual rotation;
    IMU arrays `imu_t_s` (M,), `imu_gyro_rad_s` (M, 3), `imu_accel_m_s2` (M, 3) in the IMU frame,
    or None; `R_wc_true` (N, 3, 3) camera-to-world ground truth (world z up) or None.
    """

    name: str
    t_frame_s: np.ndarray
    visuals: list
    imu_t_s: np.ndarray | None = None
    imu_gyro_rad_s: np.ndarray | None = None
    imu_accel_m_s2: np.ndarray | None = None
    R_wc_true: np.ndarray | None = None
    notes: list = field(default_factory=list)

    @property
    def has_imu(self) -> bool:
        return self.imu_t_s is not None and len(self.imu_t_s) > 0


@dataclass
class BackendRun:
    """One backend's estimates over a sequence and its latency per frame (ms)."""

    name: str
    estimates: list = field(default_factory=list)
    latency_ms: list = field(default_factory=list)
    note: str = ""


def solve_frames(normal_maps: list, t_frame_s: np.ndarray) -> tuple[list, int]:
    """Visual rotations for a list of `NormalMap`s (None entries stay None), each solve initialised
    from the previous solution; returns them and the number of maps without valid normals."""
    visuals, R_prev, invalid = [], None, 0
    for nm, t in zip(normal_maps, t_frame_s):
        if nm is None:
            visuals.append(None)
            continue
        try:
            vis = solve_manhattan(nm, R_init=R_prev)
        except InputError:  # no valid normals in this map: the frame gives no visual rotation
            invalid += 1
            visuals.append(None)
            continue
        visuals.append(vis)
        R_prev = vis.R_cm
    return visuals, invalid


def synthetic_sequence(
    scenario: str = "walk",
    seed: int = 0,
    duration_s: float = 20.0,
    fps: float = 15.0,
    drop_fraction: float = 0.1,
    bad_fraction: float = 0.05,
    noise_deg: float = 10.0,
    correlation_px: float = 4.0,
    imu_rate_hz: float = 200.0,
    height: int = 120,
    width: int = 160,
) -> VisualSequence:
    """A sequence built in memory from the simulator's trajectory `scenario` and IMU, with normal
    maps from `manhattan_normal_map` at the true `R_cm = R_wc^T R_wm`.

    A `drop_fraction` of frames (never the first) gives no visual rotation; a `bad_fraction` has
    only random normals (a blank wall or black frame: the solver returns an arbitrary rotation).
    """
    from .sim.imu import simulate_imu
    from .sim.trajectory import make_trajectory

    if not (0 <= drop_fraction < 1 and 0 <= bad_fraction < 1 and drop_fraction + bad_fraction < 1):
        raise InputError(f"drop_fraction + bad_fraction must be in [0, 1), got {drop_fraction} + {bad_fraction}")
    if not fps > 0:
        raise InputError(f"fps must be > 0, got {fps}")
    traj = make_trajectory(scenario, duration_s, seed=seed)
    rng = np.random.default_rng(seed + 7919)
    t_frame = np.arange(0.0, duration_s, 1.0 / fps)
    R_wc_true = traj.sample(t_frame).R_wc
    R_cm_true = traj.R_cm(t_frame)
    kinds = rng.choice(3, size=len(t_frame), p=[1 - drop_fraction - bad_fraction, drop_fraction, bad_fraction])
    kinds[0] = 0
    maps = []
    for k, kind in enumerate(kinds):
        if kind == 1:
            maps.append(None)
            continue
        nm = manhattan_normal_map(R_cm_true[k], rng, height, width, noise_deg=noise_deg, correlation_px=correlation_px)
        if kind == 2:
            random = rng.standard_normal(nm.normals.shape)
            nm = type(nm)(normals=(random / np.linalg.norm(random, axis=-1, keepdims=True)).astype(np.float32),
                          kappa=nm.kappa)
        maps.append(nm)
    visuals, _ = solve_frames(maps, t_frame)
    imu_t, gyro, accel = simulate_imu(traj, rate_hz=imu_rate_hz, seed=seed)
    notes = [f"synthetic '{scenario}' seed {seed}: {len(t_frame)} frames at {fps:g} fps, "
             f"{int(np.sum(kinds == 1))} dropped, {int(np.sum(kinds == 2))} with random normals"]
    return VisualSequence(f"{scenario} (seed {seed})", t_frame, visuals, imu_t, gyro, accel, R_wc_true, notes)


def load_sequence(source: str | Path) -> VisualSequence:
    """A dataset folder written by `uareme-fusion simulate` (TUM RGB-D layout, `imu0/data.csv` in EuRoC
    format, normals as `.npz`): its normals are solved once per frame.

    Normals: `normals.npz` with `normals` (N, H, W, 3), optional `kappa` (N, H, W) and `t_s` (N,),
    or a folder `normals/` of per-frame `.npz` files (sorted by name) with frame times from `rgb.txt`.
    Ground truth from `groundtruth.txt` (`t tx ty tz qx qy qz qw`, camera to world), interpolated at
    the frame times; IMU from `imu0/data.csv` (ns, gyro rad/s, accel m/s^2). Missing ground truth or
    IMU is allowed and noted; a missing folder or missing normals is an `InputError`.
    """
    from .io.normal_maps import load_normal_map
    from .types import NormalMap

    root = Path(source)
    if not root.exists():
        raise InputError(f"{root}: no such dataset folder")
    if not root.is_dir():
        raise InputError(f"{root}: expected a dataset folder written by 'uareme-fusion simulate', got a file")
    notes = []
    stacked = root / "normals.npz"
    if stacked.is_file():
        try:
            with np.load(stacked) as data:
                if "normals" not in data:
                    raise InputError(f"{stacked}: no array named 'normals' (found {', '.join(data.files)})")
                normals = data["normals"]
                kappa = data["kappa"] if "kappa" in data else np.ones(normals.shape[:-1], np.float32)
                t_frame = data["t_s"] if "t_s" in data else None
        except (OSError, ValueError) as exc:
            raise InputError(f"{stacked}: not a readable .npz file ({exc})") from None
        if normals.ndim != 4 or normals.shape[-1] != 3:
            raise InputError(f"{stacked}: expected normals of shape (N, H, W, 3), got {normals.shape}")
        maps = [NormalMap(n, k) for n, k in zip(normals, kappa)]
    elif (root / "normals").is_dir():
        files = sorted((root / "normals").glob("*.npz"))
        if not files:
            raise InputError(f"{root / 'normals'}: no .npz normal maps")
        maps, t_frame = [load_normal_map(f) for f in files], None
    else:
        raise InputError(f"{root}: no normals (expected normals.npz or a normals/ folder of .npz files)")
    if t_frame is None:
        if not (root / "rgb.txt").is_file():
            raise InputError(f"{root / 'rgb.txt'}: missing (needed for the frame times of the normal maps)")
        t_frame, _ = read_tum_list(root / "rgb.txt")
    t_frame = np.asarray(t_frame, dtype=float)
    if len(t_frame) != len(maps):
        raise InputError(f"{root}: {len(maps)} normal maps but {len(t_frame)} frame times")
    visuals, invalid = solve_frames(maps, t_frame)
    if invalid:
        notes.append(f"{invalid} normal maps had no valid normals and gave no visual rotation")
    R_wc_true = _groundtruth_at(root / "groundtruth.txt", t_frame, notes)
    imu = _imu(root / "imu0" / "data.csv", notes)
    return VisualSequence(root.name, t_frame, visuals, *imu, R_wc_true, notes)


def _groundtruth_at(path: Path, t_frame: np.ndarray, notes: list) -> np.ndarray | None:
    if not path.is_file():
        notes.append("no groundtruth.txt: ARE, tilt and NEES not computed")
        return None
    t, _, quat_xyzw = read_tum_trajectory(path)
    if len(t) == 0 or t_frame[0] < t[0] or t_frame[-1] > t[-1]:
        span = f"{t[0]:.3f}-{t[-1]:.3f} s" if len(t) else "no time"
        raise InputError(f"{path}: ground truth covers {span} but frames span "
                         f"{t_frame[0]:.3f}-{t_frame[-1]:.3f} s")
    return Slerp(t, Rotation.from_quat(quat_xyzw))(t_frame).as_matrix()


def _imu(path: Path, notes: list):
    if not path.is_file():
        notes.append("no imu0/data.csv: IMU backends run without IMU or are skipped")
        return None, None, None
    imu = read_euroc_imu(path)
    return imu.t_s, imu.gyro_rad_s, imu.accel_m_s2


def make_backends(names=BACKEND_NAMES) -> tuple[dict, dict]:
    """Backends by name, and a note for each that could not be made (e.g. mekf not installed)."""
    backends, notes = {}, {}
    paper = load_config("paper", SmootherConfig, section="smoother")
    for name in names:
        if name == "single":
            backends[name] = SingleFrame()
        elif name == "smoother":
            backends[name] = Smoother(paper)
        elif name == "smoother-gyro":
            backends[name] = Smoother(paper.model_copy(update={"mode": SmootherMode.GYRO}))
        elif name == "mekf":
            try:
                from .backends.mekf import Mekf, MekfConfig
            except ImportError as exc:
                notes[name] = f"not available ({exc})"
                continue
            backends[name] = Mekf(MekfConfig())
        else:
            raise InputError(f"unknown backend {name!r}; valid: {', '.join(BACKEND_NAMES)}")
    return backends, notes


def run_backend(backend: Backend, seq: VisualSequence) -> BackendRun:
    """Feed the sequence in time order: the IMU samples up to each frame, then the frame."""
    run = BackendRun(backend.name)
    if seq.has_imu:
        ends = np.searchsorted(seq.imu_t_s, seq.t_frame_s, side="right")
    start = 0
    for k, t in enumerate(seq.t_frame_s):
        t0 = time.perf_counter()
        if seq.has_imu and ends[k] > start:
            backend.process_imu(seq.imu_t_s[start:ends[k]], seq.imu_gyro_rad_s[start:ends[k]],
                                seq.imu_accel_m_s2[start:ends[k]])
            start = ends[k]
        run.estimates.append(backend.process_frame(float(t), seq.visuals[k]))
        run.latency_ms.append(1e3 * (time.perf_counter() - t0))
    return run


GRAVITY_AWARE = ("mekf", "smoother-gyro")
"""Backends whose tilt is absolute when an IMU is present: NEES after a yaw-only alignment."""
def errors_over_time(run: BackendRun, R_wc_true: np.ndarray, yaw_only_nees: bool = False) -> dict:
    """Per-frame ARE, tilt (deg) and NEES of an initialised run (`metrics.attitude_errors`); NaN where
    not initialised. `initialised` marks the scored frames."""
    ok = np.array([not (e.status & Status.NOT_INITIALISED) for e in run.estimates])
    err = attitude_errors(np.array([e.R_wc for e in run.estimates]), np.array([e.cov for e in run.estimates]),
                          ok, R_wc_true, yaw_only_nees)
    err["initialised"] = err.pop("valid")
    return err


def summarise(run: BackendRun, R_wc_true: np.ndarray | None, yaw_only_nees: bool = False) -> dict:
    """The table row of one backend (numbers as plain floats for JSON)."""
    lat = np.asarray(run.latency_ms)
    row = {"frames": len(run.estimates),
           "latency_ms_median": float(np.median(lat)), "latency_ms_p95": float(np.percentile(lat, 95)),
           "not_initialised": int(sum(bool(e.status & Status.NOT_INITIALISED) for e in run.estimates)),
           "optimiser_failed": int(sum(bool(e.status & Status.OPTIMISER_FAILED) for e in run.estimates))}
    if R_wc_true is not None:
        err = errors_over_time(run, R_wc_true, yaw_only_nees)
        ok = err["initialised"]
        a, t, ne = err["are_deg"][ok], err["tilt_deg"][ok], err["nees"][ok]
        row.update(are_deg_mean=float(a.mean()), are_deg_median=float(np.median(a)), are_deg_max=float(a.max()),
                   **jump_counts({**err, "valid": ok}), tilt_deg_mean=float(t.mean()),
                   tilt_deg_max=float(t.max()), nees_mean=float(ne.mean()), nees_median=float(np.median(ne)))
    return row


def compare(seq: VisualSequence, out_dir: str | Path, names=BACKEND_NAMES) -> dict:
    """Run the backends on `seq` and write compare.md, compare.json and compare.png into `out_dir`.

    Returns the JSON document: sequence name, notes, and one row per backend (see `summarise`);
    a backend that could not run has only a `note`.
    """
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{out}: cannot create the output folder ({exc.strerror or exc})") from None
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
        rows[name] = summarise(runs[name], seq.R_wc_true, yaw_only_nees=seq.has_imu and name in GRAVITY_AWARE)
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
        t = np.array([e.t for e in run.estimates])
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
    fig.savefig(path)
