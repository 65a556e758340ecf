"""The image path's sky-first solve (pipeline/single_image.py `_sky_first`, solver/horizon_estimate.py
`sky_decides`, `sky_start`; solver/atlanta.py `vertical_segments`): the same decisions and horizons as the
structure-first path, without the focal-length search."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uareme_fusion.formats.images import read_rgb
from uareme_fusion.solver.line_detection import SegmentDetector
from uareme_fusion.pinhole import assumed_K
from uareme_fusion.solver.atlanta import estimate_horizon, vertical_segments
from uareme_fusion.solver.horizon_estimate import sky_start
from uareme_fusion.rotations import manhattan_symmetries
from uareme_fusion.types import NormalMap


def manhattan_normals(R_cm: np.ndarray, n: int = 3000, noise: float = 0.05, seed: int = 0) -> NormalMap:
    """Normals along the axes of `R_cm` (floor-heavy: 60 % along the third axis), with noise."""
    rng = np.random.default_rng(seed)
    axis = rng.choice(3, size=n, p=[0.2, 0.2, 0.6])
    normals = R_cm[:, axis].T * rng.choice([-1.0, 1.0], size=(n, 1)) + noise * rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return NormalMap(normals.reshape(50, 60, 3), np.full((50, 60), 10.0))


def angle_deg(R1: np.ndarray, R2: np.ndarray) -> float:
    """The smallest angle between `R1` and the 24 labellings of `R2`."""
    best = min(np.linalg.norm(Rotation.from_matrix(R1.T @ R2 @ S).as_rotvec()) for S in manhattan_symmetries())
    return float(np.degrees(best))


@pytest.mark.parametrize("rotvec", [[0.1, -0.3, 0.05], [-0.2, 1.2, 0.3], [0.4, 0.7, -0.1]])
def test_sky_start_keeps_the_sky_up_and_finds_the_turn_about_it(rotvec):
    R_cm = Rotation.from_rotvec(rotvec).as_matrix()
    up = R_cm[:, 2]
    start = sky_start(manhattan_normals(R_cm), up)
    assert start[:, 2] @ up == pytest.approx(1.0)
    assert np.linalg.det(start) == pytest.approx(1.0)
    assert angle_deg(start, R_cm) < 2.6  # the nearest of turns 5 deg apart
    assert sky_start(None, up) is None
    empty = NormalMap(np.zeros((4, 4, 3)), np.zeros((4, 4)))
    assert sky_start(empty, up) is None


def test_vertical_segments_is_the_atlanta_horizons_count(shared_data):
    """Real photos (ECD's buildings, horizon_uav's fields): the zenith step alone counts the verticals that
    the whole Atlanta horizon reports, so the sky's veto is decided as before."""
    photos = (sorted((shared_data / "eurasian_cities").glob("*.jpg"))[:60:6]
              + sorted((shared_data / "horizon_uav" / "images").glob("*.jpg"))[::25])
    detector = SegmentDetector(640)
    seen_both = 0
    for path in photos:
        rgb = read_rgb(path, 4_000_000)
        h, w = rgb.shape[:2]
        segments, K = detector.detect(rgb), assumed_K(h, w, 60.0)
        up = np.array([0.0, -1.0, 0.0])
        atlanta = estimate_horizon(segments, K, up)
        count = vertical_segments(segments, K, up)
        if atlanta is not None:
            assert count == pytest.approx(atlanta.n_vertical), path.name
            seen_both += count >= 15.0
    assert seen_both >= 5  # buildings: counts above the veto's 15


def test_drone_photos_take_the_sky_first_path_and_keep_the_sky_line(shared_data):
    """horizon_uav (real): photos without man-made verticals are solved once (focal length assumed), their
    horizon on the sky boundary."""
    from uareme_fusion.benchmarks.horizon_uav import label_line, roll_error_deg
    from uareme_fusion.pipeline.single_image import ImageAnalyser

    folder = shared_data / "horizon_uav"
    rows = list(csv.DictReader((folder / "label.csv").open()))[::40]
    analyser = ImageAnalyser()
    for row in rows:
        result = analyser.analyse(folder / "images" / row["filename"])
        doc = result.as_dict()
        assert doc["horizon_source"] == "sky" and doc["focal_source"] == "assumed" and doc["horizon_known"]
        assert roll_error_deg(result.horizon, result.sky.line) < 0.5
        truth = label_line(float(row["slope"]), float(row["offset"]), result.rgb.shape[0])
        assert roll_error_deg(result.horizon, truth) < 3.0
        assert np.all(np.isfinite(doc["std_deg"]))
