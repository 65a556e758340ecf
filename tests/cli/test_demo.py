"""The built-in demo runs offline and shows what it claims."""

import io

import pytest
from rich.console import Console

from uareme_fusion.demo import solver_demo


def test_solver_demo_figures():
    out = io.StringIO()
    figures = solver_demo(Console(file=out, width=120))
    assert figures["3 deg noise"]["error_deg"] < 0.1
    assert figures["10 deg correlated"]["error_deg"] < 1.5
    assert figures["+30% outliers"]["error_deg"] < 2.0
    wall = figures["blank wall*"]
    assert wall["error_deg"] < 0.5 and max(wall["std_deg"]) > 50
    assert "Manhattan solver" in out.getvalue()


@pytest.mark.slow
def test_rendered_fusion_demo_figures(tmp_path):
    """Room and bus rendered and run through the pipeline (the simulator's normals, half the scenes'
    length, half the frame rate and a quarter of the pixels, to stay fast; at 120x90 the line cue has too few
    pixels per segment and the bus p95 reaches 1.08 deg)."""
    from uareme_fusion.demo import fusion_demo

    out = io.StringIO()
    figures = fusion_demo(Console(file=out, width=120), tmp_path, normals="source", scale_seconds=0.5,
                          size=(160, 120), fps=7.5)
    bus = figures["bus"]
    fused = bus["fused (mekf, vehicle)"]
    assert fused["p95"] <= 1.0 and fused["max"] <= 2.0
    # The IMU alone tilts in the bus's turns and brakes: fusion is several times better.
    assert bus["IMU only (our filter)"]["p95"] > 3 * fused["p95"]
    assert figures["room"]["fused (mekf, handheld)"]["mean"] < 1.0
    assert (tmp_path / "demo_tilt.png").stat().st_size > 10_000
    assert (tmp_path / "demo_bus_horizon.mp4").stat().st_size > 10_000
    assert "Tilt error" in out.getvalue()
