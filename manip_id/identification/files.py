"""Several log files -> one problem -> :func:`~manip_id.identification.solve`.

Each file (or window) is scanned, preprocessed and accumulated on its own
(:mod:`~manip_id.identification.file_sums`), in this process, in forked processes,
or as Dask tasks (:func:`~manip_id.identification.tasks.distributed_problem`); the
training sums add, the validation files keep their own sums, and the errors of any
estimate follow from them.
"""

from __future__ import annotations

import time
from typing import Any

from ..datasets import Layout
from ..estimators.consistent.terms import missing_term_warnings
from ..identifiability import BaseParameters
from ..robot.model import Robot
from .file_sums import accumulate_files, merge_accumulations
from .options import (
    ConsistentOptions,
    PreprocessOptions,
    RankOptions,
    RunOptions,
    UncertaintyOptions,
    check_least_squares,
)
from .problem import Problem, check_equations, resolve_base
from .reading import iter_processed
from .result import IdentificationResult
from .solve import solve
from .tasks import distributed_problem
from .temperature import note_reference, reference_from_files


def identify_datasets(
    robot: Robot,
    files,
    *,
    validation=None,
    options: PreprocessOptions | None = None,
    window=None,
    method: str = "wls",
    base: BaseParameters | None = None,
    consistent: ConsistentOptions | bool | dict | None = None,
    rank: RankOptions | dict | None = None,
    run: RunOptions | dict | None = None,
    scans: dict | None = None,
    uncertainty: UncertaintyOptions | str | dict | None = None,
) -> IdentificationResult:
    """Least squares from several log files, each read in chunks and preprocessed on its own.

    Parameters
    ----------
    robot : Robot
        The robot (its joint terms decide the columns).
    files : sequence
        File specs (:class:`~manip_id.datasets.FileSpec` or their texts ``PATH``,
        ``PATH@START:STOP`` [s from the file's first stamp], ``PATH@#A:#B`` [rows]):
        NPZ, CSV, ROS 2 bags, Panda log folders.
    validation : sequence or None
        File specs of validation data (same options).
    options : PreprocessOptions or None
        Filtering, torque scale, velocity deadband, bad rows; default all defaults.
    window : str or None
        Window applied to every file (training and validation) that has none.
    method : str
        "wls" (default) or "ols"; ``consistent``, ``rank`` as :func:`identify`.
    run : RunOptions or None
        ``workers``: several files in up to that many forked processes (one file: its
        samples in parts); ``scheduler``: each file one Dask task, the sums added there;
        ``progress(done, total)`` [samples of the training files]; ``chunk``.
    scans : dict or None
        FileSpec -> :class:`~manip_id.identification.reading.FileScan` of files
        already scanned.
    uncertainty : UncertaintyOptions, str or None
        The covariance: "auto" (default), "white" or "hac" (as :func:`identify`); each
        file's end is a block boundary.

    Returns
    -------
    IdentificationResult
        Of the information summed over the files (``n_samples`` their total): with
        accelerations in the files, the estimate of their concatenation.
        ``relative_error.validation`` is pooled over the validation files (every
        sample weighs the same), ``validation_per_file`` gives each file's.
        ``files`` holds every file's :class:`FileRecord`.
    """
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    check_least_squares(method, "identify_datasets solves")
    run_o = RunOptions.from_value(run)
    copts = ConsistentOptions.from_value(consistent)
    minimum_norm = RankOptions.from_value(rank).minimum_norm
    options = options or PreprocessOptions()
    uopts = UncertaintyOptions.from_value(uncertainty)
    robot, scans, made = reference_from_files(robot, files, validation, options, window, scans)
    base = resolve_base(robot, base, timings)
    kw: dict[str, Any] = dict(consistent=copts, minimum_norm=minimum_norm, uncertainty=uopts)
    if run_o.scheduler is not None:
        problem = distributed_problem(
            robot, files, validation, base, options, window=window, run=run_o, timings=timings,
            uncertainty=uopts,
        ).problem  # fmt: skip
        problem.t_start = t_start
        for scan in made:  # the temperature reference's scans: the tasks scan their own
            scan.discard()
        return note_reference(solve(problem, method, **kw), robot)
    ind = base.independent
    t0 = time.perf_counter()
    train = accumulate_files(
        robot, files, options, ind, window=window, run=run_o, scans=scans, uncertainty=uopts
    )
    valid = _validation_sums(robot, validation, options, ind, window, run_o, scans)
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
        t_start,
        validation_files=None if valid is None else [fa.sums() for fa in valid],
        files={
            "train": [fa.record() for fa in train],
            "validation": None if valid is None else [fa.record() for fa in valid],
        },
        chunk=run_o.chunk,
        still=sums.still,
        raw=sums.raw,
    )
    result = solve(problem, method, **kw)
    if window is None:  # an implausible fit: would a joint term the model lacks lower the error?
        vblocks = None if validation is None else _file_blocks(robot, validation, options, scans)
        result.warnings.extend(
            missing_term_warnings(
                robot,
                result.standard,
                _file_blocks(robot, files, options, scans),
                vblocks,
                ind,
                run_o.chunk,
            )
        )
    return note_reference(result, robot)


def _file_blocks(robot: Robot, files, options, scans):
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


__all__ = ["identify_datasets"]
