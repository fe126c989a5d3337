"""Deprecated: the result schema moved to :mod:`manip_id.identification` (``result`` and
``document``). Kept for one release because ``from manip_id import load_result`` and
``manip-id show`` read it from here; import from :mod:`manip_id.identification` instead.
"""

from __future__ import annotations

from .identification import (
    CONDITION_LIMIT,
    CONVERGENCE_LIMIT,
    POORLY_IDENTIFIED,
    load_result,
    parameter_flags,
    result_from_dict,
    result_text,
    result_to_dict,
    result_warnings,
    structural_directions,
)

__all__ = [
    "CONDITION_LIMIT",
    "CONVERGENCE_LIMIT",
    "POORLY_IDENTIFIED",
    "load_result",
    "parameter_flags",
    "result_from_dict",
    "result_text",
    "result_to_dict",
    "result_warnings",
    "structural_directions",
]
