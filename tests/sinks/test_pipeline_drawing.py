"""Drawing sinks: the horizon overlay video and the ground masks, on a simulated walk."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from uareme_fusion.errors import InputError
from uareme_fusion.pipeline import RunConfig
from uareme_fusion.sinks.drawing import GroundSink, HorizonVideoSink, VideoFileWriter
from uareme_fusion.pipeline.session import run_source
from uareme_fusion.types import Frame

from helpers import WalkSource  # pytest puts tests/ on sys.path


class PaintedWalk(WalkSource):
    """The walk with a grey image per frame, so the sinks have something to draw on."""

    def events(self):
        for ev in super().events():
            if isinstance(ev, Frame):
                ev = dataclasses.replace(ev, rgb=np.full((60, 80, 3), 90, np.uint8))
            yield ev


def read_video(path):
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, image = cap.read()
        if not ok:
            break
        frames.append(image)
    cap.release()
    return frames


@pytest.mark.parametrize("panes,width", [(False, 80), (True, 240)])
def test_horizon_video_has_every_frame_with_the_line_drawn(tmp_path, panes, width):
    src = PaintedWalk(seconds=2.0)
    sink = HorizonVideoSink(tmp_path / "h.avi", fps=15, panes=panes)
    summary = run_source(src, tmp_path / "run", RunConfig(mekf_preset="building"), extra_sinks=[sink])
    frames = read_video(tmp_path / "h.avi")
    assert len(frames) == summary["frames"] == len(src.t_frame)
    assert frames[0].shape == (60, width, 3)
    # Something was drawn on the grey frame (horizon, axes, the assumed-FOV note).
    changed = np.abs(frames[-1][:, :80].astype(int) - 90).max(axis=2) > 40
    assert changed.mean() > 0.02


def test_ground_sink_finds_the_floor(tmp_path):
    src = PaintedWalk(seconds=1.0)
    run_source(src, tmp_path, RunConfig(mekf_preset="building"), extra_sinks=[GroundSink(tmp_path, 15.0)])
    masks = sorted((tmp_path / "masks").glob("*.png"))
    overlays = sorted((tmp_path / "overlay").glob("*.png"))
    assert len(masks) == len(overlays) == len(src.t_frame)
    mask = cv2.imread(str(masks[-1]), cv2.IMREAD_UNCHANGED)
    assert mask.shape == (60, 80) and set(np.unique(mask)) <= {0, 255}
    # manhattan_normal_map shows the floor in part of the view: some ground, not all of it.
    assert 0.02 < (mask > 0).mean() < 0.9


def test_video_writer_rejects_unknown_extension(tmp_path):
    with pytest.raises(InputError, match="unsupported video extension"):
        VideoFileWriter(tmp_path / "x.gif", 30)
