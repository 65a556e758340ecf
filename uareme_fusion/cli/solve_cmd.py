"""`uareme-fusion solve FILE`: bring your own normals, get the Manhattan rotation and covariance."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from ..errors import InputError
from ..io.normal_maps import NORMAL_FRAMES, load_normal_map
from ..rotations import quat_xyzw
from ..solver.manhattan import solve_manhattan, up_candidate
from .app import app


def solve_report(path: Path, frame: str) -> dict:
    """Solve one normal-map file and return the JSON-ready report."""
    normal_map = load_normal_map(path, frame=frame)
    try:
        result = solve_manhattan(normal_map.normals, normal_map.kappa)
    except InputError as exc:  # e.g. no valid normals: the message names the map's shape, not the file
        raise InputError(f"{path}: {exc}") from None
    axis, up_c = up_candidate(result.R_cm)
    std_deg = np.degrees(np.sqrt(np.diag(result.cov)))
    return {
        "file": str(path),
        "shape": list(normal_map.normals.shape[:2]),
        "R_cm": result.R_cm.round(9).tolist(),
        "quat_cm_xyzw": quat_xyzw(result.R_cm).round(9).tolist(),
        "cov_rad2": result.cov.tolist(),
        "std_deg": std_deg.round(6).tolist(),
        "up_candidate_axis": axis,
        "up_candidate_c": up_c.round(9).tolist(),
        "cost": result.cost,
        "quality": result.quality,
        "iterations": result.iterations,
        "n_valid": result.n_valid,
        "n_invalid": result.n_invalid,
        "solve_ms": result.timing_ms["moments"] + result.timing_ms["optimise"],
        "timing_ms": result.timing_ms,
        "convention": "R_cm maps Manhattan to camera (OpenCV: x right, y down, z forward); "
        "cov is of delta in R_true = R_cm @ Exp(delta), rad^2; quaternion order x y z w",
    }


@app.command()
def solve(
    file: Path = typer.Argument(..., help="Normal map: .npy/.npz (H,W,3 [+kappa]) or a normal PNG (X-Y-Z as R-G-B)."),
    json_out: bool = typer.Option(False, "--json", help="Print the result as JSON."),
    frame: str = typer.Option("opencv", help=f"Axes of the stored normals: {' or '.join(NORMAL_FRAMES)}."),
) -> None:
    """Manhattan rotation R_cm, its covariance and the up axis from a normal map you bring."""
    report = solve_report(file, frame)
    if json_out:
        typer.echo(json.dumps(report, indent=2))
        return
    table = Table(title=f"Manhattan rotation of {file.name}", show_header=False)
    table.add_row("quaternion R_cm (x y z w)", " ".join(f"{v:+.6f}" for v in report["quat_cm_xyzw"]))
    table.add_row("std about delta axes (deg)", " ".join(f"{v:.4f}" for v in report["std_deg"]))
    table.add_row("up candidate (camera frame)", " ".join(f"{v:+.4f}" for v in report["up_candidate_c"]))
    table.add_row("cost / quality", f"{report['cost']:.4f} / {report['quality']:.3f}")
    table.add_row("valid / invalid pixels", f"{report['n_valid']} / {report['n_invalid']}")
    table.add_row("solve time", f"{report['solve_ms']:.2f} ms ({report['iterations']} iterations)")
    Console().print(table)
