"""Identification: robot + data -> base parameters with their uncertainty, streamed.

One door, :func:`identify` = :func:`build_problem` (the accumulated information of a
data set: arrays, a dataset, log files or blocks, :mod:`~.data_sources`) + :func:`solve`,
for N samples ``(q, dq, ddq, tau)``::

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

Members: :mod:`~.front` (the door), :mod:`~.data_sources` (what ``data`` is),
:mod:`~.options` (one frozen dataclass per concern), :mod:`~.problem` (sums, counts,
records; the accumulation), :mod:`~.solve`, :mod:`~.result` and :mod:`~.document` (the
one schema), :mod:`~.document_text` (its text), :mod:`~.run_context` (what a run adds to
it), :mod:`~.arrays` (in-memory data and blocks), :mod:`~.file_run` (the file pipeline:
audit, scans, temperature reference, friction choice), :mod:`~.reading`,
:mod:`~.file_sums`, :mod:`~.files` (log files accumulated, here or as tasks),
:mod:`~.tasks` (the tasks of a distributed run), :mod:`~.nominal_check` (joints the fit
made worse than the nominal model); :mod:`~.forward`, :mod:`~.rollout` and :mod:`~.refine`
(the model integrated forward from the measured torques: rollout validation and
output-error refinement); :mod:`~.closed_loop` (IDIM-IV and DIDIM: closed-loop logs with a
known controller)."""

from __future__ import annotations

from .arrays import accumulate_parts
from .closed_loop import CLOSED_LOOP_METHODS, ClosedLoopOptions, closed_loop_estimate
from .data_sources import data_source
from .document import (
    CONDITION_LIMIT,
    CONVERGENCE_LIMIT,
    NOT_DETERMINED,
    POORLY_IDENTIFIED,
    parameter_flags,
    read_result_json,
    result_to_dict,
    result_warnings,
    structural_directions,
)
from .document_text import result_text, summary_rows, verdict_text
from .file_run import FileOptions
from .file_sums import FileAccumulation, accumulate_file, accumulate_files, merge_accumulations
from .files import FileEstimate
from .front import build_problem, identify
from .options import (
    LEAST_SQUARES,
    METHODS,
    ConsistentOptions,
    ModelOptions,
    OnlineOptions,
    PreprocessOptions,
    RunOptions,
    SolveSettings,
    UncertaintyOptions,
)
from .problem import (
    FileRecord,
    FileSums,
    Problem,
    accumulate_blocks,
    row_supports,
)
from .reading import FileScan, iter_processed, processed_count, scan_file, split_file
from .refine import RefineOptions, refine
from .result import IdentificationResult, RelativeError, load_result, result_from_dict
from .rollout import RolloutOptions, RolloutReport, read_logs, rollout_validation
from .solve import solve, validation_errors
from .tasks import PartitionOptions, distributed_problem

__all__ = [
    "CLOSED_LOOP_METHODS",
    "CONDITION_LIMIT",
    "CONVERGENCE_LIMIT",
    "LEAST_SQUARES",
    "METHODS",
    "NOT_DETERMINED",
    "POORLY_IDENTIFIED",
    "ClosedLoopOptions",
    "ConsistentOptions",
    "FileAccumulation",
    "FileEstimate",
    "FileOptions",
    "FileRecord",
    "FileScan",
    "FileSums",
    "IdentificationResult",
    "ModelOptions",
    "OnlineOptions",
    "PartitionOptions",
    "PreprocessOptions",
    "Problem",
    "RefineOptions",
    "RelativeError",
    "RolloutOptions",
    "RolloutReport",
    "RunOptions",
    "SolveSettings",
    "UncertaintyOptions",
    "accumulate_blocks",
    "accumulate_file",
    "accumulate_files",
    "accumulate_parts",
    "build_problem",
    "closed_loop_estimate",
    "data_source",
    "distributed_problem",
    "identify",
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
