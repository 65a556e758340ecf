"""Normals and confidence kappa from uncalibrated RGB with a small trained network (paper Sec. 3).

    est = LearnedNormals()                      # the shipped weights, loaded offline
    normal_map = est.estimate(rgb_uint8)        # NormalMap: normals (H, W, 3), kappa (H, W)
    est = LearnedNormals(model="my_model.pt")   # a drop-in model (TorchScript or state dict)

The image (any size) is resized to `LearnedNormalsConfig.width_px` x `height_px` (160 x 120, the
size the shipped network was trained at; configurable), run
through the network, and the output is upsampled back to the input size. No intrinsics are used.
Returned normals are unit vectors in the OpenCV camera frame (x right, y down, z forward), facing
the camera; kappa (the paper's eq. 3 concentration) is capped at `kappa_cap` (default 75, the
paper's released setting) and is 0 where the network's output is not finite.

Model files (`model=`), all with the contract of `network.py` (RGB in [0, 1] as (B, 3, H, W)
float32 -> (B, 4, H, W): unit normal, kappa >= 0):
- the shipped format: `torch.save({"format": WEIGHTS_FORMAT, "config": NetworkConfig fields,
  "state_dict": ..., "meta": ...})` (what `tools/train_normals.py export` writes);
- a bare state dict of `NormalNet` with the default `NetworkConfig`;
- a TorchScript module (`torch.jit.save`) of any architecture;
- an ONNX model (`.onnx`, run on ONNX Runtime: the `onnx` extra), any architecture with that contract
  for a batch of one (`onnx_model.py`).
The shipped weights run on ONNX Runtime when it is installed (`LearnedNormalsConfig.engine` auto:
exported once into the user's cache folder, about 1.9x torch's speed on one CPU thread and the same
normals within 1e-4, `uareme-fusion bench normals`), on torch otherwise.
Every model is probed once on load with a small image; a file that is not one of these, or whose
weights or outputs do not fit, raises `InputError` naming the file and the problem. `NormalNet`
weights are scripted and frozen for inference (BatchNorm folded), torch runs in inference mode.
"""

from __future__ import annotations

import dataclasses
import functools
import sys
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..errors import ConfigError, InputError
from ..solver.evidence import textured_fraction
from ..types import Frame, NormalMap

WEIGHTS_FORMAT = "uareme-normalnet-v1"
DEFAULT_WEIGHTS = Path(__file__).resolve().parent / "weights" / "normalnet_lite0.pt"
DEFAULT_THREADS = 1
"""torch CPU threads unless configured (`LearnedNormalsConfig.threads`, `--threads`)."""
ENGINES = ("auto", "torch", "onnx")
PROBE_SIZE_PX = (64, 48)
"""(width, height) of the image every loaded model is checked on."""
_MIRROR_X = np.array([-1.0, 1.0, 1.0, 1.0], np.float32)
"""A left-right mirror of the image flips the normals' x (OpenCV camera frame); y, z and kappa stay."""


@dataclass(frozen=True)
class LearnedNormalsConfig:
    """Parameters of `LearnedNormals` (units in the names)."""

    width_px: int = 160
    """Network input width; images are resized to width_px x height_px and back. The shipped network
    was trained on 160x120 crops: at 320x240 its held-out synthetic error triples (15 vs 5 degrees,
    tools/bench_normals.py), so 160x120 is the default; raise it only for a model trained larger."""
    height_px: int = 120
    at_input_size: bool = True
    """Upsample the map (bilinear) to the input image's size; False keeps the network's width_px x
    height_px. The solver's rotation and covariance do not depend on the map's resolution (its
    moments are weighted means, its covariance scales with the valid fraction): streams keep the
    small map and skip a 16x larger pass at 640x480 (about half the normals stage, `bench pipeline`)."""
    mirror_average: bool | None = None
    """Average the network's output on the image and on its left-right mirror image (mirrored back); None:
    for the shipped network only (a drop-in model file runs as given). Twice the network's time (about 4 ms
    more a frame at 160x120 on ONNX), an estimator that is exactly mirror-symmetric, and errors that partly
    cancel (REAL, round-4 network, with `independent_regions` fitted again, `tools/visual_only_replay.py`:
    TUM fr1 rpy eval RGB single 8.23 -> 7.32 deg, mekf 4.17 -> 3.91; EuRoC cam0 0.86 -> 0.81; ICSL normals
    alone 1.48 / 3.51 -> 1.41 / 3.24; ICL kt3 (rendered) normals alone 2.79 -> 2.06; docs/normals_training.md)."""
    kappa_cap: float = 75.0
    """kappa is capped here before the solver (paper: 100; its released config: 75)."""
    independent_regions: float = 5.0
    """Effective number of independent normal errors in a full map: a network's errors are correlated
    over whole surfaces (a wall slightly mis-oriented as a block), so few. Sets the solver's covariance
    scale; fitted on real frames so that the mean NEES of single-frame rotations (learned normals alone,
    mirror-averaged, `tools/visual_only_replay.py`) on the TUM fr1 rpy training frames is 3: 2.97 (3.0 gave
    1.80; the median is 0.65 there, a few confidently wrong frames carry the mean). Measured beside it
    (never fitted on): TUM eval 1.14, EuRoC cam0 1.17, ICSL 2.70 / 2.97, ICL kt3 2.47 (RENDERED)."""
    texture_power: float = 1.0
    """`independent_regions` is scaled by (t / `texture_reference`)^power, t the image's textured fraction
    (`solver.evidence.textured_fraction`, at 160 px wide): a network's normals are measured where the image
    has texture and guessed elsewhere, so its information grows with the textured area (0: not scaled).
    REAL, single-frame rotations, learned normals alone (`tools/visual_only_replay.py`), unscaled -> scaled:
    mean NEES TUM fr1 rpy eval 1.14 -> 1.38, EuRoC cam0 1.17 -> 1.23, ICSL 2.70 / 2.97 -> 2.52 / 1.76, ICL kt3
    (RENDERED) 2.47 -> 2.18: the spread across scenes followed their texture (median t TUM 0.42, EuRoC 0.36, ICSL
    0.21 / 0.20, kt3 0.16). Std separation (the median error of the low-std half over the high-std half's, goal
    0.5): TUM eval 0.53 -> 0.48, ICSL 1.43 / 0.83 -> 0.65 / 0.75, kt3 1.66 -> 1.35. With the lines, the normals of a
    low-texture corridor now weigh less: ICSL corridor_more normals + lines 1.68 -> 1.45 deg (single)."""
    texture_reference: float = 0.327
    """t at which `independent_regions` holds: fitted, as it was, so that the mean NEES of the TUM fr1 rpy
    training frames' single-frame rotations (learned normals alone) is 3 (their median t is 0.376)."""
    regions_cost: float = 0.03
    """`NormalMap.regions_cost`: above this residual the independent errors shrink as regions_cost / E (real
    frames: the rotation error grows about as E, not as sqrt(E)); fitted on the TUM fr1 rpy training frames."""
    threads: int | None = DEFAULT_THREADS
    """torch CPU threads (None: leave torch's setting). One by default: beside another CPU-bound
    process, torch's default of one thread per core makes its threads wait on each other and a
    frame takes 10-20x longer; one thread loses little on a quiet machine (README, "Troubleshooting";
    `uareme-fusion bench pipeline` measures both)."""
    device: str = "cpu"
    engine: str = "auto"
    """What runs the shipped network: torch, onnx (ONNX Runtime, the `onnx` extra) or auto: onnx when
    onnxruntime is installed (faster on CPU: `uareme-fusion bench normals`), torch otherwise. A model
    file runs on what its format needs (.onnx on ONNX Runtime, torch files on torch)."""

    def __post_init__(self):
        if self.engine not in ENGINES:
            raise ConfigError(f"engine must be one of {', '.join(ENGINES)}, got {self.engine!r}")
        if self.width_px < 32 or self.height_px < 32 or self.width_px * self.height_px > 4096 * 4096:
            raise ConfigError(f"width_px and height_px must be 32..4096, got {self.width_px}x{self.height_px}")
        if not self.kappa_cap > 0:
            raise ConfigError(f"kappa_cap must be > 0, got {self.kappa_cap}")
        if not self.independent_regions >= 1:
            raise ConfigError(f"independent_regions must be >= 1, got {self.independent_regions}")
        if not (self.texture_power >= 0 and self.texture_reference > 0):
            raise ConfigError(f"texture_power must be >= 0 and texture_reference > 0, got {self.texture_power} "
                              f"and {self.texture_reference}")
        if self.threads is not None and self.threads < 1:
            raise ConfigError(f"threads must be >= 1, got {self.threads}")


def _is_torchscript(path: Path) -> bool:
    """TorchScript archives are zip files with a `code/` folder (plain torch.save zips have none)."""
    if not zipfile.is_zipfile(path):
        return False
    with zipfile.ZipFile(path) as zf:
        return any("/code/" in name or name.startswith("code/") for name in zf.namelist())


def load_model(path: str | Path, device: str = "cpu"):
    """A torch module in eval mode from a model file (see the module docstring for the formats).

    Raises `InputError` naming the file when it is missing, not a torch file, holds weights of
    another architecture, or gives outputs that break the (B, 4, H, W) contract."""
    import torch

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: model file not found")
    if _is_torchscript(path):
        try:
            with warnings.catch_warnings():  # torch 2.13 marks TorchScript deprecated; users still ship it
                warnings.simplefilter("ignore", DeprecationWarning)
                model = torch.jit.load(str(path), map_location=device)
        except Exception as exc:  # torch raises RuntimeError and others for broken archives
            raise InputError(f"{path}: cannot load this TorchScript module ({_first_line(exc)})") from None
    else:
        model = _frozen(load_network(path, device))
    model.eval()
    _probe(model, path, device)
    return model


def load_network(path: Path, device: str = "cpu"):
    """The eager `NormalNet` (eval mode) of a weights file: the shipped format or a bare state dict."""
    import torch

    from .network import NetworkConfig, NormalNet, config_from_dict

    try:
        payload = torch.load(path, map_location=device, weights_only=True)
    except Exception as exc:
        raise InputError(f"{path}: not a TorchScript module or a torch weights file "
                         f"({_first_line(exc)})") from None
    if isinstance(payload, dict) and payload.get("format") == WEIGHTS_FORMAT:
        try:
            config = config_from_dict(payload["config"])
            model = NormalNet(config)
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{path}: bad network config in the weights file ({exc})") from None
        state_dict = payload.get("state_dict")
    elif isinstance(payload, dict) and payload and all(isinstance(v, torch.Tensor) for v in payload.values()):
        model, state_dict = NormalNet(NetworkConfig()), payload
    else:
        raise InputError(f"{path}: expected a {WEIGHTS_FORMAT} weights file, a NormalNet state dict or a "
                         f"TorchScript module; found a {type(payload).__name__} of another layout")
    _load_state_dict(model, state_dict, path)
    return model.to(device).eval()


@functools.lru_cache(maxsize=4)
def shipped_model(path: Path, device: str = "cpu"):
    """`load_model` of the shipped weights at `path`, once per process and device: scripting, freezing
    and probing the network takes about 0.7 s, and the frozen module only runs inference, so every
    `LearnedNormals` of a process shares it. (Drop-in model files are loaded afresh each time.)"""
    return load_model(path, device)


@functools.lru_cache(maxsize=4)
def shipped_onnx(path: Path, threads: int | None, run_size_hw: tuple[int, int] | None = None):
    """The shipped weights at `path` on ONNX Runtime (exported into the user's cache folder on first
    use, `onnx_model.shipped_onnx_model`), once per process, thread count and run size."""
    from .onnx_model import shipped_onnx_model

    return shipped_onnx_model(path, threads, run_size_hw)


def _frozen(model):
    """`model` scripted, frozen and optimised for inference: BatchNorm folded into the convolutions,
    about 2x faster on CPU than eager mode, same outputs to 1e-6."""
    import torch

    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore", DeprecationWarning)
        return torch.jit.optimize_for_inference(torch.jit.freeze(torch.jit.script(model)))


def _first_line(exc: Exception) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _load_state_dict(model, state_dict, path: Path) -> None:
    import torch

    if not isinstance(state_dict, dict):
        raise InputError(f"{path}: the weights file has no state_dict")
    expected = model.state_dict()
    missing = sorted(set(expected) - set(state_dict))
    unexpected = sorted(set(state_dict) - set(expected))
    wrong = [k for k in expected if k in state_dict and tuple(state_dict[k].shape) != tuple(expected[k].shape)]
    if missing or unexpected or wrong:
        parts = []
        if missing:
            parts.append(f"{len(missing)} missing tensors (e.g. {missing[0]})")
        if unexpected:
            parts.append(f"{len(unexpected)} unexpected tensors (e.g. {unexpected[0]})")
        if wrong:
            k = wrong[0]
            parts.append(f"{len(wrong)} tensors of the wrong shape (e.g. {k}: {tuple(state_dict[k].shape)} "
                         f"instead of {tuple(expected[k].shape)})")
        raise InputError(f"{path}: weights of another architecture, they do not fit NormalNet: " + "; ".join(parts))
    model.load_state_dict({k: v.to(expected[k].dtype) if isinstance(v, torch.Tensor) else v
                           for k, v in state_dict.items()})


def _probe(model, path: Path, device: str) -> None:
    """Run the model once on a small image and check the output contract."""
    import torch

    w, h = PROBE_SIZE_PX
    try:
        with torch.no_grad():
            out = model(torch.full((1, 3, h, w), 0.5, device=device))
    except Exception as exc:
        raise InputError(f"{path}: the model fails on a (1, 3, {h}, {w}) RGB input ({_first_line(exc)})") from None
    if not isinstance(out, torch.Tensor) or tuple(out.shape) != (1, 4, h, w):
        shape = tuple(out.shape) if isinstance(out, torch.Tensor) else type(out).__name__
        raise InputError(f"{path}: the model must map (1, 3, {h}, {w}) RGB to (1, 4, {h}, {w}) "
                         f"(normal, kappa), it gave {shape}")


class LearnedNormals:
    """Normal estimator for RGB frames: `estimate(rgb_uint8) -> NormalMap` (OpenCV camera frame)."""

    name = "learned"

    def __init__(self, model: str | Path | None = None, config: LearnedNormalsConfig | None = None):
        self.config = config or LearnedNormalsConfig()
        self.model_path = Path(model) if model is not None else DEFAULT_WEIGHTS
        self.shipped = model is None
        if model is None and not DEFAULT_WEIGHTS.is_file():
            raise InputError(f"{DEFAULT_WEIGHTS}: the shipped normal network weights are missing "
                             "(reinstall uareme-fusion)")
        self.engine = self._engine(model)
        if self.engine == "onnx":
            from .onnx_model import OnnxNormalModel

            run_size_hw = (self.config.height_px, self.config.width_px)  # `infer` resizes every image to it
            try:
                self.model = (shipped_onnx(self.model_path, self.config.threads, run_size_hw) if model is None
                              else OnnxNormalModel(self.model_path, self.config.threads, run_size_hw))
            except Exception:  # auto: an export that cannot be made or cached here falls back to torch
                if model is not None or self.config.engine != "auto":
                    raise
                self.engine = "torch"
        if self.engine == "torch":
            _set_torch_threads(self.config.threads)
            self.model = (shipped_model(self.model_path, self.config.device) if model is None
                          else load_model(self.model_path, self.config.device))
        elif "torch" in sys.modules:  # torch in use elsewhere in the process (or by the export): same threads
            _set_torch_threads(self.config.threads)

    def _engine(self, model) -> str:
        """torch or onnx for this model (see `LearnedNormalsConfig.engine`)."""
        if model is not None:
            return "onnx" if Path(model).suffix.lower() == ".onnx" else "torch"
        if self.config.engine == "auto":
            from .onnx_model import onnxruntime_available

            return "onnx" if onnxruntime_available() and self.config.device == "cpu" else "torch"
        return self.config.engine

    def estimate_frame(self, frame: Frame) -> NormalMap:
        """Normals of a `Frame`'s RGB image; `InputError` if it has none."""
        source = f"frame {frame.index} (t = {frame.t_s:g} s)"
        if frame.rgb is None:
            raise InputError(f"{source}: learned normals need an RGB image, the frame has none")
        return dataclasses.replace(self.estimate(frame.rgb, source=source), t_s=frame.t_s)

    def estimate(self, rgb_uint8, source: str = "image") -> NormalMap:
        """Unit normals (H, W, 3) float32 in the OpenCV camera frame and kappa (H, W) float32 in
        [0, kappa_cap] for an RGB uint8 image (H, W, 3) of any size (at least 8x8); (height_px,
        width_px) instead of (H, W) when `config.at_input_size` is False."""
        rgb = _check_rgb(rgb_uint8, source)
        out = self.infer(rgb)
        fraction = textured_fraction(rgb)
        return dataclasses.replace(
            self.to_normal_map(out, rgb.shape[:2] if self.config.at_input_size else out.shape[1:],
                               self.texture_regions(rgb, fraction)), textured_fraction=fraction)

    def texture_regions(self, rgb: np.ndarray, fraction: float | None = None) -> float:
        """`independent_regions` scaled by the image's texture (`LearnedNormalsConfig.texture_power`;
        `fraction`: its `textured_fraction` when already measured)."""
        cfg = self.config
        if cfg.texture_power == 0:
            return cfg.independent_regions
        fraction = textured_fraction(rgb) if fraction is None else fraction
        factor = max(fraction / cfg.texture_reference, MIN_TEXTURE_FACTOR) ** cfg.texture_power
        return max(cfg.independent_regions * factor, 1.0)

    def infer(self, rgb: np.ndarray) -> np.ndarray:
        """Raw network output (4, h, w) float32 at the internal size for a checked RGB uint8 image; with
        `config.mirror_average`, the mean of the image's and its mirror image's (mirrored back)."""
        cfg = self.config
        mirror_average = cfg.mirror_average if cfg.mirror_average is not None else self.shipped
        size = (self.model.input_size if self.engine == "onnx" else None) or (cfg.width_px, cfg.height_px)
        small = cv2.resize(rgb, size, interpolation=cv2.INTER_AREA)
        out = self._forward(small)
        if mirror_average:  # the mirror image's normals, mirrored back: x flips sign, columns reverse
            mirrored = self._forward(np.ascontiguousarray(small[:, ::-1]))[:, :, ::-1]
            out = 0.5 * (out + mirrored * _MIRROR_X[:, None, None])
        return out

    def _forward(self, small: np.ndarray) -> np.ndarray:
        """The network on an RGB uint8 image at its input size: (4, h, w) float32."""
        if self.engine == "onnx":
            return self.model(np.ascontiguousarray(small.transpose(2, 0, 1)[None], np.float32) / np.float32(255.0))[0]
        import torch

        x = torch.from_numpy(small).to(self.config.device).permute(2, 0, 1)[None].float().div_(255.0)
        with torch.inference_mode():
            out = self.model(x)
        return out[0].float().cpu().numpy()

    def to_normal_map(self, out: np.ndarray, shape_hw: tuple[int, int],
                      independent_regions: float | None = None) -> NormalMap:
        """Upsample a (4, h, w) network output to `shape_hw`, renormalise, cap kappa (`independent_regions`:
        the map's, None: the config's, unscaled by texture). Works on the
        output's channel planes (at 160x120 about 8x less CPU than on (H, W, 4) pixels through
        `np.linalg.norm`, the same float32 operations in the same order: bit-identical maps)."""
        H, W = shape_hw
        planes = out
        if out.shape[1:] != (H, W):
            hwc = np.ascontiguousarray(out.transpose(1, 2, 0))
            planes = cv2.resize(hwc, (W, H), interpolation=cv2.INTER_LINEAR).transpose(2, 0, 1)
        x, y, z, kappa = planes
        norm = x * x
        norm += y * y
        norm += z * z
        np.sqrt(norm, out=norm)
        ok = np.isfinite(norm) & (norm > 1e-6) & np.isfinite(kappa)
        divisor = np.where(ok, norm, np.float32(1.0))
        normals = np.empty((H, W, 3), np.float32)
        for axis in range(3):
            np.divide(planes[axis], divisor, out=normals[..., axis])
        normals[~ok] = 0.0
        kappa = np.where(ok, np.clip(kappa, 0.0, self.config.kappa_cap), 0.0).astype(np.float32)
        regions = self.config.independent_regions if independent_regions is None else independent_regions
        return NormalMap(normals, kappa, independent_regions=regions, regions_cost=self.config.regions_cost)


MIN_TEXTURE_FACTOR = 0.4
"""t / `texture_reference` is floored here: the shading of a surface without texture (a flat-shaded render's
walls, t about 0.02) still carries its normal, which the textured fraction does not count. Real frames: the
10th percentile of ICL kt3 (rendered with noise) 0.125, of ICSL corridor_more 0.125, of TUM 0.30."""


def _set_torch_threads(threads: int | None) -> None:
    """torch's CPU thread count (None: leave it). Only where torch runs: on the ONNX engine torch is
    not imported for this (about 0.6 s of CPU at start-up)."""
    if threads is not None:
        import torch

        torch.set_num_threads(threads)


def _check_rgb(rgb, source: str) -> np.ndarray:
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise InputError(f"{source}: expected an RGB image of shape (H, W, 3), got {rgb.shape}")
    if rgb.dtype != np.uint8:
        raise InputError(f"{source}: expected an 8-bit (uint8) RGB image, got {rgb.dtype}")
    if min(rgb.shape[:2]) < 8:
        raise InputError(f"{source}: image of {rgb.shape[1]}x{rgb.shape[0]} pixels is too small (at least 8x8)")
    return np.ascontiguousarray(rgb)
