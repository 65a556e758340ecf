"""`uareme-fusion image IMAGE... [--json] [--out PNG|DIR] [--force] [--same-camera]`: images in; rotation,
covariance, up, focal length, horizon and an overlay out (the model is loaded once). `--same-camera`:
one camera's images, K pooled over them (`ImageAnalyser.analyse_same_camera`).

Several images write `<stem>.png` into the --out folder, named as `normals` names its outputs
(`a.png` and `a.jpg` become `a_png.png` and `a_jpg.png`); a non-empty folder, or an existing overlay
file for one image, needs `--force`."""

from __future__ import annotations

import json
from pathlib import Path
from typing import List, Optional

import numpy as np
import typer

from ..drivers.intrinsics import parse_intrinsics
from ..errors import InputError
from ..io.safe_files import refuse_input_as_output, write_image_atomic
from ..normals.export import unique_stems
from ..solver.cues import DEFAULT_CUES
from ..pipeline.session import make_output_folder, prepare_output_folder
from ..pipeline.single_image import ImageAnalyser, image_overlay, image_paths
from .app import app
from .run_cmd import _o


@app.command("image")
def image_command(
    image: List[Path] = typer.Argument(..., help="PNG/JPEG images of man-made scenes, or folders of them."),
    json_out: bool = typer.Option(False, "--json", help="Print one JSON object per image, one per line."),
    out: Optional[Path] = typer.Option(None, "--out", help="Overlay image (one input) or folder (several)."),
    normals: str = typer.Option("learned", "--normals", help="learned or a model file (.pt, .onnx)."),
    cues: str = typer.Option(DEFAULT_CUES, "--cues", help="Visual cues: normals, lines, sky (comma-separated; "
                             "sky: the sky/ground boundary of open scenes)."),
    fov_deg: float = typer.Option(60.0, "--fov-deg",
                                  help="Horizontal field of view assumed when the scene cannot tell the focal length."),
    intrinsics: Optional[str] = _o["intrinsics"],
    same_camera: bool = typer.Option(False, "--same-camera", help="The images come from one camera: without "
                                     "--intrinsics its focal length and principal point are pooled over all of "
                                     "them, then each image is solved again with that K (two passes)."),
    force: bool = typer.Option(False, "--force", help="Write into a non-empty --out folder, or replace an "
                               "existing --out image (overlays of the same name are replaced)."),
) -> None:
    """Manhattan rotation, covariance, up vector, focal length and horizon of images, with optional overlays."""
    if not 1.0 < fov_deg < 179.0:  # also refuses NaN
        raise InputError(f"--fov-deg must be between 1 and 179 degrees, got {fov_deg}")
    paths = image_paths(image)
    several = len(paths) > 1
    if out is not None and not several and out.suffix.lower() not in (".png", ".jpg", ".jpeg"):
        raise InputError(f"{out}: the overlay is an image; use a .png or .jpg name")
    camera = parse_intrinsics(intrinsics) if intrinsics is not None else None
    targets: list[Path | None] = [None] * len(paths)
    if out is not None:
        refuse_input_as_output(out, paths)
        if several:
            stems = unique_stems(paths)  # refused before the folder is made
            folder = prepare_output_folder(out, force)
            targets = [folder / f"{stem}.png" for stem in stems]
        else:
            if out.exists() and not force:
                raise InputError(f"--out {out} exists; pass --force to replace it")
            targets = [out]
    analyser = ImageAnalyser(normals, cues, camera=camera, assumed_fov_deg=fov_deg)
    results = (analyser.analyse_same_camera(paths, warn=lambda line: typer.echo(f"warning: --same-camera: {line}",
                                                                               err=True))
               if same_camera else map(analyser.analyse, paths))
    for target, result in zip(targets, results):
        if target is not None:
            make_output_folder(target.parent)
            write_image_atomic(target, image_overlay(result)[..., ::-1])
        doc = result.as_dict()
        if json_out:
            typer.echo(json.dumps(doc))
            continue
        _print_text(result, doc)


def _print_text(result, doc: dict) -> None:
    np.set_printoptions(precision=4, suppress=True)
    v = result.visual
    typer.echo(f"{result.path}: quality {v.quality:.2f}, {v.n_valid} valid pixels, "
               f"{doc['cues']['lines'].get('segments', 0)} line segments")
    typer.echo(f"R_cm (Manhattan axes as columns, camera frame):\n{result.R_cm}")
    typer.echo(f"std (deg) about x, y, z: {np.round(doc['std_deg'], 3)}")
    typer.echo(f"up in the camera frame: {np.round(result.up_c, 4)}")
    f_std = f" +- {doc['f_std_px']:.1f}" if doc["f_std_px"] is not None else ""
    typer.echo(f"focal length {doc['f_px']:.1f}{f_std} px ({doc['focal_source']}), HFOV {doc['hfov_deg']:.1f} deg")
    if not doc["horizon_known"]:
        typer.echo("horizon unknown: no man-made structure or sky boundary fixes it in this image")
    else:
        std = doc["horizon_std_px"]
        where = "" if doc["horizon_in_image"] else " (off-screen)"
        typer.echo(f"horizon a x + b y + c = 0: {np.round(doc['horizon'], 4)}{where}, from {doc['horizon_source']}"
                   + (f", std {std:.1f} px, {doc['horizon_angle_std_deg']:.2f} deg" if std is not None else ""))
    shares = ", ".join(f"{k} {e['share']:.2f}" for k, e in doc["cues"].items() if e.get("present"))
    typer.echo(f"information share: {shares}")
    typer.echo(", ".join(f"{k} {t:.1f} ms" for k, t in doc["timing_ms"].items()))
