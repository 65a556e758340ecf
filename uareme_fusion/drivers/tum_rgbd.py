"""Moved to `uareme_fusion.formats.tum`; this name stays for scripts that import it from here."""

from ..formats.tum import *  # noqa: F401,F403
from ..formats.tum import (  # noqa: F401
    associate,
    load_tum_rgbd,
    read_associations,
    read_tum_list,
    read_tum_trajectory,
)
