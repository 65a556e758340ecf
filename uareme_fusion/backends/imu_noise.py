"""Gyro noise settings shared by the EKF (`MekfConfig`) and the smoother (`SmootherConfig`): one
pydantic model both configs extend, so the same setting has the same key, bounds and meaning in
both (and in the YAML presets)."""

from __future__ import annotations

from pydantic import BaseModel, Field


class GyroNoiseConfig(BaseModel):
    """Continuous-time gyro noise model, SI units and radians."""

    gyro_noise_rad_s_sqrt_hz: float = Field(2e-3, ge=1e-9, le=1.0)
    """Gyro white-noise density (angle random walk), rad/s/sqrt(Hz)."""
    gyro_bias_rw_rad_s2_sqrt_hz: float = Field(1e-4, ge=0, le=1.0)
    """Gyro bias random-walk density, rad/s^2/sqrt(Hz)."""
    gyro_bias_initial_std_rad_s: float = Field(0.01, ge=0, le=10.0)
    """Prior standard deviation of each gyro bias component, rad/s."""
