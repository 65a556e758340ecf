"""`uareme-fusion image IMAGE [--json] [--out PNG]`: one image in, rotation, covariance, up and an overlay out."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import numpy as np
import typer

from ..drivers.intrinsics import parse_intrinsics
from ..errors import InputError
from ..io.safe_files import refuse_input_as_output, write_image_atomic
from ..pipeline.session import make_output_folder
from ..pipeline.single_image import analyse_image, image_overlay
from .app import app
from .run_cmd import _o


@app.command("image")
def image_command(
    image: Path = typer.Argument(..., help="A PNG/JPEG image of a man-made scene."),
    json_out: bool = typer.Option(False, "--json", help="Print the result as JSON."),
    out: Optional[Path] = typer.Option(None, "--out", help="Write the overlay (horizon, axes, normal panes) here."),
    normals: str = typer.Option("learned", "--normals", help="learned or a model file (.pt)."),
    fov_deg: float = typer.Option(60.0, "--fov-deg", help="Assumed horizontal field of view for drawing, degrees."),
    intrinsics: Optional[str] = _o["intrinsics"],
) -> None:
    """Manhattan rotation, its covariance and the up vector of one image, with an optional overlay."""
    if not 1.0 < fov_deg < 179.0:  # also refuses NaN
        raise InputError(f"--fov-deg must be between 1 and 179 degrees, got {fov_deg}")
    if out is not None and out.suffix.lower() not in (".png", ".jpg", ".jpeg"):
        raise InputError(f"{out}: the overlay is an image; use a .png or .jpg name")
    camera = parse_intrinsics(intrinsics) if intrinsics is not None else None
    if out is not None:
        refuse_input_as_output(out, [image])
    result = analyse_image(image, normals, camera=camera)
    if out is not None:
        overlay = image_overlay(result, fov_deg=fov_deg)
        make_output_folder(out.parent)
        write_image_atomic(out, overlay[..., ::-1])
    doc = result.as_dict()
    if json_out:
        typer.echo(json.dumps(doc, indent=2))
        return
    np.set_printoptions(precision=4, suppress=True)
    typer.echo(f"{image}: quality {result.visual.quality:.2f}, {result.visual.n_valid} valid pixels")
    typer.echo(f"R_cm (Manhattan axes as columns, camera frame):\n{result.visual.R_cm}")
    typer.echo(f"std (deg) about x, y, z: {np.round(doc['std_deg'], 3)}")
    typer.echo(f"up in the camera frame: {np.round(result.up_c, 4)}")
    typer.echo(f"normals {doc['timing_ms']['normals']:.1f} ms, solver {doc['timing_ms']['solver']:.1f} ms")
    if out is not None:
        typer.echo(f"wrote {out}")
