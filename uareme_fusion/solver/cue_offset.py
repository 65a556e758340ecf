"""A stream's steady disagreement between its normals and its segments, kept from turning into frame-to-frame error.

Alone, each cue has its own minimum; on real frames the two often differ by a steady rotation (the network's
bias on a kind of scene, segments on objects a little off the room's axes). EuRoC V1_01 micro, RGB: the
normals' and the segments' own rotations 11.4 deg apart on average, 0.8 deg about that from frame to frame.
The joint minimum lies between them at a fraction lambda_k (0 at the normals' own, 1 at the segments') that
follows the frame's information shares, so the steady offset times a fraction that changes from frame to
frame (0.72 +- 0.16 there) is frame-to-frame error that neither cue has: joint ARE 1.50 deg against 0.65 for
the normals alone.

So a stream keeps the mean offset dbar (weighted by lambda (1 - lambda): an offset says something only where
both cues count) and the mean fraction lbar, and each frame's joint rotation is moved by (lbar - lambda_k) dbar
(right perturbation): the steady part of the offset enters every frame with the stream's share, what changes
from frame to frame enters with the frame's own shares. The move is made only while dbar stands out of its
own spread (`min_offset_sigmas` standard errors): unbiased cues, or a segment cue near chance whose own
minimum wanders, move nothing. The covariance is left as it is.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..rotations import exp_so3
from ..types import VisualRotation


@dataclasses.dataclass(frozen=True)
class CueOffsetConfig:
    """When the steady offset is taken out (units in the names)."""

    min_offset_sigmas: float = 3.0
    """dbar is used only when its length exceeds this many of its standard errors."""
    min_frames: int = 3
    """Frames with both cues before anything is moved."""


class CueOffset:
    """The running means of one stream (`update` each frame's joint rotation in order; `reset` after a jump)."""

    def __init__(self, config: CueOffsetConfig | None = None):
        self.config = config or CueOffsetConfig()
        self.reset()

    def reset(self) -> None:
        self.frames = 0
        self._w = self._w2 = self._lam = 0.0
        self._wd = np.zeros(3)
        self._wdd = np.zeros(3)

    def offset(self) -> np.ndarray | None:
        """dbar (3,) rad when it stands out of its spread, else None."""
        if self.frames < self.config.min_frames or self._w <= 0:
            return None
        mean = self._wd / self._w
        var = np.maximum(self._wdd / self._w - mean**2, 0.0)
        n_eff = self._w**2 / max(self._w2, 1e-300)
        standard_error = np.sqrt(var.sum() / max(n_eff - 1.0, 1.0))
        return mean if np.linalg.norm(mean) > self.config.min_offset_sigmas * standard_error else None

    def update(self, visual: VisualRotation) -> VisualRotation:
        """`visual` moved by (lbar - lambda_k) dbar when it holds both cues' own minima (`JointSolver.solve`'s
        `cues[...]["own_offset_rad"]`), the running means updated with this frame first; else unchanged."""
        try:
            d_normals = np.asarray(visual.cues["normals"]["own_offset_rad"], float)
            d_lines = np.asarray(visual.cues["lines"]["own_offset_rad"], float)
        except KeyError:
            return visual
        if visual.jump_deg > 0 or visual.reason:
            self.reset()
        delta = d_lines - d_normals
        norm2 = float(delta @ delta)
        if not norm2 > 0 or not np.all(np.isfinite(delta)):
            return visual
        lam = float(np.clip(-d_normals @ delta / norm2, 0.0, 1.0))
        w = lam * (1.0 - lam)
        self.frames += 1
        self._lam += lam
        self._w += w
        self._w2 += w * w
        self._wd += w * delta
        self._wdd += w * delta**2
        dbar = self.offset()
        if dbar is None:
            return visual
        move = (self._lam / self.frames - lam) * dbar
        return dataclasses.replace(visual, R_cm=visual.R_cm @ exp_so3(move))
