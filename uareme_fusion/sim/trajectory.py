"""Smooth camera trajectories with exact derivatives, for rendering and IMU simulation.

Public API::

    traj = make_trajectory("walk", duration_s=60.0, seed=0)
    R_wc, p_w, omega_c_rad_s, accel_w_m_s2 = traj.sample(t_s)      # t_s: (N,) seconds
    R_wm = traj.R_wm(t_s)                                          # (N, 3, 3)

Conventions (docs/design.md):
- `R_wc` (N, 3, 3) maps camera coordinates (OpenCV: x right, y down, z forward) to the world
  (z up, gravity (0, 0, -9.81) m/s^2). `p_w` (N, 3) is the camera centre in the world, metres.
- `omega_c_rad_s` (N, 3) is the camera's angular velocity in the CAMERA (body) frame, rad/s:
  `dR_wc/dt = R_wc @ skew(omega_c)`.
- `accel_w_m_s2` (N, 3) is the camera centre's kinematic acceleration `d^2 p_w / dt^2` in the
  world frame (gravity NOT included; `imu.simulate_imu` forms the specific force).
- `R_wm(t)` (N, 3, 3) maps Manhattan-frame coordinates to the world. In buildings the scene is
  built axis-aligned with the world, so `R_wm` is the identity at all times. In the vehicle
  scenario the Manhattan frame is the bus body (x forward, y left, z up): `R_wm(t)` is the bus's
  full attitude (its yaw plus the < 2 degree body sway), and the camera is rigidly mounted in it,
  so `R_cm = R_wc^T R_wm` is constant.

How trajectories are made: the camera is carried by a "body" b (x forward, y left, z up) whose
attitude is `R_wb = Rz(yaw) @ Ry(pitch) @ Rx(roll)` (scipy intrinsic "ZYX"), and
`R_wc = R_wb @ R_bc` with a constant mount `R_bc` (default: camera looks along body x, image
down = body -z). Yaw, pitch, roll and the position are `Signal`s, sums of sinusoids, polynomials
and smooth (raised-cosine) ramps, each with analytic first and second derivatives, so the angular
velocity is exact: `omega_b = [roll' - yaw' sin(pitch), pitch' cos(roll) + yaw' cos(pitch)
sin(roll), yaw' cos(pitch) cos(roll) - pitch' sin(roll)]`, `omega_c = R_bc^T omega_b`.
The vehicle's position is the integral of speed along its heading; its acceleration is exact
(`v' * heading + v * yaw' * left`), its position is integrated numerically (1 ms Simpson steps,
then a cubic Hermite spline with the exact velocities).

Scenarios (`TRAJECTORY_NAMES`): `walk` (handheld walk around a loop of about 1.5 m radius at
eye height, head bob, pan and small tilt/roll), `forward_walk` (walking along +x at about
1.2 m/s, for corridors and streets), `pan`, `tilt`, `roll` (sinusoidal sweeps about one axis of
`amplitude_deg`), `shake` (fast handheld shake, several Hz, up to about 5 rad/s), `static`, and
`bus` (camera fixed in a bus that accelerates at up to 1.5 m/s^2, brakes at up to 2.5 m/s^2, takes
a 90 degree corner and a roundabout with 2-3 m/s^2 centripetal acceleration, with < 2 degrees of
body sway). All of them are seeded: the same seed gives the same trajectory.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, NamedTuple

import numpy as np
from scipy.interpolate import CubicHermiteSpline
from scipy.spatial.transform import Rotation

from ..errors import InputError
from .signals import Signal, const_signal, random_sines

# Camera mounted looking along body x (forward), image x right = body -y, image y down = body -z.
R_BC_FORWARD = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
"""Default mount `R_bc`: columns are the camera axes (x right, y down, z forward) in the body frame."""

EYE_HEIGHT_M = 1.5
"""Camera height of handheld trajectories above the floor (z = 0), metres."""


# --------------------------------------------------------------------------------------------
# Trajectory
# --------------------------------------------------------------------------------------------


class TrajectorySample(NamedTuple):
    """One or many samples of a trajectory; unpacks as `R_wc, p_w, omega_c_rad_s, accel_w_m_s2`."""

    R_wc: np.ndarray
    """(N, 3, 3) camera-to-world rotation."""
    p_w: np.ndarray
    """(N, 3) camera centre in the world, m."""
    omega_c_rad_s: np.ndarray
    """(N, 3) angular velocity in the camera frame, rad/s."""
    accel_w_m_s2: np.ndarray
    """(N, 3) kinematic acceleration in the world frame (no gravity), m/s^2."""


PositionFn = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class Trajectory:
    """A camera trajectory over [0, duration_s]; see the module docstring for conventions.

    `yaw`, `pitch`, `roll` (rad) give the body attitude `R_wb = Rz(yaw) Ry(pitch) Rx(roll)`;
    `position` returns (p_w, v_w, a_w) arrays (N, 3); `R_bc` is the camera mount; `manhattan_is_body`
    says whether the Manhattan frame moves with the body (vehicle) or is the world's axes.
    `params` records every number the trajectory was built from (for `scene.json`).
    """

    name: str
    duration_s: float
    yaw: Signal
    pitch: Signal
    roll: Signal
    position: PositionFn
    R_bc: np.ndarray = field(default_factory=lambda: R_BC_FORWARD.copy())
    manhattan_is_body: bool = False
    R_wm_fixed: np.ndarray = field(default_factory=lambda: np.eye(3))
    params: dict = field(default_factory=dict)

    def R_wb(self, t_s: np.ndarray) -> np.ndarray:
        """Body attitude (N, 3, 3): body (x forward, y left, z up) to world."""
        t = np.atleast_1d(np.asarray(t_s, float))
        angles = np.stack([self.yaw(t)[0], self.pitch(t)[0], self.roll(t)[0]], axis=-1)
        return Rotation.from_euler("ZYX", angles).as_matrix()

    def sample(self, t_s: np.ndarray) -> TrajectorySample:
        """Attitude, position, body angular velocity and world acceleration at times `t_s` (N,)."""
        t = np.atleast_1d(np.asarray(t_s, float))
        psi, dpsi, _ = self.yaw(t)
        theta, dtheta, _ = self.pitch(t)
        phi, dphi, _ = self.roll(t)
        R_wb = Rotation.from_euler("ZYX", np.stack([psi, theta, phi], axis=-1)).as_matrix()
        # Body angular velocity of the ZYX Euler sequence.
        omega_b = np.stack(
            [
                dphi - dpsi * np.sin(theta),
                dtheta * np.cos(phi) + dpsi * np.cos(theta) * np.sin(phi),
                dpsi * np.cos(theta) * np.cos(phi) - dtheta * np.sin(phi),
            ],
            axis=-1,
        )
        p_w, _, a_w = self.position(t)
        return TrajectorySample(R_wb @ self.R_bc, p_w, omega_b @ self.R_bc, a_w)

    def R_wm(self, t_s: np.ndarray) -> np.ndarray:
        """(N, 3, 3) Manhattan frame to world: the bus attitude in a vehicle, else a constant."""
        t = np.atleast_1d(np.asarray(t_s, float))
        if self.manhattan_is_body:
            return self.R_wb(t)
        return np.broadcast_to(self.R_wm_fixed, (t.size, 3, 3)).copy()

    def R_cm(self, t_s: np.ndarray) -> np.ndarray:
        """(N, 3, 3) Manhattan frame to camera, `R_wc^T R_wm` (what a visual solver measures, up to
        the 24 Manhattan symmetries)."""
        R_wc = self.sample(t_s).R_wc
        return np.swapaxes(R_wc, -1, -2) @ self.R_wm(t_s)


def _signal_position(x: Signal, y: Signal, z: Signal) -> PositionFn:
    def position(t: np.ndarray):
        parts = [s(t) for s in (x, y, z)]
        return tuple(np.stack([p[k] for p in parts], axis=-1) for k in range(3))

    return position


def _vehicle_position(speed: Signal, yaw: Signal, height_m: float, t_end_s: float) -> PositionFn:
    """Planar vehicle: p' = v (cos yaw, sin yaw, 0); exact velocity and acceleration, position by
    Simpson integration on a 1 ms grid and a cubic Hermite spline with exact velocities."""
    t_grid = np.arange(-2.0, t_end_s + 2.0 + 1e-9, 0.001)

    def vel_acc(t):
        v, dv, _ = speed(t)
        psi, dpsi, _ = yaw(t)
        c, s = np.cos(psi), np.sin(psi)
        zeros = np.zeros_like(v)
        vel = np.stack([v * c, v * s, zeros], axis=-1)
        acc = np.stack([dv * c - v * dpsi * s, dv * s + v * dpsi * c, zeros], axis=-1)
        return vel, acc

    vel_grid, _ = vel_acc(t_grid)
    vel_mid, _ = vel_acc(t_grid[:-1] + 0.0005)
    step = (vel_grid[:-1] + 4 * vel_mid + vel_grid[1:]) * (0.001 / 6.0)  # Simpson per interval
    pos_grid = np.concatenate([np.zeros((1, 3)), np.cumsum(step, axis=0)])
    pos_grid -= pos_grid[np.searchsorted(t_grid, 0.0)]  # start at the origin at t = 0
    pos_grid[:, 2] = height_m
    spline = CubicHermiteSpline(t_grid, pos_grid, vel_grid, axis=0)

    def position(t: np.ndarray):
        if np.any(t < t_grid[0]) or np.any(t > t_grid[-1]):
            raise InputError(
                f"vehicle trajectory asked for t outside [{t_grid[0]:.1f}, {t_grid[-1]:.1f}] s"
            )
        vel, acc = vel_acc(t)
        return spline(t), vel, acc

    return position


# --------------------------------------------------------------------------------------------
# Scenario builders
# --------------------------------------------------------------------------------------------


def _handheld(name: str, duration_s: float, rng: np.random.Generator, **kw) -> Trajectory:
    yaw0 = float(rng.uniform(-np.pi, np.pi))
    if name == "static":
        pitch0 = float(np.radians(rng.uniform(-15, 15)))
        roll0 = float(np.radians(rng.uniform(-10, 10)))
        pos = _signal_position(const_signal(0.0), const_signal(0.0), const_signal(EYE_HEIGHT_M))
        params = dict(yaw0_rad=yaw0, pitch0_rad=pitch0, roll0_rad=roll0)
        return Trajectory(name, duration_s, const_signal(yaw0), const_signal(pitch0), const_signal(roll0), pos,
                          params=params)
    if name in ("pan", "tilt", "roll"):
        amp = np.radians(float(kw.get("amplitude_deg", {"pan": 60, "tilt": 30, "roll": 40}[name])))
        period = float(kw.get("period_s", rng.uniform(4.0, 8.0)))
        sweep = Signal(sines=((float(amp), 2 * np.pi / period, float(rng.uniform(0, 2 * np.pi))),))
        jitter = lambda: Signal(sines=random_sines(rng, 2, np.radians(1.5), 0.1, 0.5))  # noqa: E731
        yaw = Signal(poly=(yaw0,), sines=sweep.sines if name == "pan" else jitter().sines)
        pitch = sweep if name == "tilt" else jitter()
        roll = sweep if name == "roll" else jitter()
        pos = _signal_position(*(Signal(poly=(c,), sines=random_sines(rng, 2, 0.02, 0.2, 1.0))
                                 for c in (0.0, 0.0, EYE_HEIGHT_M)))
        params = dict(amplitude_rad=float(amp), period_s=period, yaw0_rad=yaw0)
        return Trajectory(name, duration_s, yaw, pitch, roll, pos, params=params)
    if name == "shake":
        max_rate = float(kw.get("max_rate_rad_s", 5.0))
        # Amplitude per axis so that sum_j A_j w_j stays near max_rate (about 3 rad/s rms).
        sines = []
        for _ in range(3):
            s = random_sines(rng, 3, 1.0, 2.0, 6.0)
            scale = max_rate / sum(a * w for a, w, _ in s)
            sines.append(tuple((a * scale, w, p) for a, w, p in s))
        yaw = Signal(poly=(yaw0,), sines=sines[0] + random_sines(rng, 1, 0.3, 0.05, 0.1))
        pitch = Signal(sines=sines[1])
        roll = Signal(sines=sines[2])
        pos = _signal_position(*(Signal(poly=(c,), sines=random_sines(rng, 3, 0.01, 2.0, 6.0))
                                 for c in (0.0, 0.0, EYE_HEIGHT_M)))
        return Trajectory(name, duration_s, yaw, pitch, roll, pos,
                          params=dict(max_rate_rad_s=max_rate, yaw0_rad=yaw0))
    if name == "walk":
        radius = float(kw.get("radius_m", 1.5))
        speed = float(kw.get("speed_m_s", 0.8))
        w = speed / radius
        ph = float(rng.uniform(0, 2 * np.pi))
        step_hz = float(rng.uniform(1.6, 2.0))
        x = Signal(sines=((radius, w, ph + np.pi / 2),))
        y = Signal(sines=((radius, w, ph),))
        z = Signal(poly=(EYE_HEIGHT_M,), sines=((0.02, 2 * np.pi * step_hz, 0.0),))
        # Facing roughly along the direction of travel, plus looking around.
        yaw = Signal(poly=(ph + np.pi, w), sines=random_sines(rng, 3, np.radians(35), 0.05, 0.3))
        pitch = Signal(poly=(float(np.radians(rng.uniform(-5, 10))),),
                       sines=random_sines(rng, 3, np.radians(12), 0.05, 0.4)
                       + ((np.radians(0.8), 2 * np.pi * step_hz, 0.3),))
        roll = Signal(sines=random_sines(rng, 3, np.radians(6), 0.05, 0.4)
                      + ((np.radians(1.0), np.pi * step_hz, 0.0),))
        pos = _signal_position(x, y, z)
        return Trajectory(name, duration_s, yaw, pitch, roll, pos,
                          params=dict(radius_m=radius, speed_m_s=speed, step_hz=step_hz))
    if name == "forward_walk":
        speed = float(kw.get("speed_m_s", 1.2))
        start_x = float(kw.get("start_x_m", 0.0))
        step_hz = float(rng.uniform(1.6, 2.0))
        x = Signal(poly=(start_x, speed), sines=((0.01, 2 * np.pi * step_hz, 0.0),))
        y = Signal(sines=random_sines(rng, 2, 0.2, 0.02, 0.1)
                   + ((0.03, np.pi * step_hz, 0.0),))
        z = Signal(poly=(EYE_HEIGHT_M,), sines=((0.02, 2 * np.pi * step_hz, 0.0),))
        yaw = Signal(sines=random_sines(rng, 3, np.radians(30), 0.05, 0.3))
        pitch = Signal(sines=random_sines(rng, 3, np.radians(10), 0.05, 0.4))
        roll = Signal(sines=random_sines(rng, 3, np.radians(5), 0.05, 0.4))
        return Trajectory(name, duration_s, yaw, pitch, roll, _signal_position(x, y, z),
                          params=dict(speed_m_s=speed, start_x_m=start_x, step_hz=step_hz))
    raise AssertionError(name)


def _speed_ramp_s(dv_m_s: float, peak_accel_m_s2: float) -> float:
    """Duration of a raised-cosine speed change dv whose peak acceleration is peak_accel."""
    return abs(dv_m_s) * np.pi / (2.0 * peak_accel_m_s2)


def _bus(duration_s: float, rng: np.random.Generator, **kw) -> Trajectory:
    """City bus: accelerate, corner 90 deg, roundabout (270 deg around), brake, repeated to fill
    `duration_s`. Peak longitudinal acceleration 1.5 m/s^2, braking 2.5 m/s^2, centripetal 2-3 m/s^2."""
    cruise = float(kw.get("cruise_m_s", rng.uniform(8.0, 11.0)))
    turn_speed = float(kw.get("turn_speed_m_s", rng.uniform(5.0, 6.5)))
    a_up = float(kw.get("accel_m_s2", 1.5))
    a_brake = float(kw.get("brake_m_s2", 2.5))
    a_c = float(kw.get("centripetal_m_s2", rng.uniform(2.2, 2.8)))
    speed_ramps: list[tuple[float, float, float, int]] = []
    rate_ramps: list[tuple[float, float, float, int]] = []  # yaw RATE steps, integrated: order 1
    yaw_steps: list[tuple[float, float, float, int]] = []  # raised-cosine yaw steps: order 0
    events: list[dict] = []
    t = 1.0
    v = 0.0

    def change_speed(v_to: float, peak: float, pause_s: float = 2.0):
        nonlocal t, v
        dur = _speed_ramp_s(v_to - v, peak)
        speed_ramps.append((v_to - v, t, dur, 0))
        events.append(dict(kind="speed", t0_s=float(t), duration_s=float(dur), from_m_s=float(v),
                           to_m_s=float(v_to)))
        t += dur + pause_s
        v = v_to

    def turn(angle_rad: float, hold_rate: bool, pause_s: float = 1.5):
        """Yaw change at constant speed v; peak (or held) yaw rate gives centripetal a_c."""
        nonlocal t
        rate = np.sign(angle_rad) * a_c / v
        ramp_s = 1.5
        if hold_rate:  # ramp rate up, hold, ramp down: angle = rate * (hold + ramp)
            hold = abs(angle_rad / rate) - ramp_s
            rate_ramps.append((rate, t, ramp_s, 1))
            rate_ramps.append((-rate, t + ramp_s + hold, ramp_s, 1))
            dur = 2 * ramp_s + hold
        else:  # raised-cosine yaw step: peak rate = angle * pi / (2 T)
            dur = abs(angle_rad) * np.pi / (2.0 * abs(rate))
            yaw_steps.append((angle_rad, t, dur, 0))
        events.append(dict(kind="turn", t0_s=float(t), duration_s=float(dur),
                           angle_rad=float(angle_rad), speed_m_s=float(v)))
        t += dur + pause_s

    while t < duration_s:
        change_speed(cruise, a_up * 0.999)
        change_speed(turn_speed, a_brake * 0.999)
        turn(np.pi / 2 * rng.choice([-1, 1]), hold_rate=False)  # 90 degree corner
        change_speed(cruise, a_up * 0.999, pause_s=3.0)
        change_speed(turn_speed, a_brake * 0.999)
        turn(np.radians(-40), hold_rate=False, pause_s=0.0)  # roundabout: veer right to enter,
        turn(np.radians(260), hold_rate=True, pause_s=0.0)  # go around counter-clockwise,
        turn(np.radians(-40), hold_rate=False)  # veer right to leave
        change_speed(0.0, a_brake * 0.999, pause_s=3.0)  # stop
    yaw0 = float(rng.uniform(-np.pi, np.pi))
    speed = Signal(ramps=tuple(speed_ramps))
    yaw = Signal(poly=(yaw0,), ramps=tuple(yaw_steps) + tuple(rate_ramps))
    sway_rad = np.radians(float(kw.get("sway_deg", 1.2)))
    pitch = Signal(sines=random_sines(rng, 3, sway_rad, 0.3, 1.5))
    roll = Signal(sines=random_sines(rng, 3, sway_rad, 0.3, 1.5))
    height = float(kw.get("camera_height_m", 1.6))
    # Camera mount in the bus: looking mostly forward, yawed and pitched down a little.
    mount_yaw = float(np.radians(rng.uniform(-30, 30)))
    mount_pitch = float(np.radians(rng.uniform(0, 15)))
    R_bc = Rotation.from_euler("ZY", [mount_yaw, mount_pitch]).as_matrix() @ R_BC_FORWARD
    params = dict(cruise_m_s=cruise, turn_speed_m_s=turn_speed, accel_m_s2=a_up,
                  brake_m_s2=a_brake, centripetal_m_s2=a_c, sway_rad=float(sway_rad),
                  camera_height_m=height, yaw0_rad=yaw0, mount_yaw_rad=mount_yaw,
                  mount_pitch_rad=mount_pitch, events=events)
    return Trajectory("bus", duration_s, yaw, pitch, roll,
                      _vehicle_position(speed, yaw, height, max(t, duration_s)),
                      R_bc=R_bc, manhattan_is_body=True, params=params)


TRAJECTORY_NAMES = ("walk", "forward_walk", "pan", "tilt", "roll", "shake", "static", "bus")


def make_trajectory(name: str, duration_s: float, seed: int = 0, **params) -> Trajectory:
    """Build the named trajectory over [0, duration_s] seconds from `seed`.

    `params` override scenario numbers (e.g. `amplitude_deg`, `period_s` for sweeps, `radius_m`,
    `speed_m_s` for walks, `max_rate_rad_s` for shake, `cruise_m_s`, `centripetal_m_s2`,
    `sway_deg` for the bus). See the module docstring for conventions.
    """
    if name not in TRAJECTORY_NAMES:
        raise InputError(f"unknown trajectory {name!r}; valid: {', '.join(TRAJECTORY_NAMES)}")
    if not np.isfinite(duration_s) or duration_s <= 0:
        raise InputError(f"trajectory duration_s must be > 0, got {duration_s}")
    rng = np.random.default_rng(seed)
    if name == "bus":
        traj = _bus(float(duration_s), rng, **params)
    else:
        traj = _handheld(name, float(duration_s), rng, **params)
    traj.params.update(name=name, seed=int(seed), duration_s=float(duration_s))
    return traj
