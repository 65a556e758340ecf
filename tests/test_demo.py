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
