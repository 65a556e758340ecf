"""Backends turn visual rotations (and IMU samples) into a trajectory of estimates."""

from .base import Backend

__all__ = ["Backend"]
