"""The EKF's oracle: the numpy/scipy/filterpy reference filter that the production `Mekf` (its numba
kernels, run as plain Python without numba) is cross-tested against, on committed recordings
(`tests/backends/data/`) and simulated streams. Not part of the package: nothing there imports it.

filterpy does its Kalman algebra (`kf_update`, `kf_predict`, Joseph form); scipy its rotations.
"""

from .filter import Mekf as OracleMekf

__all__ = ["OracleMekf"]
