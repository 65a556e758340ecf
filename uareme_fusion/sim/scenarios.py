"""Named simulation scenarios: a scene, a trajectory and rendering/IMU options that belong together.

    spec = SCENARIOS["bus"]
    world = build_scenario("bus", duration_s=20.0, seed=0)   # -> SimWorld
    frame = world.render(renderer, t_s)                       # layer poses and R_wm handled here

Scenarios (`SCENARIO_NAMES`): `room`, `office`, `corridor`, `street`, `bus`, `shake`, `static`,
`pan`, `tilt`, `roll`, `dropped_frames`. In `bus` the Manhattan frame is the bus body (see
`trajectory.py`); everywhere else it is the world's axes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from .render import Renderer
from .scenes import Scene, make_scene
from .trajectory import Trajectory, make_trajectory


@dataclass(frozen=True)
class ScenarioSpec:
    """What a scenario is made of; every field is recorded in scene.json."""

    scene: str
    trajectory: str
    description: str
    trajectory_params: dict = field(default_factory=dict)
    hfov_deg: float = 70.0
    noise_std_dn: float = 1.5
    """Gaussian sensor noise, 8-bit digital numbers."""
    motion_blur_exposure_s: float = 0.0
    """Exposure time over which motion blurs each image (0: none)."""
    exposure_change: bool = False
    """Slowly varying exposure gain (auto-exposure hunting)."""
    drop_probability: float = 0.0
    """Probability that a frame is dropped (black image, zero depth)."""
    platform: str = "handheld"
    """What carries the camera (an EKF preset name): `vehicle` where the Manhattan frame moves with it."""


SCENARIOS: dict[str, ScenarioSpec] = {
    "room": ScenarioSpec("room", "walk", "handheld walk in a furnished room",
                         dict(radius_m=1.2)),
    "office": ScenarioSpec("office", "walk", "handheld walk in an office with desks",
                           dict(radius_m=1.2)),
    "corridor": ScenarioSpec("corridor", "forward_walk", "walking down a long corridor",
                             dict(speed_m_s=1.2), hfov_deg=80.0),
    "street": ScenarioSpec("street", "forward_walk", "walking along a street canyon",
                           dict(speed_m_s=1.4), hfov_deg=80.0),
    "bus": ScenarioSpec("bus", "bus", "camera fixed in a city bus: accelerating, braking, corner, "
                        "roundabout; the interior is the Manhattan frame", hfov_deg=90.0, platform="vehicle"),
    "shake": ScenarioSpec("room", "shake", "fast handheld shake in a room (motion blur)",
                          motion_blur_exposure_s=0.01),
    "static": ScenarioSpec("room", "static", "camera at rest in a room"),
    "pan": ScenarioSpec("room", "pan", "pan sweep in a room"),
    "tilt": ScenarioSpec("room", "tilt", "tilt sweep in a room"),
    "roll": ScenarioSpec("room", "roll", "roll sweep in a room"),
    "dropped_frames": ScenarioSpec("room", "walk", "walk in a room with 10% dropped (black) frames "
                                   "and changing exposure", dict(radius_m=1.2),
                                   drop_probability=0.1, exposure_change=True, noise_std_dn=3.0),
}
SCENARIO_NAMES = tuple(SCENARIOS)


@dataclass
class SimWorld:
    """A scene and the trajectory through it, with the per-frame pose bookkeeping."""

    name: str
    spec: ScenarioSpec
    scene: Scene
    trajectory: Trajectory

    def layer_poses(self, t_s: float) -> dict:
        """Pose (R_ws, p_ws) of each moving layer at time t: the bus body, floor origin below
        the camera."""
        if not self.trajectory.manhattan_is_body:
            return {}
        R_wb = self.trajectory.R_wb(t_s)[0]
        p_w = self.trajectory.sample(t_s).p_w[0]
        height = self.trajectory.params["camera_height_m"]
        return {"body": (R_wb, p_w - R_wb @ np.array([0.0, 0.0, height]))}

    def render_radiance(self, renderer: Renderer, t_s: float):
        """(radiance, depth, normals_c, manhattan_mask, R_wc, p_w) at time t_s (no blur)."""
        sample = self.trajectory.sample(t_s)
        R_wc, p_w = sample.R_wc[0], sample.p_w[0]
        out = renderer.render_float(R_wc, p_w, self.layer_poses(t_s), self.trajectory.R_wm(t_s)[0])
        return (*out, R_wc, p_w)


def build_scenario(name: str, duration_s: float, seed: int = 0) -> SimWorld:
    """The named scenario's scene and trajectory, both generated from `seed`."""
    if name not in SCENARIOS:
        raise InputError(f"unknown scenario {name!r}; valid: {', '.join(SCENARIO_NAMES)}")
    spec = SCENARIOS[name]
    traj = make_trajectory(spec.trajectory, duration_s, seed, **spec.trajectory_params)
    scene_params = {}
    if spec.scene == "bus":
        t = np.arange(0.0, duration_s + 1.0, 0.5)
        scene_params["route_xy_m"] = traj.sample(np.minimum(t, duration_s)).p_w[:, :2]
    if spec.trajectory == "forward_walk":
        scene_params["length_m"] = max(60.0, 1.5 * spec.trajectory_params.get("speed_m_s", 1.2) * duration_s + 20.0)
    scene = make_scene(spec.scene, seed + 1_000_003, **scene_params)
    return SimWorld(name, spec, scene, traj)
