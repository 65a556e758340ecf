"""`Status` flags as plain int bits, as `Mekf` gathers them between two estimates.

A frame's path runs between solver calls, where an `enum.Flag` operation costs microseconds; the
filter ors these ints instead and turns the word into a `Status` once per estimate (`status_of`).
"""

from __future__ import annotations

from ...types import Status

OK = 0
ACCEL_DOWNWEIGHTED = int(Status.ACCEL_DOWNWEIGHTED)
VISUAL_REJECTED = int(Status.VISUAL_REJECTED)
VISUAL_MISSING = int(Status.VISUAL_MISSING)
REINITIALISED = int(Status.REINITIALISED)
IMU_GAP = int(Status.IMU_GAP)
GYRO_SATURATED = int(Status.GYRO_SATURATED)
IMU_DROPPED = int(Status.IMU_DROPPED)
NOT_INITIALISED = int(Status.NOT_INITIALISED)
UPDATE_NONFINITE = int(Status.UPDATE_NONFINITE)
VISUAL_IGNORED = int(Status.VISUAL_IGNORED)

_STATUS: dict[int, Status] = {}


def status_of(bits: int) -> Status:
    """The `Status` of an int word of flag bits (one dict look-up once a word was seen)."""
    status = _STATUS.get(bits)
    if status is None:
        status = _STATUS[bits] = Status(bits)
    return status
