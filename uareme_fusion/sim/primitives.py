"""The parts of a procedural scene: unit `Shape`s placed as `Primitive`s, grouped in `Layer`s that
move together, and the `Scene` of layers with its lighting (see `scenes` for the conventions)."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation


class Shape(enum.IntEnum):
    BOX = 0
    ROOM = 1
    """A box seen from inside: rays hit its far faces, normals point inwards."""
    SPHERE = 2
    CYLINDER = 3


@dataclass(frozen=True)
class Primitive:
    shape: Shape
    center_m: np.ndarray
    half_size_m: np.ndarray
    R_sl: np.ndarray
    """Local to layer rotation (3, 3)."""
    materials: tuple[int, int, int, int, int, int]
    tile_m: float = 1.0
    """Texture period in metres; 0 stretches the texture once over each face (posters)."""

    def as_dict(self) -> dict:
        return dict(shape=self.shape.name.lower(), center_m=self.center_m.tolist(),
                    half_size_m=self.half_size_m.tolist(),
                    quat_xyzw=Rotation.from_matrix(self.R_sl).as_quat().tolist(),
                    materials=list(self.materials), tile_m=self.tile_m)


@dataclass
class Layer:
    name: str
    """`"world"` (static in the world) or `"body"` (moves with the vehicle body)."""
    primitives: list[Primitive] = field(default_factory=list)


@dataclass
class Scene:
    """Geometry, materials and lights of one synthetic scene; see the module docstring."""

    name: str
    seed: int
    layers: list[Layer]
    textures: np.ndarray
    """(n_materials, TEXTURE_PX, TEXTURE_PX, 3) float32 albedo."""
    material_kinds: list[str]
    light_dir_w: np.ndarray
    """Unit vector pointing FROM the scene TOWARDS the directional light, world frame."""
    ambient: float
    diffuse: float
    light_rgb: np.ndarray
    sky_rgb: np.ndarray
    """Colour of rays that hit nothing (float in [0, 1])."""
    params: dict = field(default_factory=dict)
    """Every number the scene was generated from (for scene.json)."""

    def as_dict(self) -> dict:
        return dict(name=self.name, seed=self.seed, material_kinds=self.material_kinds,
                    light_dir_w=self.light_dir_w.tolist(), ambient=self.ambient,
                    diffuse=self.diffuse, light_rgb=self.light_rgb.tolist(),
                    sky_rgb=self.sky_rgb.tolist(), params=self.params,
                    layers={layer.name: [p.as_dict() for p in layer.primitives]
                            for layer in self.layers})
