"""Which visual cues a run uses (`--cues normals,lines`), and the per-frame line cue stage.

The line cue detects segments in each frame and hands them, with the frame's intrinsics, to the
joint solver (`solver/joint.py`). Without intrinsics, the focal length is estimated from the scene
(`solver/focal.py`) on frames until one gives a confident estimate, and then kept for the stream.
"""

from __future__ import annotations

from ..errors import ConfigError
from ..lines.detect import LineSegments, SegmentDetector

VALID_CUES = ("normals", "lines")
DEFAULT_CUES = "normals,lines"


def parse_cues(spec: str | tuple | list) -> tuple[str, ...]:
    """`"normals,lines"` -> ("normals", "lines"); an unknown or empty selection is a one-line ConfigError."""
    names = [s.strip() for s in (spec.split(",") if isinstance(spec, str) else spec)]
    names = [n for n in names if n]
    bad = [n for n in names if n not in VALID_CUES]
    if bad or not names:
        raise ConfigError(f"--cues {','.join(names) if isinstance(spec, (list, tuple)) else spec!r}: "
                          f"expected a comma-separated selection of {', '.join(VALID_CUES)}")
    return tuple(n for n in VALID_CUES if n in names)


class LineCue:
    """Segments of each frame (`detect(rgb) -> LineSegments`)."""

    name = "lines"

    def __init__(self, detector: SegmentDetector | None = None):
        self.detector = detector or SegmentDetector()

    def segments(self, rgb) -> LineSegments | None:
        return None if rgb is None else self.detector.detect(rgb)
