"""Line segments: the vanishing-line cue (docs/design.md "Vanishing lines").

`detect.detect_segments` finds weighted segments in an image; the maths that turns them into a
Manhattan cost lives in `solver/lines.py`, and the focal length from them in `solver/focal.py`.
"""

from .detect import LineSegments, SegmentDetector, detect_segments

__all__ = ["LineSegments", "SegmentDetector", "detect_segments"]
