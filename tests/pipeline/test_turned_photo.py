"""The quarter-turn geometry of `pipeline/turned_photo.py` (issue 26: a photo turned 90, 180 or 270 deg is
answered upright and carried back): pixels, lines, K and up map back consistently, and the sky side picks
the turn."""

from __future__ import annotations

import numpy as np
import pytest

from uareme_fusion.benchmarks.turned import sky_side_up, turned_line, verdict
from uareme_fusion.overlay.horizon import horizon_line
from uareme_fusion.pipeline.turned_photo import mapped_line, quarter_turn, sky_quarters, turned_photo

H, W = 5, 7


@pytest.mark.parametrize("quarters", [0, 1, 2, 3])
def test_the_pixel_map_is_the_turned_array(quarters):
    """Every pixel of an image with distinct values lands where `T` says in `np.rot90(rgb, k=-quarters)`."""
    image = np.arange(H * W).reshape(H, W)
    turned = turned_photo(image[..., None], quarters)[..., 0]
    T, _ = quarter_turn(H, W, quarters)
    for y in range(H):
        for x in range(W):
            u, v, s = T @ [x, y, 1.0]
            assert turned[int(round(v / s)), int(round(u / s))] == image[y, x]


@pytest.mark.parametrize("quarters", [1, 2, 3])
def test_up_k_and_the_horizon_map_back_together(quarters):
    """With K_t = T K R_z^T (the turned camera), the horizon of up_t under K_t, carried back by T^-1, is the
    horizon of R_z^T up_t under T^-1 K_t R_z = K (one answer both ways); K stays upper triangular."""
    K = np.array([[800.0, 0.0, 3.2], [0.0, 790.0, 2.1], [0.0, 0.0, 1.0]])
    T, R_z = quarter_turn(H, W, quarters)
    K_t = T @ K @ R_z.T
    assert np.allclose(np.tril(K_t, -1), 0.0) and K_t[2, 2] == pytest.approx(1.0)
    up_t = np.array([0.1, -0.9, 0.3]) / np.linalg.norm([0.1, -0.9, 0.3])
    back = mapped_line(horizon_line(up_t, K_t), np.linalg.inv(T))
    assert np.allclose(np.linalg.inv(T) @ K_t @ R_z, K)
    assert np.allclose(back, horizon_line(R_z.T @ up_t, K), atol=1e-9)


def test_sky_quarters_bring_the_sky_to_the_top():
    """A sky on the right takes three clockwise turns, below two, on the left one; on top none."""
    assert [sky_quarters(np.array([*n, 0.0])) for n in ((0, -1), (1, 0), (0, 1), (-1, 0))] == [0, 3, 2, 1]
    for quarters in (1, 2, 3):  # a sky put on a side by the turn comes back on top
        side = turned_line([0.0, -1.0, 2.0], H, W, quarters)
        assert (sky_quarters(side) + quarters) % 4 == 0


def test_a_verdict_is_scored_upright_and_knows_the_sky_side():
    """The turned photo's true horizon carried into it is "right"; the same line with the sky below is
    "wrong" (180 deg: the line is right, up is not); not known is "declined"."""
    truth = sky_side_up(np.array([0.05, 1.0, -3.0]) / np.hypot(0.05, 1.0))
    assert truth[1] < 0
    for quarters in (0, 1, 2, 3):
        line = turned_line(truth, 768, 1152, quarters)
        assert verdict(True, line, truth, 768, 1152, quarters)["verdict"] == "right"
        assert verdict(True, -line, truth, 768, 1152, quarters)["verdict"] == "wrong"
        assert verdict(False, line, truth, 768, 1152, quarters)["verdict"] == "declined"
