"""Fleet scale: identification over many logs, accumulated on Dask and solved on the client.

Least squares over a fleet of logs is a map-reduce, because the information
sums of disjoint data add (:class:`~manip_id.estimators.InformationAccumulator`
is a monoid). For files ``f`` cut into blocks ``b`` (each one task), per joint ``j``::

    A_j  = sum_f sum_b  Y_fbj^T Y_fbj        (r, r)    on the workers
    b_j  = sum_f sum_b  Y_fbj^T tau_fbj      (r,)
    zz_j = sum_f sum_b  tau_fbj^T tau_fbj
    theta_b = solve(sum_j A_j, sum_j b_j)              on the client

Each task is the real-log pipeline's unit of work
(:func:`manip_id.identification.accumulate_file`, the tasks of
:mod:`manip_id.identification.tasks`): it reads its file in chunks,
checks it against the robot, preprocesses it in overlapping blocks when the file
lacks ``ddq`` or filtering is asked for, and accumulates the base-regressor
rows. A block of a long file (``block`` samples of the preprocessed stream) is
a task of its own that accumulates only its rows of that same stream, so the
partition changes the sums only by round-off. The parts are added in a tree
(``split_every`` at a time: blocks into files, files into the fleet), always in
the same grouping. The client receives ``nv`` matrices of ``r x r`` (and one
set per file with ``per_file``), never samples.

Weighted least squares needs no second pass: the per-joint residual sums at an
estimate are linear in the sums, ``RSS_j(theta) = sum_tasks (zz_j - 2 b_j.theta +
theta.A_j.theta)``, i.e. the sum of the per-task residual sums, so the variances
``sigma_j^2 = RSS_j / (n - r / nv)`` and the re-weighted solve come from the
reduced sums alone, exactly as in the local run. Validation files are tasks too;
their errors for the estimate follow from their sums in the same way.

Back-ends: no scheduler runs the same tasks and the same tree in this process
(and imports nothing of Dask); ``"local"`` / ``"local:N"`` starts a
``LocalCluster`` of N single-threaded worker processes on 127.0.0.1 (stopped at
the end); ``"tcp://HOST:PORT"`` connects to a running scheduler; a path to a
scheduler JSON file (``dask scheduler --scheduler-file``) too; a
``distributed.Client`` is used as it is. A worker that dies mid-run has its
tasks recomputed by Dask elsewhere; a bad file fails the run with a
:class:`~manip_id.errors.DataError` naming the file, and no result.
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field, replace
from typing import Any

from ..datasets import FileSpec
from ..errors import InputError, RankDeficiencyError
from ..execution import (
    DEFAULT_LOCAL_WORKERS,
    SPLIT_EVERY,
    WORKER_ENV,
    header_samples,
    parse_scheduler,
    portable_robot,
)
from ..identifiability import BaseParameters
from ..robot.compiled_regressor import planned_samples
from ..robot.model import Robot
from . import (
    LEAST_SQUARES,
    ConsistentOptions,
    FileRecord,
    IdentificationResult,
    ModelOptions,
    PartitionOptions,
    PreprocessOptions,
    Problem,
    RankOptions,
    RunOptions,
    UncertaintyOptions,
    distributed_problem,
    solve,
)
from .options import options_from
from .problem import resolve_base
from .tasks import FilePart, PartSums, file_length, part_sums
from .temperature import note_reference, reference_from_files

#: Methods that accumulate (the online laws need the samples in order).
FLEET_METHODS: tuple[str, ...] = LEAST_SQUARES
#: The record of one file (its former name here).
FileInfo = FileRecord


@dataclass(frozen=True)
class FileEstimate:
    """One file's own identification, from its own sums (fleet monitoring).

    Attributes
    ----------
    path
        the file (spec label)
    n_samples
        samples accumulated from it (after preprocessing)
    n_tasks
        tasks (blocks) it was cut into
    result
        its identification (same base parameters and method as the pooled
        one), or None when the file alone cannot be solved
    error
        why it cannot (e.g. it does not excite every base parameter), else None
    summary
        samples, rows left out, preprocessing and data quality (:meth:`FileInfo.summary`)
    """

    path: str
    n_samples: int
    n_tasks: int
    result: IdentificationResult | None
    error: str | None = None
    summary: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready: estimate, std and errors by base parameter name (None if unsolved),
        with the file's summary (rows left out, preprocessing, data quality)."""
        out: dict[str, Any] = {
            **self.summary,
            "file": self.path,
            "n_samples": int(self.n_samples),
            "n_tasks": int(self.n_tasks),
            "error": self.error,
        }
        res = self.result
        if res is None:
            return out
        d = res.to_dict()
        out.update(
            parameters=[
                {k: p[k] for k in ("name", "value", "std", "std_percent")}
                for p in d["base_parameters"]
            ],
            sigma2=d["sigma2"],
            noise_variance=d["noise_variance"],
            condition_number=d["condition_number"],
            relative_error={
                "train": d["relative_error"]["train"],
                "train_per_joint": d["relative_error"]["train_per_joint"],
            },
        )
        return out


def preprocess_options(options) -> PreprocessOptions:
    """``options`` as :class:`~manip_id.identification.PreprocessOptions` (None: defaults;
    a mapping of its fields)."""
    if options is None:
        return PreprocessOptions()
    if isinstance(options, PreprocessOptions):
        return options
    if isinstance(options, Mapping):
        try:
            return PreprocessOptions(**options)
        except TypeError as exc:
            raise InputError(f"unknown preprocessing option in {sorted(options)}: {exc}") from exc
    raise InputError(
        f"options must be PreprocessOptions or a mapping of its fields, got {type(options)}"
    )


def identify_files(
    robot: Robot,
    paths: Sequence[str | os.PathLike | FileSpec],
    *,
    method: str = "wls",
    validation: Sequence[str | os.PathLike | FileSpec] | None = None,
    base: BaseParameters | None = None,
    window=None,
    options: PreprocessOptions | Mapping | None = None,
    consistent: ConsistentOptions | bool | dict | None = None,
    rank: RankOptions | dict | None = None,
    model: ModelOptions | str | dict | None = None,
    run: RunOptions | dict | None = None,
    partition: PartitionOptions | dict | None = None,
    uncertainty: UncertaintyOptions | str | dict | None = None,
) -> IdentificationResult:
    """Identify the base parameters of ``robot`` from many files, each file a task.

    Parameters
    ----------
    robot : Robot
        The robot.
    paths : sequence
        Data files, as file specs (``PATH``, ``PATH@START:STOP``, ``PATH@#A:#B`` or
        :class:`~manip_id.datasets.FileSpec`), any format the real-log pipeline reads;
        each preprocessed on its own.
    method : str
        ``"wls"`` (default) or ``"ols"``.
    validation : sequence or None
        Files for the validation error (each one task).
    base : BaseParameters or None
        Base parametrization; default the structural one.
    window : str or None
        A window for every file that has none.
    options : PreprocessOptions or mapping or None
        Preprocessing of every file; default: files without ``ddq`` are preprocessed
        with the default settings, the others used as they are.
    consistent, rank : as :func:`~manip_id.identification.identify` (solved on the
        client from the reduced sums).
    model : ModelOptions or str or None
        "dynamic" (``tau = Y(q, dq, ddq) theta``), or "energy" / "momentum"
        (:mod:`manip_id.models`, no accelerations; the torques are integrated
        unfiltered); energy blocks hold whole windows, momentum runs one task per file.
        The validation error is the torque error of the dynamic model.
    run : RunOptions or None
        ``scheduler``: None (this process, no Dask), ``"local[:N]"``,
        ``"tcp://HOST:PORT"``, a scheduler JSON file, or a ``distributed.Client``;
        ``chunk``: samples per regressor chunk.
    partition : PartitionOptions or None
        ``block`` (samples per task), ``split_every`` (parts per reduction task),
        ``per_file`` (also each file's own estimate, ``result.per_file``).
    uncertainty : UncertaintyOptions or str or None
        The covariance: "auto" (default), "white" or "hac", as
        :func:`~manip_id.identification.identify`; the per-block sums travel with each
        task's sums (a file's end is a block boundary; its blocks merge exactly).

    Returns
    -------
    IdentificationResult
        Equal to the local run's (:func:`~manip_id.identification.identify_datasets`)
        to round-off whatever the workers or the partition. ``files`` is ``{"train":
        [FileRecord], "validation": [FileRecord] or None}``, ``per_file`` the files' own
        estimates (:class:`FileEstimate`) when asked. Its timings hold the task times
        summed over the tasks and ``distributed`` (the wall time of the map-reduce) [s].

    Raises
    ------
    DataError
        A file that cannot be read or used, named (no partial result).
    RankDeficiencyError
        The pooled data do not excite every base parameter.
    """
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    if method not in FLEET_METHODS:
        raise InputError(
            f"fleet identification accumulates {list(FLEET_METHODS)}, got {method!r} "
            "(the online laws need the samples in order)"
        )
    copts = ConsistentOptions.from_value(consistent)
    minimum_norm = RankOptions.from_value(rank).minimum_norm
    mopts = ModelOptions.from_value(model)
    part = options_from(PartitionOptions, partition, "partition")
    pre = preprocess_options(options)
    robot, _, made = reference_from_files(robot, paths, validation, pre, window)  # its T0
    for scan in made:  # (the tasks scan their files themselves)
        scan.discard()
    base = resolve_base(robot, base, timings)
    uopts = UncertaintyOptions.from_value(uncertainty)
    with _announced([*paths, *(validation or [])]):
        sums = distributed_problem(
            robot,
            paths,
            validation,
            base,
            pre,
            window=window,
            timings=timings,
            run=RunOptions.from_value(run),
            model=mopts,
            partition=part,
            uncertainty=uopts,
        )
    sums.problem.t_start = t_start
    result = solve(
        sums.problem, method, consistent=copts, minimum_norm=minimum_norm, uncertainty=uopts
    )
    note_reference(result, robot)  # the temperature law's T0, if any
    if sums.per_file is None:
        return result
    records = sums.problem.files["train"] if sums.problem.files else []
    estimates = [
        _file_estimate(robot, info, fs, base, method, mopts.name, uopts)
        for info, fs in zip(records, sums.per_file, strict=True)
    ]
    result = replace(result, per_file=estimates)
    result.timings["total"] = time.perf_counter() - t_start
    return result


def _announced(files: list):
    """The run announced with the rows the files' headers declare
    (:func:`~manip_id.execution.header_samples`), so that in ``auto`` regressor mode every
    process of it takes the same regressor path; no announcement when a count is unknown."""
    n = header_samples(files)
    return planned_samples(n) if n else nullcontext()


def _file_estimate(
    robot, info: FileRecord, fs: PartSums, base, method, model="dynamic", uncertainty=None
):
    """One file's own estimate from its own sums (None with the reason when unsolvable)."""
    summary = info.summary(robot.dof_names)
    n = info.n_samples
    problem = Problem(robot, base, fs.acc, n, dict(fs.timings), model=model)
    try:
        res = solve(problem, method, uncertainty=uncertainty)
        return FileEstimate(info.label, n, info.n_tasks, res, summary=summary)
    except (RankDeficiencyError, InputError) as exc:
        return FileEstimate(info.label, n, info.n_tasks, None, str(exc), summary=summary)


__all__ = [
    "DEFAULT_LOCAL_WORKERS",
    "FLEET_METHODS",
    "SPLIT_EVERY",
    "WORKER_ENV",
    "FileEstimate",
    "FileInfo",
    "FilePart",
    "PartSums",
    "PartitionOptions",
    "file_length",
    "identify_files",
    "parse_scheduler",
    "part_sums",
    "portable_robot",
    "preprocess_options",
]
