"""The Manhattan labelling of a camera-only stream, chained from frame to frame.

A visual rotation `R_cm` is known up to the 24 symmetries of the Manhattan frame; a backend without an
IMU has to pick one per frame. Picking the one nearest its own prediction lets a wrong prediction
choose the labelling: on the real TUM fr1 rpy evaluation frames (handheld, 100 deg/s, learned normals)
the visual-only EKF coasted 48 deg away from the rotations during five gated-out frames, then took
the frame 90 deg relabelled and kept that labelling to the end (ARE 34.7 deg against `single`'s
24.4 with the same rotations); on ICSL corridor_more (lines only) it re-initialised nearest an
estimate that had spun 150 deg away (42.6 against 3.3). The rotations themselves moved by a few
degrees per frame there, so the labelling nearest the previous frame's rotation (what `single` keeps)
was the right one. Labelled by the chain (and re-initialised once two disagreeing frames agree), the
EKF gives 23.83 there (`single` 24.44, same rotations) and 3.17 on ICSL corridor_more lines (3.30).

`VisualLabelChain` labels each frame's rotation nearest the last one the filter trusted: the
filter's innovation is then measured against a labelling the filter's own error cannot change, and
a filter that drifts shows it as a growing innovation (the disagreement that re-initialises it), not
as a silent relabelling.
"""

from __future__ import annotations

import numpy as np

from ..types import VisualRotation


class VisualLabelChain:
    """Each frame's `VisualRotation` relabelled nearest the previous frame's (module docstring)."""

    def __init__(self):
        self.R_cm: np.ndarray | None = None
        """The last labelled rotation `R_cm` (3, 3), None before the first."""

    def start(self, visual: VisualRotation) -> None:
        """Start the chain at `visual` as it is labelled (a backend's first frame or re-initialisation)."""
        self.R_cm = np.array(visual.R_cm, float)

    def label(self, visual: VisualRotation) -> VisualRotation:
        """`visual` labelled nearest the chain's end (as given before the first); a non-finite rotation
        is returned as it is. The caller `take`s the frames it trusts (a frame off by far more than its
        covariance, a solver's wrong minimum, must not become the reference of the next)."""
        if self.R_cm is None or not np.isfinite(visual.R_cm).all():
            return visual
        return visual.symmetric_to(self.R_cm)

    def take(self, visual: VisualRotation) -> None:
        """`visual` (labelled by `label`) as the chain's new end."""
        self.R_cm = np.array(visual.R_cm, float)
