"""Zenith and horizontal vanishing points by consensus and J-linkage (solver/zenith.py,
solver/horizontal_vps.py, solver/vp_linkage.py)."""

import math

import numpy as np
import pytest

from uareme_fusion.overlay.camera import assumed_K
from uareme_fusion.rotations import exp_so3
from uareme_fusion.sim.line_segments import manhattan_segments
from uareme_fusion.solver.horizontal_vps import fitted_vp, horizontal_vps
from uareme_fusion.solver.vp_linkage import linkage_vps
from uareme_fusion.solver.zenith import estimate_zenith, miss_angles, segment_lines

W, H = 640, 480
LEVEL = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])  # world (x fwd, z up) to camera


def _centred(segments, K):
    """End points centred on the principal point and scaled by the diagonal, with that scale."""
    scale = math.hypot(W, H)
    return (segments.endpoints_px - K[:2, 2]) / scale, scale


def _vp_centred(direction_c, K, scale):
    """The homogeneous VP of camera-frame direction `direction_c` in centred, scaled coordinates."""
    return np.array([K[0, 0] * direction_c[0], K[1, 1] * direction_c[1], direction_c[2] * scale])


def _angle_deg(a, b):
    """Angle between two homogeneous points as directions through the camera (same scaling)."""
    return math.degrees(math.acos(min(1.0, abs(a @ b) / np.linalg.norm(a) / np.linalg.norm(b))))


def test_zenith_found_far_from_a_wrong_guess_and_despite_clutter():
    rng = np.random.default_rng(5)
    K = assumed_K(H, W, 60.0)
    R_cw = exp_so3(np.radians([-20.0, 0.0, 3.0])) @ LEVEL  # looking 20 deg up, rolled 3 deg
    segments = manhattan_segments(R_cw, K, W, H, per_axis=(20, 20, 25), clutter=30, rng=rng)
    ends, scale = _centred(segments, K)
    up_c = R_cw[:, 2]
    truth = _vp_centred(up_c, K, scale)
    wrong_guess = _vp_centred(exp_so3(np.radians([0.0, 0.0, 25.0])) @ up_c, K, scale)  # 25 deg off
    found = estimate_zenith(ends, segments.weights, np.full(len(ends), 1e-3), wrong_guess,
                            np.array([W, H]) / 2 / scale)
    assert _angle_deg(found.point, truth) < 0.5
    assert found.point[:2] @ truth[:2] > 0  # oriented towards the sky
    assert found.n_effective > 15  # the 25 vertical segments, not the clutter


def test_zenith_inside_the_image_is_never_proposed():
    """Segments radiating from a point inside the frame (ground markings) make no zenith."""
    from uareme_fusion.solver.line_detection import LineSegments

    rng = np.random.default_rng(1)
    centre = np.array([300.0, 400.0])
    angles = rng.uniform(-0.6, 0.6, 30) - math.pi / 2
    d = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    ends = np.stack([centre + 40 * d, centre + 160 * d], axis=1)
    vertical = np.array([[[x, 100.0], [x + 0.5, 300.0]] for x in (50.0, 200.0, 450.0, 600.0)])
    segments = LineSegments(np.concatenate([ends, vertical]), np.full(34, 0.1), H, W)
    K = assumed_K(H, W, 60.0)
    c_ends, scale = _centred(segments, K)
    found = estimate_zenith(c_ends, segments.weights, np.full(34, 1e-3), np.array([0.0, -1.0, 0.0]),
                            np.array([W, H]) / 2 / scale)
    point = found.point[:2] / found.point[2] * scale + K[:2, 2] if abs(found.point[2]) > 1e-9 else None
    assert point is None or not (0 <= point[0] < W and 0 <= point[1] < H)
    assert found.inliers[30:].all()


def test_horizontal_vps_of_two_directions_in_order_of_support():
    rng = np.random.default_rng(2)
    K = assumed_K(H, W, 60.0)
    R_cw = exp_so3(np.radians([-10.0, 0.0, 0.0])) @ LEVEL @ exp_so3(np.radians([0.0, 0.0, 30.0]))
    segments = manhattan_segments(R_cw, K, W, H, per_axis=(30, 15, 0), noise_px=0.3, rng=rng)
    ends, scale = _centred(segments, K)
    lines = segment_lines(ends)
    i, j = np.triu_indices(len(ends), 1)
    found = horizontal_vps(ends, segments.weights, lines, np.full(len(ends), 1e-3), np.cross(lines[i], lines[j]))
    assert len(found) == 2 and found[0].support > found[1].support
    truths = [_vp_centred(R_cw[:, axis], K, scale) for axis in (0, 1)]
    for vp in found:
        axis = int(np.argmin([_angle_deg(vp.point, t) for t in truths]))
        assert _angle_deg(vp.point, truths[axis]) < 0.5
        members = slice(0, 30) if axis == 0 else slice(30, 45)
        assert np.median(miss_angles(ends[members], vp.point[None])) < math.radians(0.5)
        assert abs(vp.n_inliers - (30 if axis == 0 else 15)) <= 2


def test_linkage_finds_both_horizontal_vps_among_clutter():
    rng = np.random.default_rng(5)
    K = assumed_K(H, W, 60.0)
    R_cw = exp_so3(np.radians([-8.0, 0.0, 0.0])) @ LEVEL @ exp_so3(np.radians([0.0, 0.0, 35.0]))
    segments = manhattan_segments(R_cw, K, W, H, per_axis=(25, 15, 0), noise_px=0.3, clutter=25, rng=rng)
    ends, scale = _centred(segments, K)
    lines = segment_lines(ends)
    i, j = np.triu_indices(len(ends), 1)
    found = linkage_vps(ends, segments.weights, lines, np.full(len(ends), 1e-3), np.cross(lines[i], lines[j]))
    truths = [_vp_centred(R_cw[:, axis], K, scale) for axis in (0, 1)]
    assert len(found) >= 2
    for axis, truth in enumerate(truths):
        best = min(found, key=lambda vp: _angle_deg(vp.point, truth))
        assert _angle_deg(best.point, truth) < 0.5
        assert abs(best.n_inliers - (25 if axis == 0 else 15)) <= 3
    # The two strongest are the two directions, not clutter.
    assert {int(np.argmin([_angle_deg(vp.point, t) for t in truths])) for vp in found[:2]} == {0, 1}
    assert all(min(_angle_deg(vp.point, t) for t in truths) < 0.5 for vp in found[:2])


def test_fitted_vp_distance_is_the_weighted_mean_distance_of_its_segments():
    """Segments on rays from a point at 0.5 and 2.0 from it, weights 3 : 1: distance (3 * 0.5 + 2) / 4."""
    point = np.array([0.3, -0.1])
    angles = np.radians([10.0, 50.0, 100.0, 170.0])
    ends, weights = [], []
    for k, a in enumerate(angles):
        u = np.array([math.cos(a), math.sin(a)])
        r = 0.5 if k % 2 == 0 else 2.0
        ends.append([point + (r - 0.05) * u, point + (r + 0.05) * u])
        weights.append(3.0 if r == 0.5 else 1.0)
    ends, weights = np.array(ends), np.array(weights)
    vp = fitted_vp(ends, segment_lines(ends), weights, np.full(4, 1e-3), np.arange(4))
    assert np.allclose(vp.point[:2] / vp.point[2], point, atol=1e-9)
    assert vp.distance == pytest.approx((3.0 * 0.5 + 2.0) / 4.0)
    assert vp.support == pytest.approx(weights.sum())  # every segment points at it
