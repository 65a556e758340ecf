"""Every ```python block of README.md runs as a user would paste it (each in a fresh namespace, in a
folder holding the `corridor.png` it reads: a rendered room frame), and says what the README says."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from uareme_fusion.drivers import open_source
from uareme_fusion.rotations import up_in_camera
from uareme_fusion.types import Frame, Status

README = Path(__file__).resolve().parents[2] / "README.md"
BLOCKS = re.findall(r"^```python\n(.*?)^```", README.read_text(encoding="utf-8"), flags=re.S | re.M)


@pytest.fixture(scope="module")
def corridor(tmp_path_factory) -> tuple[Path, np.ndarray]:
    """A folder with `corridor.png` (a rendered room at 320x240) and that frame's true up in the camera."""
    folder = tmp_path_factory.mktemp("readme")
    with open_source("sim:room", seconds=0.2, width=320, height=240) as source:
        frame = next(e for e in source.events() if isinstance(e, Frame))
        truth = source.ground_truth()
    cv2.imwrite(str(folder / "corridor.png"), cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR))
    R_wc = truth.R_wc[np.argmin(np.abs(truth.t_s - frame.t_s))]
    return folder, up_in_camera(R_wc)


def run_block(index: int, folder: Path, monkeypatch) -> dict:
    monkeypatch.chdir(folder)
    namespace: dict = {"__name__": "__readme__"}
    exec(compile(BLOCKS[index], f"README.md python block {index + 1}", "exec"), namespace)
    return namespace


def test_the_readme_has_the_four_python_examples():
    assert len(BLOCKS) == 4


@pytest.mark.slow
def test_image_to_up_vector(corridor, monkeypatch):
    folder, up_true = corridor
    analysis = run_block(0, folder, monkeypatch)["analysis"]
    angle_deg = np.degrees(np.arccos(np.clip(analysis.up_c @ up_true, -1.0, 1.0)))
    assert angle_deg < 5.0, angle_deg  # a rendered room: the up vector within a few degrees of the truth
    assert analysis.horizon.shape == (3,) and np.all(np.isfinite(analysis.visual.cov))


@pytest.mark.slow
def test_normals_to_rotation(corridor, monkeypatch):
    visual = run_block(1, corridor[0], monkeypatch)["visual"]
    assert np.allclose(visual.R_cm.T @ visual.R_cm, np.eye(3), atol=1e-9) and 0.5 < visual.quality <= 1.0
    assert np.all(np.linalg.eigvalsh(visual.cov) > 0)


def test_fusing_with_an_imu(tmp_path, monkeypatch):
    estimate = run_block(2, tmp_path, monkeypatch)["estimate"]
    assert np.allclose(estimate.up_c, [0.0, -1.0, 0.0], atol=1e-3)  # image up is world up, as the comment says
    assert not estimate.status & Status.NOT_INITIALISED


@pytest.mark.slow
def test_the_whole_pipeline(tmp_path, monkeypatch):
    namespace = run_block(3, tmp_path, monkeypatch)
    assert namespace["summary"]["frames"] == 15
    assert (tmp_path / "out_room" / "estimates.csv").read_text().count("\n") == 16  # header and 15 rows


def test_ci_runs_the_readme_test_command_and_the_readme_names_no_issue():
    text = README.read_text(encoding="utf-8")
    test_line = next(line for line in text.splitlines() if line.endswith("# install, run the tests"))
    ci_lines = (README.parent / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    assert test_line.split("  #")[0].strip() in ci_lines
    assert len(text.splitlines()) <= 400 and not re.search(r"\b(issue|session|round) \d", text, flags=re.I)
