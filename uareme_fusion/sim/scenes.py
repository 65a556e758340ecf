"""Seeded procedural scenes made of boxes, rooms (boxes seen from inside), spheres and cylinders.

A `Scene` is a list of `Layer`s. Each layer's primitives are static in the layer's own frame `s`:
layer `"world"` is the world frame (buildings, streets), layer `"body"` moves with the vehicle
body (the bus interior, whose frame is the Manhattan frame of the bus scenario). The renderer
takes each layer's pose (`R_ws`, `p_ws`) per frame.

Building scenes are axis-aligned with the world, so their Manhattan frame is the world's axes
(`R_wm = I`); clutter (rotated boxes, spheres, cylinders, people-sized ellipsoids) is deliberately
not. Every primitive is a unit shape (cube [-1, 1]^3, unit sphere, unit cylinder of radius 1 and
z in [-1, 1]) scaled by `half_size_m` along its local axes, rotated by `R_sl` (local to layer) and
moved to `center_m`. Faces carry material indices in the order -x, +x, -y, +y, -z, +z (spheres and
cylinders use index 0 for the curved surface, 4 and 5 for the caps).

Scene names (`SCENE_NAMES`): `room`, `office`, `corridor`, `street`, `bus`. Same seed, same scene.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from .materials import make_texture
from .primitives import Layer, Primitive, Scene, Shape


def _yaw(angle_rad: float) -> np.ndarray:
    return Rotation.from_euler("z", angle_rad).as_matrix()


class _Builder:
    """Accumulates materials and primitives from one seeded generator."""

    def __init__(self, rng: np.random.Generator):
        self.rng = rng
        self.textures: list[np.ndarray] = []
        self.kinds: list[str] = []
        self.layers = {"world": Layer("world")}

    def material(self, kind: str, colour=None) -> int:
        self.textures.append(make_texture(kind, self.rng, colour))
        self.kinds.append(kind)
        return len(self.textures) - 1

    def random_material(self, kinds=("plain", "noise", "stripes", "wood")) -> int:
        return self.material(str(self.rng.choice(kinds)))

    def add(self, shape, center, size, mats, R=None, tile_m=1.0, layer="world"):
        """Add a primitive of full `size` (m) centred at `center`; `mats` an int or 6 ints."""
        mats = (mats,) * 6 if np.isscalar(mats) else tuple(mats)
        prim = Primitive(Shape(shape), np.asarray(center, float), 0.5 * np.asarray(size, float),
                         np.eye(3) if R is None else np.asarray(R, float),
                         tuple(int(m) for m in mats), float(tile_m))
        self.layers.setdefault(layer, Layer(layer)).primitives.append(prim)

    def box(self, lo, hi, mats, tile_m=1.0, layer="world"):
        """Axis-aligned box between corners lo and hi."""
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        self.add(Shape.BOX, (lo + hi) / 2, hi - lo, mats, tile_m=tile_m, layer=layer)

    # ----- building parts ------------------------------------------------------------------
    def room(self, lo, hi, layer="world", n_doors=1, n_windows=2, n_posters=2):
        """A room between corners lo and hi (floor at lo z) with doors, windows and posters."""
        rng = self.rng
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        wall = self.random_material(("plain", "noise", "stripes"))
        floor = self.random_material(("wood", "checker", "noise"))
        ceiling = self.material("plain", rng.uniform(0.75, 0.95, 3))
        mats = (wall, wall, wall, wall, floor, ceiling)
        self.add(Shape.ROOM, (lo + hi) / 2, hi - lo, mats, layer=layer)
        items = [("door", 0.9, 2.0, 0.0)] * n_doors + [("window", 1.2, 1.0, 0.9)] * n_windows
        items += [("poster", 0.6, 0.8, 1.2)] * n_posters
        for kind, width, height, bottom in items:
            self.wall_panel(lo, hi, kind, width, height, bottom, layer)

    def wall_panel(self, lo, hi, kind, width, height, bottom, layer="world"):
        """A thin box on a random wall: a door, a window or a poster."""
        rng = self.rng
        axis, side = int(rng.integers(0, 2)), int(rng.integers(0, 2))
        along = 1 - axis
        span = hi[along] - lo[along]
        if span < width + 0.4 or hi[2] - lo[2] < bottom + height + 0.05:
            return
        s = rng.uniform(lo[along] + 0.2 + width / 2, hi[along] - 0.2 - width / 2)
        depth = 0.04 if kind == "door" else 0.02
        wall_at = hi[axis] if side else lo[axis]
        box_lo, box_hi = np.zeros(3), np.zeros(3)
        box_lo[axis], box_hi[axis] = (wall_at - depth, wall_at) if side else (wall_at, wall_at + depth)
        box_lo[along], box_hi[along] = s - width / 2, s + width / 2
        box_lo[2], box_hi[2] = lo[2] + bottom, lo[2] + bottom + height
        mat = {"door": lambda: self.random_material(("wood", "plain")),
               "window": lambda: self.material("sky"),
               "poster": lambda: self.material("poster")}[kind]()
        self.box(box_lo, box_hi, mat, tile_m=0.0 if kind != "door" else 1.0, layer=layer)

    def table(self, x, y, z0, width, depth, height, yaw90: bool):
        w, d = (depth, width) if yaw90 else (width, depth)
        top = self.random_material(("wood", "plain"))
        leg = self.material("plain")
        self.box((x - w / 2, y - d / 2, z0 + height - 0.04), (x + w / 2, y + d / 2, z0 + height), top)
        for sx in (-1, 1):
            for sy in (-1, 1):
                cx, cy = x + sx * (w / 2 - 0.05), y + sy * (d / 2 - 0.05)
                self.box((cx - 0.025, cy - 0.025, z0), (cx + 0.025, cy + 0.025, z0 + height - 0.04), leg)

    def furniture_along_walls(self, lo, hi, n, keep_out_radius_m):
        """Cabinets, shelves, sofas and tables against the walls, outside a central keep-out disc."""
        rng = self.rng
        for _ in range(n):
            axis, side = int(rng.integers(0, 2)), int(rng.integers(0, 2))
            along = 1 - axis
            width = rng.uniform(0.6, 1.8)
            depth = rng.uniform(0.35, 0.6)
            height = rng.uniform(0.45, 2.0)
            if hi[along] - lo[along] < width + 0.2:
                continue
            s = rng.uniform(lo[along] + width / 2 + 0.05, hi[along] - width / 2 - 0.05)
            box_lo, box_hi = np.zeros(3), np.zeros(3)
            wall = hi[axis] if side else lo[axis]
            box_lo[axis], box_hi[axis] = (wall - depth, wall - 0.001) if side else (wall + 0.001, wall + depth)
            box_lo[along], box_hi[along] = s - width / 2, s + width / 2
            box_lo[2], box_hi[2] = lo[2], lo[2] + height
            inner = box_lo[axis] if side else box_hi[axis]
            if abs(inner) < keep_out_radius_m:
                continue
            if rng.random() < 0.3 and height < 1.0:
                self.table((box_lo[0] + box_hi[0]) / 2, (box_lo[1] + box_hi[1]) / 2, lo[2],
                           box_hi[along] - box_lo[along], depth, 0.75, yaw90=axis == 0)
            else:
                self.box(box_lo, box_hi, self.random_material(), tile_m=rng.uniform(0.5, 2.0))

    def clutter(self, lo, hi, n, keep_out_radius_m=0.0, keep_out_center=(0.0, 0.0), layer="world"):
        """Non-Manhattan objects: rotated boxes, spheres, cylinders, people-sized ellipsoids."""
        rng = self.rng
        added = 0
        for _ in range(4 * n):
            if added == n:
                break
            x, y = rng.uniform(lo[:2] + 0.3, hi[:2] - 0.3)
            if np.hypot(x - keep_out_center[0], y - keep_out_center[1]) < keep_out_radius_m:
                continue
            kind = rng.choice(["box", "sphere", "cylinder", "person"], p=[0.4, 0.2, 0.2, 0.2])
            mat = self.random_material(("plain", "noise", "stripes"))
            z0 = lo[2]
            if kind == "box":
                size = rng.uniform(0.2, 0.7, 3)
                R = Rotation.from_euler("zyx", rng.uniform(-np.pi, np.pi, 3) * [1, 0.3, 0.3]).as_matrix()
                self.add(Shape.BOX, (x, y, z0 + size[2] / 2 + 0.1), size, mat, R=R, layer=layer)
            elif kind == "sphere":
                r = rng.uniform(0.1, 0.35)
                self.add(Shape.SPHERE, (x, y, z0 + r), (2 * r,) * 3, mat, layer=layer)
            elif kind == "cylinder":
                r, h = rng.uniform(0.1, 0.3), rng.uniform(0.3, 1.0)
                R = None if rng.random() < 0.6 else Rotation.from_euler("x", np.pi / 2).as_matrix() @ _yaw(rng.uniform(0, np.pi))
                self.add(Shape.CYLINDER, (x, y, z0 + h / 2 if R is None else z0 + r), (2 * r, 2 * r, h), mat,
                         R=R, layer=layer)
            else:  # person: body ellipsoid and head sphere
                h = rng.uniform(1.5, 1.9)
                R = _yaw(rng.uniform(0, np.pi))
                self.add(Shape.SPHERE, (x, y, z0 + 0.42 * h), (0.45, 0.3, 0.84 * h), mat, R=R, layer=layer)
                self.add(Shape.SPHERE, (x, y, z0 + 0.9 * h), (0.22, 0.22, 0.25), self.material("plain"),
                         layer=layer)
            added += 1

    def building_block(self, lo_xy, hi_xy, height, ground_z=0.0, layer="world", facade_windows=True):
        """A building: one box with rows of window panes on the faces that a street sees."""
        rng = self.rng
        facade = self.random_material(("plain", "noise", "stripes"))
        self.box((lo_xy[0], lo_xy[1], ground_z), (hi_xy[0], hi_xy[1], ground_z + height), facade,
                 tile_m=rng.uniform(2.0, 6.0), layer=layer)
        if not facade_windows:
            return
        glass = self.material("sky")
        # Window bands: one thin box per floor along each long face (few primitives, many panes).
        for floor_z in np.arange(ground_z + 1.2, ground_z + height - 1.0, 3.0):
            for axis_y in (lo_xy[1] - 0.02, hi_xy[1]):
                self.box((lo_xy[0] + 0.5, axis_y, floor_z), (hi_xy[0] - 0.5, axis_y + 0.02, floor_z + 1.2),
                         glass, tile_m=0.0, layer=layer)

    def build(self, name: str, seed: int, params: dict, sky=(0.7, 0.8, 0.95)) -> Scene:
        rng = self.rng
        light = np.array([rng.uniform(-0.6, 0.6), rng.uniform(-0.6, 0.6), 1.0])
        return Scene(name, int(seed), list(self.layers.values()), np.stack(self.textures), self.kinds,
                     light / np.linalg.norm(light), float(rng.uniform(0.3, 0.5)),
                     float(rng.uniform(0.5, 0.7)), rng.uniform(0.9, 1.0, 3).astype(np.float32),
                     np.asarray(sky, np.float32), params)


# --------------------------------------------------------------------------------------------
# Scene generators
# --------------------------------------------------------------------------------------------


def _room(b: _Builder, seed: int, **kw) -> Scene:
    rng = b.rng
    half = np.array([kw.get("half_x_m", rng.uniform(2.8, 4.0)), kw.get("half_y_m", rng.uniform(2.8, 4.0))])
    height = float(kw.get("height_m", rng.uniform(2.5, 3.2)))
    lo, hi = np.array([-half[0], -half[1], 0.0]), np.array([half[0], half[1], height])
    b.room(lo, hi, n_doors=1, n_windows=int(rng.integers(1, 3)), n_posters=int(rng.integers(1, 4)))
    keep = float(kw.get("keep_out_radius_m", 2.0))
    b.furniture_along_walls(lo, hi, int(kw.get("n_furniture", 5)), keep)
    b.clutter(lo, hi, int(kw.get("n_clutter", 4)), keep_out_radius_m=keep)
    return b.build("room", seed, dict(half_x_m=float(half[0]), half_y_m=float(half[1]), height_m=height,
                                      keep_out_radius_m=keep))


def _office(b: _Builder, seed: int, **kw) -> Scene:
    rng = b.rng
    half = np.array([rng.uniform(4.5, 6.5), rng.uniform(4.0, 6.0)])
    height = float(rng.uniform(2.6, 3.2))
    lo, hi = np.array([-half[0], -half[1], 0.0]), np.array([half[0], half[1], height])
    b.room(lo, hi, n_doors=2, n_windows=3, n_posters=2)
    keep = float(kw.get("keep_out_radius_m", 2.0))
    # Desks in rows with monitors, outside the walking disc.
    for x in np.arange(-half[0] + 1.2, half[0] - 0.8, 2.2):
        for y in (-half[1] + 0.8, half[1] - 0.8):
            if np.hypot(x, y) < keep + 0.8:
                continue
            b.table(x, y, 0.0, 1.4, 0.7, 0.74, yaw90=False)
            b.box((x - 0.25, y - 0.02, 0.74), (x + 0.25, y + 0.02, 1.1), b.material("plain", (0.1, 0.1, 0.12)))
    for _ in range(int(rng.integers(2, 5))):  # ceiling light panels
        x, y = rng.uniform(lo[:2] + 1, hi[:2] - 1)
        b.box((x - 0.6, y - 0.3, height - 0.02), (x + 0.6, y + 0.3, height - 0.001), b.material("plain", (1, 1, 0.95)))
    b.furniture_along_walls(lo, hi, 3, keep)
    b.clutter(lo, hi, int(kw.get("n_clutter", 5)), keep_out_radius_m=keep)
    return b.build("office", seed, dict(half_x_m=float(half[0]), half_y_m=float(half[1]), height_m=height,
                                        keep_out_radius_m=keep))


def _corridor(b: _Builder, seed: int, **kw) -> Scene:
    rng = b.rng
    length = float(kw.get("length_m", rng.uniform(40.0, 60.0)))
    half_w = float(rng.uniform(1.0, 1.6))
    height = float(rng.uniform(2.5, 3.0))
    lo, hi = np.array([-5.0, -half_w, 0.0]), np.array([length - 5.0, half_w, height])
    b.room(lo, hi, n_doors=0, n_windows=0, n_posters=0)
    door = b.random_material(("wood", "plain"))
    for x in np.arange(lo[0] + 2.0, hi[0] - 1.0, rng.uniform(3.0, 5.0)):
        side = hi[1] - 0.04 if rng.random() < 0.5 else lo[1]
        b.box((x, side, 0.0), (x + 0.9, side + 0.04, 2.0), door)
        if rng.random() < 0.4:
            y = lo[1] if side > 0 else hi[1] - 0.02
            b.box((x + 1.5, y, 1.2), (x + 2.1, y + 0.02, 2.0), b.material("poster"), tile_m=0.0)
    lamp = b.material("plain", (1.0, 1.0, 0.95))
    for x in np.arange(lo[0] + 1.0, hi[0], 4.0):
        b.box((x, -0.2, height - 0.02), (x + 1.2, 0.2, height - 0.001), lamp)
    b.clutter(lo, hi, int(kw.get("n_clutter", 4)), keep_out_radius_m=0.8, keep_out_center=(0.0, 0.0))
    return b.build("corridor", seed, dict(length_m=length, half_width_m=half_w, height_m=height))


def _street(b: _Builder, seed: int, **kw) -> Scene:
    rng = b.rng
    length = float(kw.get("length_m", 120.0))
    half_w = float(rng.uniform(6.0, 10.0))
    road = b.material("noise", (0.3, 0.3, 0.32))
    pavement = b.material("checker")
    b.box((-20.0, -half_w + 2.5, -0.1), (length, half_w - 2.5, 0.0), road, tile_m=4.0)
    for sy in (-1, 1):
        y_in, y_out = sy * (half_w - 2.5), sy * half_w
        b.box((-20.0, min(y_in, y_out), -0.1), (length, max(y_in, y_out), 0.12), pavement, tile_m=2.0)
        x = -20.0
        while x < length:
            width = rng.uniform(8.0, 20.0)
            depth = rng.uniform(8.0, 15.0)
            y0 = sy * half_w
            y1 = sy * (half_w + depth)
            b.building_block((x, min(y0, y1)), (x + width, max(y0, y1)), rng.uniform(6.0, 25.0))
            x += width + rng.uniform(0.0, 2.0)
    for x in np.arange(-10.0, length, rng.uniform(12.0, 20.0)):  # street lamps
        b.add(Shape.CYLINDER, (x, half_w - 2.9, 2.5), (0.16, 0.16, 5.0), b.material("plain", (0.2, 0.2, 0.2)))
    b.clutter(np.array([-10.0, -half_w + 0.5, 0.0]), np.array([length, half_w - 0.5, 3.0]),
              int(kw.get("n_clutter", 8)), keep_out_radius_m=1.5)
    return b.build("street", seed, dict(length_m=length, half_width_m=half_w))


BUS_HALF_WIDTH_M = 1.25
BUS_HEIGHT_M = 2.4


def _bus(b: _Builder, seed: int, route_xy_m: np.ndarray | None = None, **kw) -> Scene:
    """Bus interior in the body layer (x forward, y left, z up; floor at z = 0, camera above the
    origin) and, when `route_xy_m` (N, 2) is given, buildings along the route in the world layer."""
    rng = b.rng
    front, back = float(rng.uniform(2.5, 4.0)), -float(rng.uniform(6.0, 9.0))
    hw, h = BUS_HALF_WIDTH_M, BUS_HEIGHT_M
    shell = b.random_material(("plain", "noise"))
    floor = b.material("noise", (0.25, 0.25, 0.28))
    roof = b.material("plain", (0.85, 0.85, 0.85))
    lay = "body"
    b.box((back, -hw, -0.05), (front, hw, 0.0), floor, layer=lay)  # floor
    b.box((back, -hw, h), (front, hw, h + 0.05), roof, layer=lay)  # roof
    b.box((front, -hw, 0.0), (front + 0.05, hw, 0.9), shell, layer=lay)  # dashboard wall
    b.box((back - 0.05, -hw, 0.0), (back, hw, h), shell, layer=lay)  # rear wall
    for sy in (-1, 1):
        y0, y1 = (sy * hw, sy * (hw + 0.05))
        ylo, yhi = min(y0, y1), max(y0, y1)
        b.box((back, ylo, 0.0), (front, yhi, 0.95), shell, layer=lay)  # below windows
        b.box((back, ylo, 2.0), (front, yhi, h), shell, layer=lay)  # above windows
        for x in np.arange(back, front, 1.6):  # window pillars
            b.box((x, ylo, 0.95), (x + 0.12, yhi, 2.0), shell, layer=lay)
    seat = b.random_material(("stripes", "noise", "plain"))
    pole = b.material("plain", (0.9, 0.8, 0.1))
    for x in np.arange(back + 0.5, front - 2.0, 0.85):
        for sy in (-1, 1):
            y_out, y_in = sy * (hw - 0.05), sy * (hw - 0.95)
            ylo, yhi = min(y_out, y_in), max(y_out, y_in)
            b.box((x, ylo, 0.0), (x + 0.45, yhi, 0.45), seat, layer=lay)  # seat
            b.box((x + 0.38, ylo, 0.45), (x + 0.48, yhi, 1.0), seat, layer=lay)  # backrest
        if rng.random() < 0.5:
            b.add(Shape.CYLINDER, (x + 0.6, float(rng.choice([-1, 1])) * (hw - 1.0), h / 2), (0.07, 0.07, h),
                  pole, layer=lay)
    for sy in (-1, 1):  # handrails along the ceiling
        b.add(Shape.CYLINDER, ((front + back) / 2, sy * 0.45, 1.95), (0.06, 0.06, front - back - 0.4), pole,
              R=Rotation.from_euler("y", np.pi / 2).as_matrix(), layer=lay)
    b.clutter(np.array([back + 0.5, -0.3, 0.0]), np.array([front - 3.0, 0.3, 0.0]),
              int(kw.get("n_passengers", 2)), keep_out_radius_m=1.0, layer=lay)
    params = dict(bus_front_m=front, bus_back_m=back, bus_half_width_m=hw, bus_height_m=h)
    if route_xy_m is not None:
        _buildings_along_route(b, np.asarray(route_xy_m, float))
        params["route_buildings"] = True
    return b.build("bus", seed, params)


def _buildings_along_route(b: _Builder, route_xy: np.ndarray, clearance_m: float = 9.0):
    """Ground plane and blocks of buildings beside a route (N, 2), none within clearance of it."""
    rng = b.rng
    lo, hi = route_xy.min(axis=0) - 40.0, route_xy.max(axis=0) + 40.0
    b.box((lo[0], lo[1], -0.2), (hi[0], hi[1], -0.05), b.material("noise", (0.3, 0.3, 0.32)), tile_m=4.0)
    route = route_xy[:: max(1, len(route_xy) // 400)]
    for x in np.arange(lo[0], hi[0], 16.0):
        for y in np.arange(lo[1], hi[1], 16.0):
            size = rng.uniform(8.0, 14.0, 2)
            corners = np.array([x, y]) + np.array([[0, 0], [size[0], 0], [0, size[1]], size, size / 2])
            if np.min(np.linalg.norm(route[:, None] - corners[None], axis=-1)) < clearance_m:
                continue
            b.building_block((x, y), (x + size[0], y + size[1]), rng.uniform(6.0, 20.0), facade_windows=False)


SCENE_NAMES = ("room", "office", "corridor", "street", "bus")
_GENERATORS = dict(room=_room, office=_office, corridor=_corridor, street=_street, bus=_bus)


def make_scene(name: str, seed: int = 0, **params) -> Scene:
    """Generate the named scene from `seed`; `params` override its numbers (see each generator)."""
    if name not in _GENERATORS:
        raise InputError(f"unknown scene {name!r}; valid: {', '.join(SCENE_NAMES)}")
    return _GENERATORS[name](_Builder(np.random.default_rng(seed)), seed, **params)
