"""Surface normal estimators: normals (H, W, 3) in the OpenCV camera frame and confidence kappa (H, W).

`DepthNormals` fits local planes to a depth map; `LearnedNormals` runs a trained network on RGB
(torch is imported only when it is first used); `kappa_loss` holds the paper's training loss
(eq. 2-3, torch imported only when it is used).
"""

from .depth import DepthNormals, DepthNormalsConfig, read_depth_png

__all__ = ["DepthNormals", "DepthNormalsConfig", "LearnedNormals", "LearnedNormalsConfig", "read_depth_png"]


def __getattr__(name: str):
    if name in ("LearnedNormals", "LearnedNormalsConfig"):
        from . import learned

        return getattr(learned, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
