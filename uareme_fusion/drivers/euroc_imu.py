"""Moved to `uareme_fusion.formats.euroc`; this name stays for scripts that import it from here."""

from ..formats.euroc import EurocImu, read_euroc_imu  # noqa: F401
