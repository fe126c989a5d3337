"""Several log files -> one problem (here, in forked processes, or as Dask tasks).

Each file (or window) is scanned, preprocessed and accumulated on its own
(:mod:`~manip_id.identification.file_sums`), in this process or in forked processes
(:func:`files_problem`), or each file (each block of one) as a task on the run's back-end,
serial or Dask (:func:`distributed_files_problem`, which can also keep each file's own
sums for its own estimate, :class:`FileEstimate`). The training sums add, the validation
files keep their own sums, and the errors of any estimate follow from them::

    A_j = sum_f A_fj,   b_j = sum_f b_fj,   zz_j = sum_f zz_fj       (per joint j)
"""

from __future__ import annotations

import time
from contextlib import nullcontext
from dataclasses import dataclass, field, replace
from typing import Any

from ..datasets import Layout
from ..errors import InputError, RankDeficiencyError
from ..estimators.consistent.terms import missing_term_warnings
from ..execution import header_samples
from ..identifiability import BaseParameters
from ..robot.compiled_regressor import planned_samples
from ..robot.model import Robot
from .file_sums import accumulate_files, merge_accumulations
from .options import ModelOptions, PreprocessOptions, RunOptions, UncertaintyOptions
from .problem import FileRecord, Problem, check_equations
from .reading import iter_processed
from .result import IdentificationResult
from .solve import solve
from .tasks import PartitionOptions, PartSums, distributed_problem


def files_problem(
    robot: Robot,
    specs: list,
    validation: list | None,
    base: BaseParameters,
    options: PreprocessOptions,
    *,
    window=None,
    run: RunOptions,
    scans: dict | None = None,
    uncertainty: UncertaintyOptions | None = None,
    timings: dict | None = None,
) -> Problem:
    """The problem of log files accumulated in this process or in ``run.workers`` forked ones.

    ``specs``, ``validation``: file specs (texts or :class:`~manip_id.datasets.FileSpec`);
    ``window`` applies to each file without one; ``scans``: FileSpec ->
    :class:`~manip_id.identification.reading.FileScan` of files already scanned. The
    validation files keep their own sums (``validation_per_file``). Without a window the
    problem carries a post-step: an implausible consistent fit asks whether a joint term
    the model lacks would lower the error (the files read once more).
    """
    timings = {} if timings is None else timings
    ind = base.independent
    t0 = time.perf_counter()
    unc = uncertainty or UncertaintyOptions()
    train = accumulate_files(
        robot, specs, options, ind, window=window, run=run, scans=scans, uncertainty=unc
    )
    valid = _validation_sums(robot, validation, options, ind, window, run, scans)
    timings["accumulate_wall"] = time.perf_counter() - t0
    for fa in train + (valid or []):
        for k, v in fa.timings.items():
            timings[k] = timings.get(k, 0.0) + float(v)
    sums = merge_accumulations(train)
    acc = sums.fit
    check_equations(acc.n * robot.nv, base.n_base, f"{acc.n} samples")
    problem = Problem(
        robot,
        base,
        acc,
        acc.n,
        timings,
        validation_files=None if valid is None else [fa.sums() for fa in valid],
        files={
            "train": [fa.record() for fa in train],
            "validation": None if valid is None else [fa.record() for fa in valid],
        },
        chunk=run.chunk,
        still=sums.still,
        raw=sums.raw,
    )
    if window is None:

        def terms(result: IdentificationResult) -> IdentificationResult:
            vblocks = None if validation is None else file_blocks(robot, validation, options, scans)
            blocks = file_blocks(robot, specs, options, scans)
            result.warnings.extend(
                missing_term_warnings(robot, result.standard, blocks, vblocks, ind, run.chunk)
            )
            return result

        problem.post.append(terms)
    return problem


def file_blocks(robot: Robot, files, options, scans):
    """The files' blocks ``(q, dq, ddq, tau[, None, temp])`` as the fit sees them, read
    again (one pass)."""
    for spec in files:
        _, blocks = iter_processed(robot, spec, options, (scans or {}).get(spec))
        for b in blocks:  # packed t | q | dq | tau | ddq [| temp]
            f = Layout.processed(robot.nq, robot.nv, b.shape[1]).unpack(b)
            states = (f["q"], f["dq"], f["ddq"], f["tau"])
            yield states + (None, f["temp"]) if "temp" in f else states


def _validation_sums(robot: Robot, validation, options, ind, window, run: RunOptions, scans):
    """The validation files' sums (errors only: white, no per-block sums), or None."""
    if validation is None:
        return None
    vrun = RunOptions(chunk=run.chunk, workers=run.workers)
    white = UncertaintyOptions(method="white")
    return accumulate_files(
        robot, validation, options, ind, window=window, run=vrun, scans=scans, uncertainty=white
    )


# ------------------------------------------------------------- distributed
@dataclass(frozen=True)
class FileEstimate:
    """One file's own identification, from its own sums (fleet monitoring).

    Attributes
    ----------
    path : str
        The file (spec label).
    n_samples : int
        Samples accumulated from it (after preprocessing).
    n_tasks : int
        Tasks (blocks) it was cut into.
    result : IdentificationResult or None
        Its identification (same base parameters and method as the pooled one), or None
        when the file alone cannot be solved.
    error : str or None
        Why it cannot (e.g. it does not excite every base parameter), else None.
    summary : dict
        Samples, rows left out, preprocessing (:meth:`FileRecord.summary`).
    """

    path: str
    n_samples: int
    n_tasks: int
    result: IdentificationResult | None
    error: str | None = None
    summary: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready: estimate, std and errors by base parameter name (None if unsolved),
        with the file's summary (rows left out, preprocessing)."""
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


def _announced(files: list):
    """The run announced with the rows the files' headers declare
    (:func:`~manip_id.execution.header_samples`), so that in ``auto`` regressor mode every
    process of it takes the same regressor path; no announcement when a count is unknown."""
    n = header_samples(files)
    return planned_samples(n) if n else nullcontext()


def distributed_files_problem(
    robot: Robot,
    specs: list,
    validation: list | None,
    base: BaseParameters,
    options: PreprocessOptions,
    *,
    window=None,
    run: RunOptions,
    model: ModelOptions | None = None,
    partition: PartitionOptions | None = None,
    uncertainty: UncertaintyOptions | None = None,
    timings: dict | None = None,
) -> Problem:
    """The problem of log files, each file (each ``partition.block`` of one) a task on the
    run's back-end (``run.scheduler``: None runs the tasks in this process, else Dask),
    the sums added in a tree (:func:`~manip_id.identification.tasks.distributed_problem`).

    With ``partition.per_file`` the problem carries a post-step that solves each training
    file from its own sums (``result.per_file``: :class:`FileEstimate`, None with the
    reason when a file alone cannot be solved).
    """
    partition = partition or PartitionOptions()
    model = model or ModelOptions()
    with _announced([*specs, *(validation or [])]):
        sums = distributed_problem(
            robot, specs, validation, base, options, window=window, timings=timings, run=run,
            model=model, partition=partition, uncertainty=uncertainty,
        )  # fmt: skip
    problem = sums.problem
    if sums.per_file is not None:
        records = problem.files["train"] if problem.files else []
        per_file = list(zip(records, sums.per_file, strict=True))

        def estimates(result: IdentificationResult) -> IdentificationResult:
            unc = problem.settings.uncertainty
            found = [
                file_estimate(robot, info, fs, base, result.method, model.name, unc)
                for info, fs in per_file
            ]
            return replace(result, per_file=found)

        problem.post.append(estimates)
    return problem


def file_estimate(
    robot: Robot,
    info: FileRecord,
    fs: PartSums,
    base: BaseParameters,
    method: str,
    model: str = "dynamic",
    uncertainty: UncertaintyOptions | None = None,
) -> FileEstimate:
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
    "FileEstimate",
    "distributed_files_problem",
    "file_blocks",
    "file_estimate",
    "files_problem",
]
