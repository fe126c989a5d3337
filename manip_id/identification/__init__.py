"""Identification: robot + data -> base parameters with their uncertainty, streamed.

Every entry point builds one :class:`Problem` (the accumulated information of a data
set) and calls one :func:`solve`, for N samples ``(q, dq, ddq, tau)``::

    base parameters     theta_b = theta_1 + K theta_2        (structural rank analysis)
    regressor chunks    Y_b = Y(q, dq, ddq)[..., independent]    (N, nv, r), chunk by chunk
    accumulate          A_j, b_j, zz_j per joint                (memory O(nv r^2))
    rank check          what these data excite (RankDeficiencyError otherwise)
    solve               OLS / WLS from the sums, or one online pass (RLS / gradient)
    validate            relative torque error on other data, from sums or one more pass

Nothing holds the stacked regressor: memory is O(chunk nv p + nv r^2) whatever N.
The relative torque error is ``||tau - tau_hat|| / ||tau||`` over all samples and
joints, also per joint; the training one comes from the sums
(``RSS_j = zz_j - 2 b_j.theta + theta.A_j.theta``), so its floor is about 1e-8.

Members: :mod:`~.options` (one frozen dataclass per concern), :mod:`~.problem` (sums,
counts, records; the accumulation), :mod:`~.solve`, :mod:`~.result` and
:mod:`~.document` (the one schema and its text), :mod:`~.arrays` (in-memory entry
points), :mod:`~.reading`, :mod:`~.file_sums`, :mod:`~.files` (log files),
:mod:`~.tasks` (the tasks of a distributed run); :mod:`~.forward`, :mod:`~.rollout`
and :mod:`~.refine` (the model integrated forward from the measured torques: rollout
validation and output-error refinement).
"""

from __future__ import annotations

from .arrays import accumulate_parts, identify, identify_chunks, identify_dataset
from .document import (
    CONDITION_LIMIT,
    CONVERGENCE_LIMIT,
    NOT_DETERMINED,
    POORLY_IDENTIFIED,
    parameter_flags,
    read_result_json,
    result_text,
    result_to_dict,
    result_warnings,
    structural_directions,
    summary_rows,
    verdict_text,
)
from .file_sums import FileAccumulation, accumulate_file, accumulate_files, merge_accumulations
from .files import identify_datasets
from .options import (
    LEAST_SQUARES,
    METHODS,
    ConsistentOptions,
    ModelOptions,
    OnlineOptions,
    PreprocessOptions,
    RankOptions,
    RunOptions,
    UncertaintyOptions,
)
from .problem import FileRecord, FileSums, Problem, accumulate_blocks, row_supports
from .reading import FileScan, iter_processed, processed_count, scan_file, split_file
from .refine import RefineOptions, refine
from .result import IdentificationResult, RelativeError, load_result, result_from_dict
from .rollout import RolloutOptions, RolloutReport, read_logs, rollout_validation
from .solve import solve, validation_errors
from .tasks import PartitionOptions, distributed_problem

__all__ = [
    "CONDITION_LIMIT",
    "CONVERGENCE_LIMIT",
    "LEAST_SQUARES",
    "METHODS",
    "NOT_DETERMINED",
    "POORLY_IDENTIFIED",
    "ConsistentOptions",
    "FileAccumulation",
    "FileRecord",
    "FileScan",
    "FileSums",
    "IdentificationResult",
    "ModelOptions",
    "OnlineOptions",
    "PartitionOptions",
    "PreprocessOptions",
    "Problem",
    "RankOptions",
    "RefineOptions",
    "RelativeError",
    "RolloutOptions",
    "RolloutReport",
    "RunOptions",
    "UncertaintyOptions",
    "accumulate_blocks",
    "accumulate_file",
    "accumulate_files",
    "accumulate_parts",
    "distributed_problem",
    "identify",
    "identify_chunks",
    "identify_dataset",
    "identify_datasets",
    "iter_processed",
    "load_result",
    "merge_accumulations",
    "parameter_flags",
    "processed_count",
    "read_logs",
    "read_result_json",
    "refine",
    "result_from_dict",
    "result_text",
    "verdict_text",
    "result_to_dict",
    "result_warnings",
    "rollout_validation",
    "row_supports",
    "scan_file",
    "solve",
    "split_file",
    "structural_directions",
    "summary_rows",
    "validation_errors",
]
