"""Measured data: the :class:`Dataset` type, its readers and writers, streamed access.

A dataset is a time series ``t`` [s] (N,), ``q`` (N, nq), ``dq``, ``tau`` and
optionally ``ddq`` (N, nv), validated on construction (:mod:`~.core`). Formats:
NPZ (:mod:`~.npz`), CSV (:mod:`~.csv`), ROS 2 bags of JointState
(:mod:`~.rosbag`), the real Panda log (:mod:`~.panda`). Whole-file access:
:func:`load_dataset`, :func:`save_dataset`. Streamed access for long logs:
a :class:`FileSpec` (path, optional window, the unit of its stamps and the
delay of its torque stream, :mod:`~.spec`, :mod:`~.adjust`) opened with
:func:`open_source` and read with :func:`iter_rows` as packed row blocks
(:mod:`~.layout`, :mod:`~.stream`), with a data-quality summary per file
(:mod:`~.quality`); a slow format's rows parsed once for a run's several passes
(:class:`RowCache`, :mod:`~.replay`).
"""

from .core import Dataset, check_robot, check_values
from .io import MEMORY_BUDGET, load_dataset, save_dataset, write_rows
from .layout import FIELDS, Layout
from .panda import PANDA_JOINTS, load_panda_gaz2019
from .replay import RowCache
from .spec import FileSpec, Window, parse_file_spec
from .stream import FORMATS, MemorySource, RowCounts, iter_rows, open_source

__all__ = [
    "FIELDS",
    "FORMATS",
    "MEMORY_BUDGET",
    "PANDA_JOINTS",
    "Dataset",
    "FileSpec",
    "Layout",
    "MemorySource",
    "RowCache",
    "RowCounts",
    "Window",
    "check_robot",
    "check_values",
    "iter_rows",
    "load_dataset",
    "load_panda_gaz2019",
    "open_source",
    "parse_file_spec",
    "save_dataset",
    "write_rows",
]
