"""The normal network through ONNX Runtime: the shipped weights exported once, and bring-your-own models.

    model = shipped_onnx_model(DEFAULT_WEIGHTS, threads=1)   # exported on first use, cached
    model = OnnxNormalModel("my_net.onnx", threads=1)        # any model with the contract below
    out = model(rgb_1x3hw_float32)                           # (1, 4, h, w) float32
    model = shipped_onnx_model(DEFAULT_WEIGHTS, run_size_hw=(120, 160))  # every call at this size: faster

Contract of an ONNX normal model (that of `network.py`): one input (1, 3, H, W) float32 RGB in [0, 1];
the first output (1, 4, H, W) float32: a unit normal per pixel in the OpenCV camera frame (x right,
y down, z forward), then kappa >= 0. H and W may be fixed in the file (images are then resized to
them) or free (the configured size is used). A file with another contract is refused with an
`InputError` that names it and the shapes found.

The shipped weights (whatever `normals/weights/*.pt` holds) are exported with torch's exporter at
first use into the user's cache folder (`cache_dir()`), under a name holding the weights' SHA-256,
so replaced weights get their own export; nothing is downloaded. Needs the `onnx` extra
(onnxruntime; onnx for the export).
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import os
import warnings
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.safe_files import temporary_sibling, publish

EXPORT_VERSION = 1
"""Part of the cached export's name: bumped when the export itself changes."""
EXPORT_OPSET = 17


def onnxruntime_available() -> bool:
    return importlib.util.find_spec("onnxruntime") is not None


def cache_dir() -> Path:
    """`$XDG_CACHE_HOME/uareme-fusion` (default `~/.cache/uareme-fusion`)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "uareme-fusion"


def cached_export_path(weights: Path) -> Path:
    digest = hashlib.sha256(Path(weights).read_bytes()).hexdigest()[:16]
    return cache_dir() / "onnx" / f"{Path(weights).stem}-{digest}-v{EXPORT_VERSION}.onnx"


def export_onnx(weights: Path, target: Path, size_hw: tuple[int, int] = (120, 160)) -> Path:
    """Export the `NormalNet` of a weights file to `target` (H and W free), written atomically."""
    import torch

    from .learned import load_network

    net = load_network(Path(weights))
    example = torch.rand(1, 3, *size_hw)
    tmp = temporary_sibling(target)
    try:
        with warnings.catch_warnings(), torch.no_grad():
            warnings.simplefilter("ignore")  # the TorchScript-based exporter is marked deprecated
            torch.onnx.export(net, (example,), str(tmp), input_names=["rgb"], output_names=["normals_kappa"],
                              dynamic_axes={"rgb": {2: "H", 3: "W"}, "normals_kappa": {2: "H", 3: "W"}},
                              opset_version=EXPORT_OPSET, dynamo=False)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    publish(tmp, target)
    return target


def shipped_onnx_model(weights: Path, threads: int | None = 1,
                       run_size_hw: tuple[int, int] | None = None) -> "OnnxNormalModel":
    """The shipped network on ONNX Runtime, exported into the cache on first use (`run_size_hw`: see
    `OnnxNormalModel`)."""
    path = cached_export_path(weights)
    if not path.is_file():
        export_onnx(weights, path)
    return OnnxNormalModel(path, threads, run_size_hw)


def _shape_text(shape) -> str:
    return "(" + ", ".join(str(d) if isinstance(d, int) else repr(d or "?") for d in shape) + ")"


def _free_hw_names(path: Path) -> tuple[str, str] | None:
    """The names of the H and W dimensions of an ONNX file's one input when both are free (named), read
    from the file by `onnx` without building a session; None when either is fixed or unnamed, the file
    does not parse (the session then says why), or `onnx` is not installed (H and W then stay free)."""
    try:
        import onnx

        graph = onnx.load(str(path), load_external_data=False).graph
    except Exception:  # noqa: BLE001 -- ImportError, or a broken file that the session reports
        return None
    weights = {w.name for w in graph.initializer}
    inputs = [i for i in graph.input if i.name not in weights]
    if len(inputs) != 1:
        return None
    dims = inputs[0].type.tensor_type.shape.dim
    names = tuple(d.dim_param if d.HasField("dim_param") else "" for d in dims[2:])
    return names if len(dims) == 4 and all(names) else None


class OnnxNormalModel:
    """An ONNX normal model on ONNX Runtime's CPU provider, checked against the contract on load;
    `model(x)` maps (1, 3, h, w) float32 to (1, 4, h, w) float32. `input_size` is the (width, height) the
    file fixes, or None when H and W are free.

    `run_size_hw` (height, width): the size of every call to come, for a file whose H and W are free
    (`LearnedNormals` always runs its configured size). The session is then built for that size (ONNX
    Runtime's free-dimension overrides: planned once, about 10 % less CPU per call on the shipped
    network at 160x120, outputs within 1e-5) and refuses any other; None keeps H and W free."""

    name = "onnx"

    def __init__(self, path: str | Path, threads: int | None = 1, run_size_hw: tuple[int, int] | None = None):
        self.path = Path(path)
        if not self.path.is_file():
            raise InputError(f"{self.path}: model file not found")
        if not onnxruntime_available():
            raise InputError(f"{self.path}: ONNX models run on onnxruntime, which is not installed "
                             "(pip install 'uareme-fusion[onnx]')")
        import onnxruntime as ort

        options = ort.SessionOptions()
        if threads is not None:
            options.intra_op_num_threads = int(threads)
            options.inter_op_num_threads = 1
        options.log_severity_level = 3
        free = _free_hw_names(self.path) if run_size_hw is not None else None
        for name, size in zip(free or (), run_size_hw or ()):
            options.add_free_dimension_override_by_name(name, int(size))
        self.run_size_hw = (int(run_size_hw[0]), int(run_size_hw[1])) if free else None
        self.session = self._session(options)  # once: the overrides are known before it is built
        self.input_size = self._check_contract()

    def _session(self, options):
        import onnxruntime as ort

        try:
            return ort.InferenceSession(str(self.path), options, providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own exception types for broken files
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise InputError(f"{self.path}: cannot load this ONNX model ({first})") from None

    def _check_contract(self) -> tuple[int, int] | None:
        inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        found = (f"found input(s) {', '.join(f'{i.name} {_shape_text(i.shape)} {i.type}' for i in inputs)} and "
                 f"output(s) {', '.join(f'{o.name} {_shape_text(o.shape)} {o.type}' for o in outputs)}")
        refusal = InputError(f"{self.path}: an ONNX normal model must map (1, 3, H, W) float RGB in [0, 1] to "
                             f"(1, 4, H, W) (unit normal, kappa); {found}")
        if len(inputs) != 1 or not outputs:
            raise refusal
        shape, kind = inputs[0].shape, inputs[0].type
        if (len(shape) != 4 or kind != "tensor(float)" or shape[1] != 3 or shape[0] not in (1, None)
                and isinstance(shape[0], int)):
            raise refusal
        out_shape = outputs[0].shape
        if len(out_shape) != 4 or (isinstance(out_shape[1], int) and out_shape[1] != 4):
            raise refusal
        sized = all(isinstance(d, int) for d in shape[2:])  # by the file, or by `run_size_hw`'s overrides
        fixed = sized and self.run_size_hw is None
        from .learned import PROBE_SIZE_PX

        w, h = (shape[3], shape[2]) if sized else PROBE_SIZE_PX
        try:
            probe = self(np.full((1, 3, h, w), 0.5, np.float32))
        except Exception as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise InputError(f"{self.path}: the model fails on a (1, 3, {h}, {w}) RGB input ({first})") from None
        if probe.shape != (1, 4, h, w):
            raise InputError(f"{self.path}: an ONNX normal model must map (1, 3, {h}, {w}) RGB to (1, 4, {h}, {w}) "
                             f"(normal, kappa), it gave {tuple(probe.shape)}; {found}")
        return (w, h) if fixed else None

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(self.session.run(None, {self._input_name: x})[0], np.float32)

    @functools.cached_property
    def _input_name(self) -> str:
        return self.session.get_inputs()[0].name
