"""When a stream looks for a sky boundary (`solver/sky_horizon.py`): only on the frames where it can matter.

The sky detector costs about 5 ms of CPU a 640x480 frame (with `sky_decides`' look at the segments),
which is an eighth of a 40 fps frame. Indoors it never fires (walls and ceilings fail its checks), and
where man-made structure holds the camera's tilt a sky would add little. So a frame is looked at when
- the last frame looked at had a sky (an open scene: the boundary is followed on every frame), or
- the last solve's tilt is weak: the standard deviation of its up vector, in its weaker direction, is
  above `SkyCadenceConfig.tilt_std_deg` (the other cues cannot hold it), or
- `SkyCadenceConfig.every_frames` frames have passed since the last look (a scene that opens up, or a
  sky that was missed, is found within that many frames: a third of a second at 30 fps).
A frame that is not looked at has no sky cue (the filter carries the tilt); it does not reuse an older
boundary, which moves with the camera.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .horizon_estimate import up_covariance
from .manhattan import up_candidate


@dataclass(frozen=True)
class SkyCadenceConfig:
    every_frames: int = 10
    """Look at least once every this many frames (1: every frame)."""
    tilt_std_deg: float = 2.0
    """Look on the next frame when the last solve's up is less certain than this in its weaker direction."""


class SkyCadence:
    """`look()` before a frame: whether to run the sky detector on it; `seen(found, visual)` after it."""

    def __init__(self, config: SkyCadenceConfig | None = None):
        self.config = config or SkyCadenceConfig()
        self._since_look = self.config.every_frames - 1
        """Frames since the last look (the first frame is looked at)."""
        self._sky_last = False
        self._tilt_weak = True
        self.frames = self.looks = 0
        """Frames asked about and frames looked at."""

    def look(self) -> bool:
        self._since_look += 1
        due = self._sky_last or self._tilt_weak or self._since_look >= self.config.every_frames
        self._since_look = 0 if due else self._since_look
        self.frames += 1
        self.looks += due
        return due

    def seen(self, looked: bool, found: bool, visual) -> None:
        """After a frame: whether it was looked at (`look()`), whether a sky was found, and its solve
        (a `VisualRotation`, or None when no cue was usable: the tilt is then weak)."""
        if looked:
            self._sky_last = found
        self._tilt_weak = visual is None or tilt_std_deg(visual.R_cm, visual.cov) > self.config.tilt_std_deg


def tilt_std_deg(R_cm: np.ndarray, cov_rad2: np.ndarray) -> float:
    """Standard deviation (deg) of the up vector (the axis of `R_cm` nearest image up, `up_candidate`) in its
    less certain direction, from the rotation's covariance (right perturbation, rad^2)."""
    up_c = up_candidate(R_cm)[1]
    cov_up = up_covariance(R_cm, cov_rad2, up_c)
    return float(np.degrees(np.sqrt(max(np.linalg.eigvalsh(0.5 * (cov_up + cov_up.T))[-1], 0.0))))
