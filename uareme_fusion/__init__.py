"""uareme-fusion: camera orientation and gravity from video of man-made scenes, fused with an IMU.

Conventions (docs/design.md): camera frame OpenCV (x right, y down, z forward), world z up, `R_ab` maps
b-coordinates to a, perturbations on the right, covariances in rad^2.
"""

from .errors import ConfigError, InputError, UaremeError
from .solver import ManhattanSolver, SolverConfig, solve_manhattan
from .types import Estimate, Frame, ImuBatch, NormalMap, Status, VisualRotation

__version__ = "0.1.0"

__all__ = [
    "ConfigError",
    "Estimate",
    "Frame",
    "ImuBatch",
    "InputError",
    "ManhattanSolver",
    "NormalMap",
    "SolverConfig",
    "Status",
    "UaremeError",
    "VisualRotation",
    "solve_manhattan",
]
