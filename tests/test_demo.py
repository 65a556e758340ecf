"""The built-in demo runs offline and shows what it claims."""

import io

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


def test_bus_fusion_demo_figures(tmp_path):
    from uareme_fusion.demo import fusion_demo

    figures = fusion_demo(Console(file=io.StringIO(), width=120), tmp_path)
    fused = figures["fused (mekf, vehicle preset)"]
    assert fused["p95"] <= 1.0 and fused["max"] <= 2.0
    # Vision alone has blank frames; the IMU alone tilts in turns: fusion beats both.
    assert figures["vision only (single frame)"]["max"] > 10 * fused["max"]
    assert figures["IMU only (our filter)"]["p95"] > 3 * fused["p95"]
    assert (tmp_path / "demo_bus_tilt.png").stat().st_size > 10_000
