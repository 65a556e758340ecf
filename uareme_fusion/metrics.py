"""Kept for imports of `uareme_fusion.metrics`: the metrics live in `uareme_fusion.evaluation.metrics`."""

from .evaluation.metrics import (GAUGE_VARIANCE_RAD2, JUMP_DEG, attitude_errors, error_summary,  # noqa: F401
                                 jump_counts, step_errors_deg)
