"""When a stream looks for a sky (solver/sky_cadence.py), and the stream's veto seeing the structure's axes."""

from __future__ import annotations

import csv
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uareme_fusion.solver.cues import CueSolver
from uareme_fusion.solver.sky_cadence import SkyCadence, SkyCadenceConfig, tilt_std_deg
from uareme_fusion.solver.sky_horizon import tangent_basis
from uareme_fusion.types import Frame

STRONG = SimpleNamespace(R_cm=np.eye(3), cov=np.diag([0.005, 0.5, 0.005]) ** 2)
"""A solve whose tilt is held to 0.29 deg (its rotation about up, y, is free)."""
WEAK = SimpleNamespace(R_cm=np.eye(3), cov=np.diag([0.1, 0.01, 0.01]) ** 2)
"""A solve whose tilt about the camera's x axis is 5.7 deg uncertain."""


def looks(cadence: SkyCadence, frames: int, found_at=(), visual=STRONG) -> list[int]:
    """The frames `cadence` looks at, a sky being found on the frames `found_at` looked at."""
    out = []
    for k in range(frames):
        looked = cadence.look()
        found = looked and k in found_at
        out += [k] if looked else []
        cadence.seen(looked, found, visual(k) if callable(visual) else visual)
    return out


def test_tilt_std_is_the_weaker_direction_perpendicular_to_up():
    # up is the camera's -y axis of R_cm = I; turns about x and z tilt it, a turn about y does not
    assert tilt_std_deg(np.eye(3), np.diag([0.01, 0.5, 0.03]) ** 2) == pytest.approx(np.degrees(0.03))
    R = Rotation.from_rotvec([0.0, 0.0, np.pi / 2]).as_matrix()  # up is now R's x axis (column 0)
    assert tilt_std_deg(R, np.diag([0.5, 0.02, 0.01]) ** 2) == pytest.approx(np.degrees(0.02))


def test_no_sky_and_a_held_tilt_looks_every_nth_frame():
    cadence = SkyCadence(SkyCadenceConfig(every_frames=10))
    assert looks(cadence, 31) == [0, 10, 20, 30]  # the first frame, then every 10th
    assert (cadence.frames, cadence.looks) == (31, 4)


def test_a_found_sky_is_followed_on_every_frame_until_it_is_lost():
    cadence = SkyCadence(SkyCadenceConfig(every_frames=10))
    assert looks(cadence, 30, found_at=set(range(10, 15))) == [0, 10, 11, 12, 13, 14, 15, 25]


def test_a_weak_tilt_looks_on_the_next_frame():
    cadence = SkyCadence(SkyCadenceConfig(every_frames=10, tilt_std_deg=2.0))
    weak_at = {3, 4}
    assert looks(cadence, 16, visual=lambda k: WEAK if k in weak_at else STRONG) == [0, 4, 5, 15]
    assert looks(SkyCadence(), 3, visual=None) == [0, 1, 2]  # no solve: nothing holds the tilt


def test_every_frame_with_every_frames_1():
    assert looks(SkyCadence(SkyCadenceConfig(every_frames=1)), 5) == [0, 1, 2, 3, 4]


def test_stream_keeps_a_sky_on_an_axis_of_its_prior(shared_data):
    """A real drone photo turned 90 deg: its receding ground lines meet where image up points, and, seen
    alone, outvote the sky (the veto); in a stream whose prior rotation has an axis on the sky's up (the
    structure agrees with the sky, `SkyVetoConfig.structure_agree_deg`) the sky stays in the solve."""
    folder = shared_data / "horizon_uav"
    row = next(csv.DictReader((folder / "label.csv").open()))
    rgb = cv2.cvtColor(cv2.imread(str(folder / "images" / row["filename"])), cv2.COLOR_BGR2RGB)
    turned = np.ascontiguousarray(np.rot90(rgb))
    alone = CueSolver(lines=True, sky=True).solve(Frame(0.0, rgb=turned, index=0), None)
    assert "sky" not in alone.cues  # vetoed without a prior
    cues = CueSolver(lines=True, sky=True)
    sky_up = cues.sky.detect(turned).observation(cues._assumed(*turned.shape[:2]).K).up_c
    prior = np.column_stack([tangent_basis(sky_up), sky_up])
    visual = cues.solve(Frame(0.0, rgb=turned, index=0), None, Rotation.from_rotvec([0.0, 0.0, 0.02]).as_matrix()
                        @ prior)
    assert "sky" in visual.cues
    up = visual.R_cm[:, 2]
    assert np.degrees(np.arccos(min(abs(up @ sky_up), 1.0))) < 2.0
