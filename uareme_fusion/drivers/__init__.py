"""Input drivers: every source of frames and IMU samples behind one interface (`base.Source`).

    from uareme_fusion.drivers import open_source, merge_imu, record
    with open_source("clip.mp4", imu="imu.csv") as src:
        for event in src.events(): ...        # Frame or ImuBatch, in time order

See `registry.open_source` for the specs each driver takes.
"""

from .base import GroundTruth, ImuBatch, Source, SourceInfo
from .imu_csv import merge_imu
from .recorder import Recorder, record
from .registry import open_source

__all__ = ["GroundTruth", "ImuBatch", "Recorder", "Source", "SourceInfo", "merge_imu", "open_source", "record"]
