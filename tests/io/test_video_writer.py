"""Overlay videos: H.264 through PyAV when installed, OpenCV's writer otherwise (issue 16)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from uareme_fusion.cli import app
from uareme_fusion.io import video_writer
from uareme_fusion.io.video_writer import h264_available, open_video_encoder


def _frames(n: int, width: int, height: int) -> list[np.ndarray]:
    rng = np.random.default_rng(0)
    return [np.full((height, width, 3), rng.integers(0, 255, 3), np.uint8) for _ in range(n)]


def _read_back(path) -> list[np.ndarray]:
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, bgr = cap.read()
        if not ok:
            break
        frames.append(bgr[..., ::-1])
    cap.release()
    return frames


@pytest.mark.skipif(not h264_available(), reason="PyAV with libx264 is not installed")
def test_h264_with_odd_size_is_padded_and_reads_back(tmp_path):
    import av

    path = tmp_path / "o.mp4"
    frames = _frames(10, 65, 47)
    writer = open_video_encoder(path, 30.0, (65, 47))
    for rgb in frames:
        writer.write(rgb)
    writer.close()
    assert writer.name.startswith("h264")
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        assert stream.codec_context.name == "h264" and (stream.width, stream.height) == (66, 48)
    back = _read_back(path)
    assert len(back) == 10
    # flat colours survive the encoding within a few grey levels (padding is black, outside the crop)
    assert np.abs(back[3][:47, :65].astype(int) - frames[3]).mean() < 4


def test_opencv_writer_is_the_fallback(tmp_path, monkeypatch):
    monkeypatch.setattr(video_writer, "h264_available", lambda: False)
    path = tmp_path / "o.mp4"
    writer = open_video_encoder(path, 30.0, (64, 48))
    for rgb in _frames(5, 64, 48):
        writer.write(rgb)
    writer.close()
    assert writer.name == "mp4v (OpenCV)"
    assert len(_read_back(path)) == 5


def test_horizon_summary_names_the_encoder(tmp_path):
    out = tmp_path / "h.mp4"
    result = CliRunner().invoke(app, ["horizon", "sim:room", "--max-frames", "6", "--out", str(out)])
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "h.run" / "summary.json").read_text())
    expected = "h264 (PyAV libx264)" if h264_available() else "mp4v (OpenCV)"
    assert summary["videos"] == {"h.mp4": expected}
    assert expected in result.output
    assert len(_read_back(out)) == 6
