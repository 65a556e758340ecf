"""Surface normal estimators: normals (H, W, 3) in the OpenCV camera frame and confidence kappa (H, W).

`DepthNormals` fits local planes to a depth map; `kappa_loss` holds the paper's training loss
(eq. 2-3, torch imported only when it is used).
"""

from .depth import DepthNormals, DepthNormalsConfig, read_depth_png

__all__ = ["DepthNormals", "DepthNormalsConfig", "read_depth_png"]
