"""`uareme-fusion normals INPUT --out DIR`: images, folders and videos in; normal/confidence images and arrays out."""

import cv2
import numpy as np
import pytest
import torch
from torch import nn
from typer.testing import CliRunner

from uareme_fusion.cli import app
from uareme_fusion.io.normal_maps import load_normal_map, normals_to_rgb
from uareme_fusion.normals.export import confidence_image

runner = CliRunner()


def image(seed, height=60, width=80):
    """A BGR test image: two flat colours split diagonally, plus noise."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:height, 0:width]
    img = np.where((u > v)[..., None], [200, 120, 40], [30, 90, 180]).astype(np.float64)
    return np.clip(img + rng.normal(0, 5, img.shape), 0, 255).astype(np.uint8)


class Tilted(nn.Module):
    """A drop-in model: every normal (0.6, 0, -0.8), kappa = 100 * mean red (cap it at 75 to see white)."""

    def forward(self, rgb: torch.Tensor) -> torch.Tensor:
        b, _, h, w = rgb.shape
        normal = torch.tensor([0.6, 0.0, -0.8]).view(1, 3, 1, 1).expand(b, 3, h, w)
        kappa = 100.0 * rgb[:, :1]
        return torch.cat([normal, kappa], dim=1)


@pytest.fixture(scope="module")
def tilted_model(tmp_path_factory):
    path = tmp_path_factory.mktemp("model") / "tilted.pt"
    torch.jit.save(torch.jit.script(Tilted()), str(path))
    return path


def run(*args):
    return runner.invoke(app, ["normals", *map(str, args)])


def test_one_image_with_the_shipped_model(tmp_path):
    cv2.imwrite(str(tmp_path / "view.png"), image(0, 61, 83))
    result = run(tmp_path / "view.png", "--out", tmp_path / "out")
    assert result.exit_code == 0, result.output
    assert "wrote 1 frame" in result.output
    nm = load_normal_map(tmp_path / "out" / "view.npz")
    assert nm.normals.shape == (61, 83, 3) and nm.kappa.shape == (61, 83)
    assert 0.0 <= nm.kappa.min() and nm.kappa.max() <= 75.0
    colours = cv2.imread(str(tmp_path / "out" / "view_normals.png"))[..., ::-1]
    np.testing.assert_array_equal(colours, normals_to_rgb(nm.normals))
    confidence = cv2.imread(str(tmp_path / "out" / "view_confidence.png"), cv2.IMREAD_UNCHANGED)
    assert confidence.shape == (61, 83) and confidence.dtype == np.uint8
    np.testing.assert_array_equal(confidence, confidence_image(nm.kappa, 75.0))


def test_folder_with_a_drop_in_model(tmp_path, tilted_model):
    folder = tmp_path / "images"
    folder.mkdir()
    for k in range(3):
        cv2.imwrite(str(folder / f"{k:03d}.jpg"), image(k))
    (folder / "notes.txt").write_text("ignored: not an image suffix")
    result = run(folder, "--out", tmp_path / "out", "--model", tilted_model, "--kappa-cap", "50")
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in (tmp_path / "out").glob("*.npz")) == ["000.npz", "001.npz", "002.npz"]
    nm = load_normal_map(tmp_path / "out" / "001.npz")
    np.testing.assert_allclose(nm.normals, np.broadcast_to([0.6, 0.0, -0.8], (60, 80, 3)), atol=1e-5)
    confidence = cv2.imread(str(tmp_path / "out" / "001_confidence.png"), cv2.IMREAD_UNCHANGED)
    red = cv2.imread(str(folder / "001.jpg"))[..., 2]
    # kappa = 100 * red / 255 capped at 50: bright-red pixels white, dark ones grey.
    assert np.all(confidence[red > 200] == 255)
    assert np.all(confidence[red < 60] < 255)


def test_video(tmp_path, tilted_model):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (80, 60))
    for k in range(4):
        writer.write(image(k))
    writer.release()
    result = run(path, "--out", tmp_path / "out", "--model", tilted_model)
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in (tmp_path / "out").glob("*.npz")) == [f"clip_{k:06d}.npz" for k in range(4)]
    assert "wrote 4 frame" in result.output


def test_bad_inputs_give_one_line_naming_the_file(tmp_path, tilted_model):
    out = tmp_path / "out"
    empty = tmp_path / "empty.png"
    empty.write_bytes(b"")
    corrupt = tmp_path / "corrupt.jpg"
    corrupt.write_bytes(b"not a jpeg at all")
    (tmp_path / "nothing").mkdir()
    bad_video = tmp_path / "broken.mp4"
    bad_video.write_bytes(b"\x00" * 100)
    cases = [(empty, "empty.png: empty file"), (corrupt, "corrupt.jpg"), (tmp_path / "nothing", "no images"),
             (tmp_path / "missing.png", "missing.png"), (tmp_path / "table.csv", "table.csv"),
             (bad_video, "broken.mp4: OpenCV cannot read a frame")]
    (tmp_path / "table.csv").write_text("1,2,3\n")
    for path, message in cases:
        result = run(path, "--out", out, "--model", tilted_model)
        assert result.exit_code == 2, (path, result.output)
        assert message in " ".join(result.output.split()), (path, result.output)
        assert "Traceback" not in result.output
    cv2.imwrite(str(tmp_path / "ok.png"), image(0))
    text_model = tmp_path / "model.pt"
    text_model.write_text("weights?")
    result = run(tmp_path / "ok.png", "--out", out, "--model", text_model)
    assert result.exit_code == 2 and "model.pt: not a TorchScript module" in " ".join(result.output.split())
    (tmp_path / "file_out").write_text("x")
    result = run(tmp_path / "ok.png", "--out", tmp_path / "file_out", "--model", tilted_model)
    assert result.exit_code == 2 and "is not a folder" in result.output
