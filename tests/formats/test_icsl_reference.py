"""The ICSL depth reference's inverse-depth offset (`formats.datasets.corrected_icsl_depth`)."""

import numpy as np

from uareme_fusion.formats.datasets import ICSL_CORRIDOR_K, ICSL_INVERSE_DEPTH_OFFSET_PER_M, corrected_icsl_depth
from uareme_fusion.normals.depth import DepthNormals


def test_the_offset_comes_off_the_inverse_depth_and_missing_depth_stays_missing():
    depth = np.array([[0.0, 3.0, 2.0 / ICSL_INVERSE_DEPTH_OFFSET_PER_M]], np.float32)
    out = corrected_icsl_depth(depth)
    assert out[0, 0] == 0.0
    np.testing.assert_allclose(1.0 / out[0, 1], 1.0 / 3.0 - ICSL_INVERSE_DEPTH_OFFSET_PER_M, rtol=1e-6)
    assert out[0, 2] == 0.0  # an inverse depth below the offset: no depth rather than a negative one
    assert corrected_icsl_depth(depth, 0.0)[0, 1] == np.float32(3.0)


def _mean_normal(normals, kappa, columns):
    n = normals[:, columns][kappa[:, columns] > 0]
    m = n.sum(0)
    return m / np.linalg.norm(m)


def test_an_inverse_depth_offset_splays_parallel_walls_and_taking_it_off_makes_them_parallel():
    """Two walls 1 m either side of the camera, looking along them; a sensor that adds b to the inverse
    depth tilts each by about b d (here 1 m) towards the optical axis: 2 b rad between them."""
    K = ICSL_CORRIDOR_K
    height, width = 480, 640
    x_bar = (np.arange(width) - K[0, 2]) / K[0, 0]
    inverse_true = np.broadcast_to(np.abs(x_bar), (height, width)).astype(np.float32)
    seen = inverse_true > 0.2  # nearer than 5 m
    depth_read = np.where(seen, 1.0 / (inverse_true + ICSL_INVERSE_DEPTH_OFFSET_PER_M), 0.0).astype(np.float32)
    left, right = x_bar < -0.2, x_bar > 0.2

    def walls_angle_deg(depth):
        nm = DepthNormals().estimate(depth, K)
        a, b = _mean_normal(nm.normals, nm.kappa, left), _mean_normal(nm.normals, nm.kappa, right)
        return np.degrees(np.arccos(abs(a @ b)))

    raw = walls_angle_deg(depth_read)
    assert abs(raw - np.degrees(2 * ICSL_INVERSE_DEPTH_OFFSET_PER_M)) < 0.1
    assert walls_angle_deg(corrected_icsl_depth(depth_read)) < 0.02
