"""Command-line interface: `uareme-fusion COMMAND ...` (see `uareme-fusion --help`)."""

from .app import app, main

# Each import registers its commands on `app`.
from . import bench_cmd, demo_cmd, solve_cmd  # noqa: E402,F401
from . import compare_cmd  # noqa: E402,F401
from . import simulate_cmd  # noqa: E402,F401
from . import run_cmd  # noqa: E402,F401
from . import overlay_cmds  # noqa: E402,F401
from . import image_cmd  # noqa: E402,F401
from . import normals_cmd  # noqa: E402,F401
from . import batch_cmd  # noqa: E402,F401

__all__ = ["app", "main"]
