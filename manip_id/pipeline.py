"""Deprecated: the real-log pipeline moved to :mod:`manip_id.identification`.

Kept for one release because the README showed ``from manip_id.pipeline import ...``;
import these names from :mod:`manip_id.identification` instead.
"""

from __future__ import annotations

from .identification import (
    FileAccumulation,
    FileScan,
    PreprocessOptions,
    accumulate_file,
    accumulate_files,
    iter_processed,
    merge_accumulations,
    processed_count,
    scan_file,
    split_file,
)

__all__ = [
    "FileAccumulation",
    "FileScan",
    "PreprocessOptions",
    "accumulate_file",
    "accumulate_files",
    "iter_processed",
    "merge_accumulations",
    "processed_count",
    "scan_file",
    "split_file",
]
