"""The single-frame Manhattan solver (paper Sec. 3.1)."""

from .manhattan import ManhattanSolver, SolverConfig, solve_manhattan
from .moments import NormalMoments, normal_moments

__all__ = ["ManhattanSolver", "SolverConfig", "solve_manhattan", "NormalMoments", "normal_moments"]
