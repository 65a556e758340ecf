"""No silent drift: visual rotations that turn wrong mid-way raise `VISUAL_IGNORED` and re-initialise
the filter within about a second; while every flag is clear no estimate is far from the camera."""

from __future__ import annotations

import numpy as np
import pytest

from uareme_fusion.backends.mekf import Mekf, MekfConfig
from uareme_fusion.rotations import WORLD_UP, angle_between, exp_so3
from uareme_fusion.types import Status

from mekf_oracle import OracleMekf  # tests/backends/mekf_oracle: pytest puts tests/backends on sys.path

from test_mekf import FPS, RATE_HZ, R_CM_UPRIGHT, visual_measurement

OMEGA = np.array([0.05, -0.1, 0.2])  # rad/s, camera frame
T_WRONG_S = 4.0
OFFSET = exp_so3([np.radians(35.0), 0.0, np.radians(10.0)])  # the visual rotations' constant error after T_WRONG_S


def run(seed, with_imu, offset=OFFSET, duration_s=9.0, std_rad=0.01, make=Mekf):
    """A constant-rate motion seen by noisy visual rotations (random labelling), wrong by `offset`
    (R_cm -> R_cm offset: the scene's axes misread, as a constant rotation of the Manhattan frame)
    from `T_WRONG_S` on; returns
    (frame times, estimates, the visual R_cm given, true R_wc)."""
    rng = np.random.default_rng(seed)
    filt = make(MekfConfig(mode="visual_imu" if with_imu else "visual_only"))
    cov = std_rad**2 * np.diag([1.0, 0.5, 2.0])
    t_imu = np.arange(0.0, duration_s, 1.0 / RATE_HZ)
    R_imu = R_CM_UPRIGHT.T @ exp_so3(np.outer(t_imu, OMEGA))
    gyro = OMEGA + rng.standard_normal((t_imu.size, 3)) * 2e-4 * np.sqrt(RATE_HZ)
    accel = np.einsum("nji,j->ni", R_imu, 9.81 * WORLD_UP)
    step = int(RATE_HZ / FPS)
    times, ests, seen, truth = [], [], [], []
    for k in range(step, t_imu.size, step):
        if with_imu:
            filt.process_imu(t_imu[k - step:k], gyro[k - step:k], accel[k - step:k])
        t_f, R_wc = t_imu[k - 1], R_imu[k - 1]
        R_cm = R_wc.T if t_f < T_WRONG_S else R_wc.T @ offset
        vis = visual_measurement(R_cm, cov, rng)
        times.append(t_f)
        ests.append(filt.process_frame(t_f, vis))
        seen.append(R_cm)
        truth.append(R_wc)
    return np.array(times), ests, np.array(seen), np.array(truth)


def cm_error_deg(ests, seen):
    """Angle between each estimate's R_cm and the camera's (noise-free) R_cm, deg."""
    return np.array([np.degrees(angle_between(e.R_wc.T @ e.R_wm, R)) for e, R in zip(ests, seen)])


@pytest.mark.parametrize("with_imu", [False, True])
def test_visual_rotations_turning_wrong_raise_the_flag_and_reinitialise(with_imu):
    t, ests, seen, _ = run(3, with_imu)
    ignored = np.array([Status.VISUAL_IGNORED in e.status for e in ests])
    reinit = np.array([Status.REINITIALISED in e.status for e in ests])
    assert not ignored[t < T_WRONG_S].any() and not reinit[t < T_WRONG_S].any()
    after = t >= T_WRONG_S
    assert ignored[after][0] or Status.VISUAL_REJECTED in ests[int(np.argmax(after))].status
    assert reinit.any() and T_WRONG_S <= t[reinit][0] <= T_WRONG_S + 1.3
    err = cm_error_deg(ests, seen)
    settled = t > t[reinit][0] + 1.0
    assert err[settled].max() < 4.0  # the estimates follow the new rotations
    assert not ignored[settled].any()
    clear = np.array([e.status == Status.OK for e in ests])
    clear[:5] = False  # the first frames initialise
    assert clear.sum() > 0.8 * len(ests) and err[clear].max() < 4.0  # never far while every flag is clear


@pytest.mark.parametrize("with_imu", [True, False])
def test_the_decision_is_the_oracles(with_imu):
    _, a, _, _ = run(5, with_imu, make=Mekf)
    _, b, _, _ = run(5, with_imu, make=OracleMekf)
    assert [e.status for e in a] == [e.status for e in b]
    assert max(np.degrees(angle_between(x.R_wc, y.R_wc)) for x, y in zip(a, b)) < 1e-6


@pytest.mark.parametrize("with_imu", [False, True])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_an_ordinary_noisy_stream_never_raises_the_flag(with_imu, seed):
    _, ests, seen, _ = run(seed, with_imu, offset=np.eye(3), duration_s=20.0)
    assert not any(Status.VISUAL_IGNORED in e.status or Status.REINITIALISED in e.status for e in ests)
    assert cm_error_deg(ests, seen)[5:].max() < 3.0
