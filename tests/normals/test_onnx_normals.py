"""The normal network on ONNX Runtime (issue 28 item 4): the shipped weights exported into the cache
give torch's normals within 1e-4 on real development images; any model with the contract runs from
`--normals FILE.onnx`; a model of another contract is refused naming the file and the shapes."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from uareme_fusion.errors import InputError
from uareme_fusion.formats.images import read_rgb
from uareme_fusion.normals.learned import DEFAULT_WEIGHTS, LearnedNormals, LearnedNormalsConfig
from helpers import cli, error_lines

pytestmark = pytest.mark.skipif(importlib.util.find_spec("onnxruntime") is None,
                                reason="onnxruntime is not installed (the onnx extra)")


@pytest.fixture(scope="module")
def engines():
    return {name: LearnedNormals(config=LearnedNormalsConfig(engine=name)) for name in ("torch", "onnx")}


@pytest.mark.slow
def test_onnx_gives_torchs_normals_on_real_images(engines, shared_data):
    images = (sorted((shared_data / "icl_nuim_office_kt3" / "rgb").glob("*.png"))[:2]
              + sorted((shared_data / "icsl_corridor" / "rgb").glob("*.png"))[:2]
              + sorted((shared_data / "eurasian_cities").glob("*.jpg"))[:2])
    assert len(images) == 6
    assert engines["onnx"].engine == "onnx" and engines["torch"].engine == "torch"
    for path in images:
        rgb = read_rgb(path)
        a, b = engines["onnx"].estimate(rgb), engines["torch"].estimate(rgb)
        assert np.abs(a.normals - b.normals).max() < 1e-4, path
        assert np.abs(a.kappa - b.kappa).max() <= 1e-4 * max(1.0, float(b.kappa.max())), path
        assert np.count_nonzero(b.kappa) > 0.9 * b.kappa.size  # a real map, not an empty one


@pytest.mark.slow
def test_the_export_is_cached_under_the_weights_digest(tmp_path, monkeypatch):
    from uareme_fusion.normals import onnx_model

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    path = onnx_model.cached_export_path(DEFAULT_WEIGHTS)
    assert path.parent == tmp_path / "uareme-fusion" / "onnx" and path.name.startswith("normalnet_lite0-")
    model = onnx_model.shipped_onnx_model(DEFAULT_WEIGHTS)
    stamp = path.stat().st_mtime_ns
    assert model.input_size is None  # H and W free: the configured 160x120 is used
    onnx_model.shipped_onnx_model(DEFAULT_WEIGHTS)
    assert path.stat().st_mtime_ns == stamp  # the second use loads, it does not export again
    out = model(np.full((1, 3, 96, 128), 0.5, np.float32))
    assert out.shape == (1, 4, 96, 128)
    assert np.allclose(np.linalg.norm(out[0, :3], axis=0), 1.0, atol=1e-4) and (out[0, 3] >= 0).all()


def _export(module, path, shape=(1, 3, 48, 64), dynamic=True):
    import torch

    names = {"input_names": ["x"], "output_names": ["y"]}
    axes = {"dynamic_axes": {"x": {2: "H", 3: "W"}, "y": {2: "H", 3: "W"}}} if dynamic else {}
    torch.onnx.export(module.eval(), (torch.rand(*shape),), str(path), opset_version=17, dynamo=False, **names, **axes)
    return path


@pytest.mark.slow
def test_a_model_with_the_contract_runs_from_normals_file(tmp_path, engines):
    """A user's model of a fixed size (here the shipped network exported at 96x128): used at its size."""
    from uareme_fusion.normals.learned import load_network

    path = _export(load_network(DEFAULT_WEIGHTS), tmp_path / "mine.onnx", (1, 3, 96, 128), dynamic=False)
    mine = LearnedNormals(model=path)
    assert mine.engine == "onnx" and mine.model.input_size == (128, 96)
    rgb = (np.random.default_rng(0).random((120, 160, 3)) * 255).astype(np.uint8)
    assert mine.estimate(rgb).normals.shape == (120, 160, 3)


def test_a_model_of_another_contract_is_refused_naming_file_and_shapes(tmp_path):
    import torch

    class OneChannel(torch.nn.Module):
        def forward(self, x):
            return x[:, :1]

    path = _export(OneChannel(), tmp_path / "gray.onnx")
    with pytest.raises(InputError) as refused:
        LearnedNormals(model=path)
    message = str(refused.value)
    assert message.startswith(f"{path}: an ONNX normal model must map (1, 3, H, W)")
    # The shapes of the session, built at the configured 160x120 (the file leaves H and W free).
    assert "x (1, 3, 120, 160) tensor(float)" in message and "y" in message and "(1, 1, 120, 160)" in message
    (tmp_path / "junk.onnx").write_bytes(b"not a model")
    with pytest.raises(InputError, match=r"junk.onnx: cannot load this ONNX model"):
        LearnedNormals(model=tmp_path / "junk.onnx")
    import cv2

    cv2.imwrite(str(tmp_path / "room.png"), np.full((48, 64, 3), 128, np.uint8))
    proc = cli("image", tmp_path / "room.png", "--normals", path)
    assert proc.returncode == 2 and error_lines(proc)[0].startswith(f"error: {path}: an ONNX normal model must map")


def test_auto_falls_back_to_torch_where_the_export_cannot_be_made(tmp_path, monkeypatch):
    from uareme_fusion.errors import OutputError
    from uareme_fusion.normals import learned, onnx_model

    def no_export(weights, target, size_hw=(120, 160)):
        raise OutputError(f"{target}: could not be written (Read-only file system)")

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setattr(onnx_model, "export_onnx", no_export)
    learned.shipped_onnx.cache_clear()
    try:
        assert LearnedNormals().engine == "torch"
        with pytest.raises(OutputError, match="Read-only file system"):
            LearnedNormals(config=LearnedNormalsConfig(engine="onnx"))  # asked for by name: the error is shown
    finally:
        learned.shipped_onnx.cache_clear()


def test_a_session_built_for_the_run_size_gives_the_free_sessions_normals():
    """`LearnedNormals` runs the shipped network at one size (160x120): its session is built for it
    (ONNX Runtime's free-dimension overrides), with the free session's outputs, and refuses another size."""
    from uareme_fusion.normals import onnx_model

    free = onnx_model.shipped_onnx_model(DEFAULT_WEIGHTS)
    sized = onnx_model.shipped_onnx_model(DEFAULT_WEIGHTS, run_size_hw=(120, 160))
    assert free.run_size_hw is None and sized.run_size_hw == (120, 160)
    assert free.input_size is None and sized.input_size is None  # the file leaves H and W free
    x = np.random.default_rng(0).random((1, 3, 120, 160), np.float32)
    assert np.abs(sized(x) - free(x)).max() < 1e-5
    with pytest.raises(Exception, match="dimensions"):
        sized(np.full((1, 3, 96, 128), 0.5, np.float32))
    assert LearnedNormals(config=LearnedNormalsConfig(engine="onnx")).model.run_size_hw == (120, 160)
