"""Vectorised ray casting of a `Scene` (numpy, float32, no per-pixel Python loops).

    renderer = Renderer(scene, intrinsics_from_fov(320, 240, 70.0), 320, 240)
    frame = renderer.render(R_wc, p_w, layer_poses={"body": (R_wb, p_wb)}, R_wm=R_wm)

Conventions: camera OpenCV (x right, y down, z forward), `R_wc` camera to world, `p_w` camera
centre (m). `layer_poses[name] = (R_ws, p_ws)` places each moving layer in the world (layers not
given are static in the world). Pixel (u, v) looks along `K^-1 (u, v, 1)`, so the ray parameter of
a hit IS its depth (z in the camera frame, metres).

Per frame (`RenderedFrame`): `rgb` (H, W, 3) uint8, `depth` (H, W) float32 m (0 where nothing is
hit), `normals_c` (H, W, 3) float32 unit normals in the camera frame facing the camera (0 where
nothing is hit), `manhattan_mask` (H, W) bool: pixels whose normal lies within
`MANHATTAN_TOL_DEG` of an axis of the Manhattan frame `R_wm`, plus `K`, `R_wc`, `p_w`.
Shading is Lambertian: `albedo * light_rgb * (ambient + diffuse * max(0, n_w . light_dir_w))`; rays
that hit nothing see the sky colour.

How it stays fast: every primitive is intersected in its own unit-shape frame with all the rays
of the screen rectangle its bounding box projects to (one numpy expression per primitive), a
z-buffer keeps the nearest hit, and shading and texturing run once per primitive over the pixels
it won.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..pinhole import intrinsics_from_fov as pinhole_from_fov
from .scenes import Scene, Shape

NEAR_M = 0.05
"""Hits closer than this along the ray (depth, m) are ignored."""
MANHATTAN_TOL_DEG = 1.0
"""A pixel is Manhattan-aligned when its normal is within this angle of a Manhattan axis."""
FOV_RANGE_DEG = (30.0, 120.0)
"""Horizontal fields of view the renderer accepts (the scenarios use 45-95 degrees)."""

_UNIT_CUBE_CORNERS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)


def intrinsics_from_fov(width: int, height: int, hfov_deg: float) -> np.ndarray:
    """`pinhole.intrinsics_from_fov` within the simulator's `FOV_RANGE_DEG`."""
    return pinhole_from_fov(width, height, hfov_deg, FOV_RANGE_DEG)


@dataclass(frozen=True)
class RenderedFrame:
    """One rendered view; see the module docstring for units and conventions."""

    rgb: np.ndarray
    depth: np.ndarray
    normals_c: np.ndarray
    manhattan_mask: np.ndarray
    K: np.ndarray
    R_wc: np.ndarray
    p_w: np.ndarray


@dataclass(frozen=True)
class _Packed:
    """A primitive ready for ray casting: local = A_ls @ (x_s - center), A_ls = S^-1 R_sl^T."""

    shape: Shape
    center: np.ndarray
    A_ls: np.ndarray
    R_sl: np.ndarray
    half: np.ndarray
    corners_s: np.ndarray
    materials: np.ndarray
    tile_m: float


def _pack(prim) -> _Packed:
    half = np.asarray(prim.half_size_m, float)
    A = (prim.R_sl / half).T  # S^-1 R^T
    corners = prim.center_m + (_UNIT_CUBE_CORNERS * half) @ prim.R_sl.T
    return _Packed(prim.shape, prim.center_m, A, prim.R_sl, half, corners,
                   np.asarray(prim.materials, np.int32), prim.tile_m)


class Renderer:
    """Renders one scene with fixed intrinsics; reuse it for every frame of a sequence."""

    def __init__(self, scene: Scene, K: np.ndarray, width: int, height: int):
        if width < 8 or height < 8:
            raise InputError(f"image size must be at least 8x8 pixels, got {width}x{height}")
        self.scene, self.K, self.width, self.height = scene, np.asarray(K, float), int(width), int(height)
        Kinv = np.linalg.inv(self.K)
        v, u = np.mgrid[0:height, 0:width].astype(np.float64)
        self.ray_x = (Kinv[0, 0] * u + Kinv[0, 1] * v + Kinv[0, 2]).astype(np.float32)
        self.ray_y = (Kinv[1, 1] * v + Kinv[1, 2]).astype(np.float32)
        self.layers = [(layer.name, [_pack(p) for p in layer.primitives]) for layer in scene.layers]
        self.textures = scene.textures
        self.tex_px = scene.textures.shape[1]

    # ----- geometry ---------------------------------------------------------------------------
    def _rect(self, prim: _Packed, R_sc: np.ndarray, o_s: np.ndarray):
        """Pixel rectangle (y0, y1, x0, x1) the primitive can cover, or None if off screen."""
        if prim.shape == Shape.ROOM:
            return 0, self.height, 0, self.width
        pc = (prim.corners_s - o_s) @ R_sc  # corners in the camera frame, (8, 3)
        z = pc[:, 2]
        if np.all(z < NEAR_M):
            return None
        if np.any(z < NEAR_M):
            return 0, self.height, 0, self.width
        u = self.K[0, 0] * pc[:, 0] / z + self.K[0, 2]
        v = self.K[1, 1] * pc[:, 1] / z + self.K[1, 2]
        x0, x1 = max(int(np.floor(u.min())), 0), min(int(np.ceil(u.max())) + 1, self.width)
        y0, y1 = max(int(np.floor(v.min())), 0), min(int(np.ceil(v.max())) + 1, self.height)
        if x0 >= x1 or y0 >= y1:
            return None
        return y0, y1, x0, x1

    @staticmethod
    def _local_rays(prim: _Packed, R_sc, o_s, rx, ry):
        """Ray origin (3,) and directions (3 arrays) in the primitive's unit-shape frame."""
        M = (prim.A_ls @ R_sc).astype(np.float32)
        o = prim.A_ls @ (o_s - prim.center)
        d = [M[k, 0] * rx + M[k, 1] * ry + M[k, 2] for k in range(3)]
        return o, d

    @staticmethod
    def _intersect(shape: Shape, o, d) -> np.ndarray:
        """Ray parameter (= depth) of the first hit beyond NEAR_M, inf where missed."""
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            if shape in (Shape.BOX, Shape.ROOM):
                inv = [1.0 / np.where(dk == 0, np.float32(1e-20), dk) for dk in d]
                t_near = np.maximum.reduce([-np.abs(iv) - o[k] * iv for k, iv in enumerate(inv)])
                t_far = np.minimum.reduce([np.abs(iv) - o[k] * iv for k, iv in enumerate(inv)])
                hit = t_near <= t_far
                t = t_far if shape == Shape.ROOM else t_near
                return np.where(hit & (t > NEAR_M), t, np.inf)
            if shape == Shape.SPHERE:
                a = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
                b = o[0] * d[0] + o[1] * d[1] + o[2] * d[2]
                c = float(o @ o) - 1.0
                t = (-b - np.sqrt(b * b - a * c)) / a
                return np.where(t > NEAR_M, t, np.inf)  # NaN (no root) compares False
            # Cylinder: radius 1 about local z, z in [-1, 1]; curved side then caps.
            a = d[0] * d[0] + d[1] * d[1]
            b = o[0] * d[0] + o[1] * d[1]
            c = o[0] ** 2 + o[1] ** 2 - 1.0
            t_side = (-b - np.sqrt(b * b - a * c)) / a
            z = o[2] + t_side * d[2]
            t_side = np.where((t_side > NEAR_M) & (np.abs(z) <= 1.0), t_side, np.inf)
            inv = 1.0 / d[2]
            t_cap = -np.abs(inv) - o[2] * inv
            xc, yc = o[0] + t_cap * d[0], o[1] + t_cap * d[1]
            t_cap = np.where((t_cap > NEAR_M) & (xc * xc + yc * yc <= 1.0), t_cap, np.inf)
            return np.minimum(t_side, t_cap)

    @staticmethod
    def _surface(prim: _Packed, x_l: np.ndarray):
        """Layer-frame normals (3, n), texture coordinates (2, n) in tiles and face index (n,) of
        local hit points x_l (3, n) on the unit shape. Arrays are (3, n): `R @ v` stays fast."""
        half = prim.half
        n = x_l.shape[1]
        cols = np.arange(n)
        if prim.shape in (Shape.BOX, Shape.ROOM):
            axis = np.argmax(np.abs(x_l), axis=0)
            coord = x_l[axis, cols]
            sign = np.where(coord > 0, 1.0, -1.0).astype(np.float32)
            face = 2 * axis + (coord > 0)
            if prim.shape == Shape.ROOM:
                sign = -sign  # seen from inside: normal points into the room
            n_s = prim.R_sl.astype(np.float32)[:, axis] * sign
            uv_axes = np.array([[1, 2], [0, 2], [0, 1]])[axis].T  # (2, n)
            uv = x_l[uv_axes, cols]
            if prim.tile_m > 0:
                uv = uv * (half[uv_axes] / prim.tile_m).astype(np.float32)
            else:
                uv = 0.5 * (uv + 1.0)
                uv[1] = 1.0 - uv[1]
            return n_s, uv, face
        around = np.arctan2(x_l[1], x_l[0]) * np.float32(half[0])
        if prim.shape == Shape.SPHERE:
            n_l = x_l
            face = np.zeros(n, np.int64)
            uv = np.stack([around, x_l[2] * np.float32(half[2])])
        else:
            cap = np.abs(x_l[2]) > 0.9999
            zero = np.zeros_like(x_l[0])
            n_l = np.where(cap, np.stack([zero, zero, np.sign(x_l[2])]), np.stack([x_l[0], x_l[1], zero]))
            face = np.where(cap, np.where(x_l[2] > 0, 5, 4), 0)
            uv = np.where(cap, x_l[:2] * half[:2, None].astype(np.float32),
                          np.stack([around, x_l[2] * np.float32(half[2])]))
        if prim.tile_m > 0:
            uv = uv / np.float32(prim.tile_m)
        n_s = (prim.R_sl / half).astype(np.float32) @ n_l  # R S^-1 n_l: inverse-transpose of S
        n_s /= np.sqrt(np.sum(n_s * n_s, axis=0))
        return n_s, uv, face

    # ----- frame --------------------------------------------------------------------------------
    def render(self, R_wc, p_w, layer_poses: dict | None = None, R_wm=None,
               exposure_gain: float = 1.0, noise_std_dn: float = 0.0, rng=None) -> RenderedFrame:
        """Render one view; see the module docstring. `exposure_gain` scales the radiance,
        `noise_std_dn` adds Gaussian sensor noise in 8-bit digital numbers (needs `rng`)."""
        radiance, depth, normals_c, mask = self.render_float(R_wc, p_w, layer_poses, R_wm)
        rgb = self.to_uint8(radiance, exposure_gain, noise_std_dn, rng)
        return RenderedFrame(rgb, depth, normals_c, mask, self.K.copy(), np.asarray(R_wc, float),
                             np.asarray(p_w, float))

    @staticmethod
    def to_uint8(radiance, exposure_gain=1.0, noise_std_dn=0.0, rng=None) -> np.ndarray:
        """Float radiance (H, W, 3) in [0, 1] to uint8 with gain and Gaussian noise (DN)."""
        img = radiance * np.float32(255.0 * exposure_gain)
        if noise_std_dn > 0:
            img += rng.standard_normal(img.shape, dtype=np.float32) * np.float32(noise_std_dn)
        return np.clip(img + 0.5, 0, 255).astype(np.uint8)

    def render_float(self, R_wc, p_w, layer_poses=None, R_wm=None):
        """(radiance (H, W, 3) float32 in [0, 1], depth, normals_c, manhattan_mask)."""
        R_wc, p_w = np.asarray(R_wc, float), np.asarray(p_w, float)
        R_wm = np.eye(3) if R_wm is None else np.asarray(R_wm, float)
        layer_poses = layer_poses or {}
        H, W = self.height, self.width
        best_t = np.full((H, W), np.inf, np.float32)
        best_id = np.full((H, W), -1, np.int32)
        jobs = []  # (prim, rect, R_sc, o_s, R_ws)
        for name, prims in self.layers:
            R_ws, p_ws = layer_poses.get(name, (np.eye(3), np.zeros(3)))
            R_ws, p_ws = np.asarray(R_ws, float), np.asarray(p_ws, float)
            R_sc, o_s = R_ws.T @ R_wc, R_ws.T @ (p_w - p_ws)
            for prim in prims:
                rect = self._rect(prim, R_sc, o_s)
                if rect is None:
                    continue
                y0, y1, x0, x1 = rect
                o, d = self._local_rays(prim, R_sc, o_s, self.ray_x[y0:y1, x0:x1], self.ray_y[y0:y1, x0:x1])
                t = self._intersect(prim.shape, o, d)
                bt, bi = best_t[y0:y1, x0:x1], best_id[y0:y1, x0:x1]
                closer = t < bt
                np.copyto(bt, t, where=closer)
                np.copyto(bi, len(jobs), where=closer)
                jobs.append((prim, rect, R_sc, o_s, R_ws))

        radiance = np.empty((H, W, 3), np.float32)
        radiance[:] = self.scene.sky_rgb
        normals_c = np.zeros((H, W, 3), np.float32)
        mask = np.zeros((H, W), bool)
        scene = self.scene
        cos_tol = np.cos(np.radians(MANHATTAN_TOL_DEG))
        flat_tex = self.textures.reshape(-1, 3)
        T = self.tex_px
        light = scene.light_dir_w.astype(np.float32)
        for k in np.flatnonzero(np.bincount(best_id.ravel() + 1, minlength=len(jobs) + 1)[1:]):
            prim, (y0, y1, x0, x1), R_sc, o_s, R_ws = jobs[k]
            sel = best_id[y0:y1, x0:x1] == k
            rx, ry = self.ray_x[y0:y1, x0:x1][sel], self.ray_y[y0:y1, x0:x1][sel]
            o, d = self._local_rays(prim, R_sc, o_s, rx, ry)
            t = best_t[y0:y1, x0:x1][sel]
            x_l = o.astype(np.float32)[:, None] + t * np.stack(d)  # (3, n)
            n_s, uv, face = self._surface(prim, x_l)
            n_w = R_ws.astype(np.float32) @ n_s
            n_c = R_wc.T.astype(np.float32) @ n_w
            n_m = np.abs(R_wm.T.astype(np.float32) @ n_w)
            tiles = np.floor(uv * T).astype(np.int64) % T
            albedo = flat_tex[(prim.materials[face] * T + tiles[1]) * T + tiles[0]]
            lambert = np.maximum(light @ n_w, 0.0)
            shade = (scene.ambient + scene.diffuse * lambert)[:, None] * scene.light_rgb
            radiance[y0:y1, x0:x1][sel] = albedo * shade
            normals_c[y0:y1, x0:x1][sel] = n_c.T
            mask[y0:y1, x0:x1][sel] = n_m.max(axis=0) >= cos_tol
        depth = np.where(np.isfinite(best_t), best_t, 0.0).astype(np.float32)
        return np.clip(radiance, 0.0, 1.0), depth, normals_c, mask
