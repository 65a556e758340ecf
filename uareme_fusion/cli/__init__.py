"""Command-line interface: `uareme-fusion COMMAND ...` (see `uareme-fusion --help`)."""

# Each import registers its commands on `app`.
from . import (  # noqa: E402,F401
    bench_cmd,
    compare_cmd,  # noqa: E402,F401
    demo_cmd,
    image_cmd,  # noqa: E402,F401
    normals_cmd,  # noqa: E402,F401
    overlay_cmds,  # noqa: E402,F401
    run_cmd,  # noqa: E402,F401
    simulate_cmd,  # noqa: E402,F401
    solve_cmd,
)
from .app import app, main

__all__ = ["app", "main"]
