"""`uareme-fusion bench WHAT`: benchmarks that print absolute figures and ratios to their goals.

- `solver`: the single-frame solver's stages (one core), medians and p90;
- `pipeline`: end-to-end fps and per-stage ms at 640x480, and memory over a long stream (issue 7);
- `soak`: one simulated hour through the full pipeline: RSS growth, state sizes, accuracy (issue 8);
- `broad`: BROAD IMU trials with default options beside imu_only, vehicle and vqf 6D (issue 14);
- `horizon`: RGB-only accuracy on real data (ECD horizon AUC, ICSL and ICL-NUIM rotations and focal
  lengths) beside goals and baselines (issue 12);
- `mekf`: the EKF on simulated bus and room scenarios, BROAD and EuRoC, beside IMU-only peers (issues 5, 17);
- `smoother`: the GTSAM smoother (paper and gyro-aided) against `single` on walk and shake (issue 6);
- `realdata`: every real development sequence, each cue set and backend beside its goal and its best
  single input, with paired 95 % intervals (issues 29, 30);
- `normals`: the shipped network on torch and on ONNX Runtime, ms per map (two passes: the mirror average) and
  their difference (issue 28);
- `batch`: `batch` throughput on real IMU-only recordings with 1, 2 and N workers, and the scaling (issue 28).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from ..benchmarks import results_doc
from .app import app, fail

BENCHMARKS = ("solver", "pipeline", "soak", "broad", "horizon", "mekf", "smoother", "realdata", "batch", "normals")


@app.command()
def bench(
    ctx: typer.Context,
    what: str = typer.Argument("solver", help=f"Which benchmark: {', '.join(BENCHMARKS)}."),
    repeats: int = typer.Option(100, min=5, help="solver: timed runs per figure."),
    duration_s: Optional[float] = typer.Option(None, "--duration-s", min=1.0, max=86400.0,
                                               help="pipeline: length of the timed 640x480 room walk, s (default "
                                                    "10); soak: simulated stream length (30 fps, 400 Hz IMU), s "
                                                    "(default 3600)."),
    memory_duration_s: float = typer.Option(600.0, "--memory-duration-s", min=0.0, max=36000.0,
                                            help="pipeline: length of the memory stream, s (0: skip)."),
    normals: str = typer.Option("learned", "--normals", help="pipeline: learned or a model file (.pt, .onnx)."),
    normals_noise_deg: float = typer.Option(2.0, "--normals-noise-deg", min=0.0, max=90.0,
                                            help="soak: angular noise on the simulator's normals, deg."),
    preset: str = typer.Option("building", "--preset", help="soak: EKF preset (building, handheld, vehicle)."),
    data: Path = typer.Option(None, "--data", help="broad, mekf: folder of BROAD .hdf5 trials (default "
                              "../shared/data/broad_subset; needs the bench extra for vqf; mekf reads EuRoC "
                              "V1_02 from euroc_v1_02_first40s/ beside it); horizon, realdata, batch, normals: the development "
                              "data folder (default ../shared/data)."),
    seeds: int = typer.Option(5, "--seeds", min=1, max=100, help="mekf, smoother: seeds per scenario."),
    quick: bool = typer.Option(False, "--quick", help="mekf: shorter simulated runs; realdata: the first 20 frames "
                               "of each sequence, no corridor_more (neither the reported figures)."),
    sequences: str = typer.Option(None, "--sequences", help="realdata: comma-separated subset of tum, euroc, icsl, "
                                  "icsl_more, kt3 (default all)."),
    markdown_out: Path = typer.Option(None, "--markdown", help="realdata: also write the rows as a markdown table."),
    run_cost: bool = typer.Option(False, "--run-cost", help="mekf: only the whole-`run` cost per IMU sample on "
                                  "every IMU-only file, beside vqf and imufusion."),
    threads: int = typer.Option(None, "--threads", min=1, max=256,
                                help="pipeline: torch CPU threads of the learned normals (default 1)."),
    cues: str = typer.Option("normals,lines,sky", "--cues", help="horizon: visual cues (normals, lines, sky)."),
    ecd_limit: int = typer.Option(None, "--ecd-limit", min=1, help="horizon: score only the first N ECD images."),
    ecd_only: bool = typer.Option(False, "--ecd-only", help="horizon: only the ECD figures (a third of the time)."),
    uav_only: bool = typer.Option(False, "--uav-only", help="horizon: only the horizon_uav figures (open country)."),
    json_out: Path = typer.Option(None, "--json", help="Also write the figures to this JSON file."),
    results_md: Path = typer.Option(None, "--results", help="Also write what it prints into this markdown file's "
                                    "section for this benchmark (docs/results.md)."),
) -> None:
    """Time a benchmark on this machine and print its figures against the goals."""
    if what not in BENCHMARKS:
        raise typer.BadParameter(f"unknown benchmark '{what}'; choose from {', '.join(BENCHMARKS)}")
    for option, path in (("--json", json_out), ("--markdown", markdown_out)):
        if path is not None and (path.is_dir() or not path.parent.is_dir()):
            raise fail(f"{option} {path}: cannot write a file there (a folder, or its folder does not exist)")
    printed = results_doc.capture_stdout(results_md) if results_md is not None else None
    if what == "solver":
        from ..benchmarks import solver

        results = solver.run(repeats=repeats)
    elif what == "pipeline":
        from ..benchmarks import pipeline

        results = pipeline.run(duration_s or 10.0, memory_duration_s / 60.0, normals, threads)
    elif what == "broad":
        from ..benchmarks import broad

        results = broad.run(data or Path("../shared/data/broad_subset"))
    elif what == "horizon":
        from ..benchmarks import horizon

        data = data or Path("../shared/data")
        needed = "horizon_uav" if uav_only else "eurasian_cities"
        if not (data / needed).is_dir():
            raise fail(f"--data {data}: no {needed}/ folder there (the development data folder)")
        results = horizon.run(data, cues, ecd_limit, ecd_only=ecd_only, uav_only=uav_only)
    elif what == "mekf":
        from ..benchmarks import mekf

        results = mekf.run(seeds=seeds, quick=quick, broad_dir=data or Path("../shared/data/broad_subset"),
                           run_cost=run_cost)
    elif what == "realdata":
        from ..benchmarks import realdata, realdata_rows

        wanted = realdata.SEQUENCES if sequences is None else tuple(s.strip() for s in sequences.split(",") if s.strip())
        unknown = sorted(set(wanted) - set(realdata.SEQUENCES))
        if unknown:
            raise fail(f"--sequences: unknown {', '.join(unknown)}; choose from {', '.join(realdata.SEQUENCES)}")
        results = realdata.run(data or Path("../shared/data"), quick=quick, wanted=wanted)
        if markdown_out is not None:
            from ..io.safe_files import write_text_atomic

            write_text_atomic(markdown_out, realdata_rows.markdown(results))
    elif what == "normals":
        from ..benchmarks import normals

        results = normals.run(data or Path("../shared/data"), threads)
    elif what == "batch":
        from ..benchmarks import batch

        results = batch.run(data or Path("../shared/data"))
    elif what == "smoother":
        from ..benchmarks import smoother

        results = smoother.run(seeds=seeds)
    else:
        from ..benchmarks import soak

        results = soak.run(seconds=duration_s or 3600.0, normals_noise_deg=normals_noise_deg, preset=preset)
    if json_out is not None:
        from ..io.safe_files import write_text_atomic

        write_text_atomic(json_out, json.dumps(results, indent=2, default=float) + "\n")
    if printed is not None:
        results_doc.write_section(results_md, what, printed.stop(), results_doc.invoked_command(ctx))
