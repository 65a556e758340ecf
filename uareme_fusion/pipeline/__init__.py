"""The streaming pipeline (docs/design.md "Data flow"): source -> normals -> solver -> backend -> sinks.

    from uareme_fusion.pipeline import RunConfig, run_to_folder
    summary = run_to_folder("clip.mp4", "out/", RunConfig(backend="mekf"), imu="imu.csv")
"""

from .config import RunConfig
from .runner import FrameResult, Pipeline, RunStats
from .session import run_to_folder

__all__ = ["FrameResult", "Pipeline", "RunConfig", "RunStats", "run_to_folder"]
