"""Tasks of a distributed run: one file, or one block of it, read and accumulated anywhere.

Least squares over many logs is a map-reduce, because the information sums of
disjoint data add. For files ``f`` cut into blocks ``b`` (each one task), per joint ``j``::

    A_j  = sum_f sum_b  Y_fbj^T Y_fbj        (r, r)    on the workers
    b_j  = sum_f sum_b  Y_fbj^T tau_fbj      (r,)
    zz_j = sum_f sum_b  tau_fbj^T tau_fbj
    theta_b = solve(sum_j A_j, sum_j b_j)              on the client

Each task reads its file in chunks, checks it against the robot, preprocesses it in
overlapping blocks when the file lacks ``ddq`` or filtering is asked for, and
accumulates the base-regressor rows of its block of that same stream, so the partition
changes the sums only by round-off. The parts are added in a tree
(:func:`manip_id.execution.reduce_tree`: blocks into files, files into the run), always
in the same grouping; the client receives ``nv`` matrices of ``r x r`` (and one set per
file when asked), never samples. Weighted least squares needs no second pass: the
per-joint residual sums at an estimate are linear in the sums. Validation files are
tasks too; their errors follow from their sums. A bad file fails the run with a
:class:`~manip_id.errors.DataError` naming the file, and no result.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ..datasets import FileSpec, Layout, parse_file_spec
from ..errors import DataError, InputError, ManipIdError
from ..estimators import InformationAccumulator
from ..execution import SPLIT_EVERY, Backend, open_backend, portable_robot, reduce_tree
from ..identifiability import BaseParameters
from ..models import accumulate_energy, accumulate_momentum, choose_window, window_samples
from ..robot.model import Robot
from ..robot.regressor import DEFAULT_CHUNK
from .file_sums import accumulate_file, accumulate_span
from .options import ModelOptions, PreprocessOptions, RunOptions, UncertaintyOptions
from .problem import (
    FileRecord,
    FileSums,
    Problem,
    RowSums,
    accumulate_blocks,
    check_equations,
)
from .reading import iter_processed, scan_file


@dataclass(frozen=True)
class FilePart:
    """One task: the samples ``[start, stop)`` of one file's preprocessed stream.

    ``stop=None``: to the end of the file. ``file`` is the index of the file
    in the list of the run.
    """

    spec: FileSpec
    file: int
    start: int = 0
    stop: int | None = None


@dataclass
class PartSums:
    """The value carried through the reduction: the information sums of some parts.

    Attributes
    ----------
    acc
        the accumulated base-column information of the fit's rows (``acc.n`` samples)
    files
        per file index, what is known of it (:class:`~.problem.FileRecord`)
    timings
        seconds per stage, summed over the tasks [s]
    still, raw
        the rows inside the deadband and the raw-torque sums
        (:class:`~.problem.RowSums`), when the parts have them
    """

    acc: InformationAccumulator
    files: dict[int, FileRecord] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    still: InformationAccumulator | None = None
    raw: InformationAccumulator | None = None

    def __add__(self, other: PartSums) -> PartSums:
        rows = RowSums(self.acc, self.still, self.raw, self.timings) + RowSums(
            other.acc, other.still, other.raw, other.timings
        )
        files = dict(self.files)
        for i, info in other.files.items():
            files[i] = files[i].merged(info) if i in files else info
        return PartSums(rows.fit, files, rows.timings, rows.still, rows.raw)

    @property
    def n_parts(self) -> int:
        """Number of tasks summed."""
        return sum(f.n_tasks for f in self.files.values())


def named_error(label: str, exc: BaseException) -> DataError:
    """``exc`` as a :class:`DataError` whose message names the file ``label``."""
    msg = str(exc) if isinstance(exc, ManipIdError) else f"{type(exc).__name__}: {exc}"
    path = label.partition("@")[0]
    return DataError(msg if path in msg else f"{label}: {msg}")


def file_length(robot: Robot, spec: FileSpec, options: PreprocessOptions) -> int:
    """Samples of a file's preprocessed stream (what its blocks partition)."""
    try:
        scan = scan_file(robot, spec, options)
        if not options.preprocesses(scan.layout.has_ddq):
            return int(scan.n)
        _, blocks = iter_processed(robot, spec, options, scan)
        return int(sum(b.shape[0] for b in blocks))
    except Exception as exc:
        raise named_error(spec.label, exc) from exc


def part_sums(
    robot: Robot,
    part: FilePart,
    columns: np.ndarray,
    chunk: int = DEFAULT_CHUNK,
    options: PreprocessOptions | None = None,
    uncertainty: UncertaintyOptions | None = None,
) -> PartSums:
    """The task body: read, preprocess and accumulate one part of one file.

    Parameters
    ----------
    robot
        the robot (:func:`portable_robot` for a worker)
    part
        the file and the block of its preprocessed samples
    columns
        the base parameters' independent columns, shape (r,)
    chunk
        samples per regressor chunk
    options
        how files are read and preprocessed (:class:`~.options.PreprocessOptions`)
    uncertainty
        the per-block sums its covariance needs (default recorded), numbered by
        ``part.file`` from the part's first sample

    Raises
    ------
    DataError
        naming the file, whatever went wrong with it.
    """
    options = options or PreprocessOptions()
    ind = np.asarray(columns, dtype=np.intp)
    try:
        if part.start == 0 and part.stop is None:
            fa = accumulate_file(
                robot, part.spec, options, ind, chunk=int(chunk), uncertainty=uncertainty
            )
        else:  # a block of the file's preprocessed stream: only its rows enter the sums
            scan = scan_file(robot, part.spec, options)
            try:
                run = RunOptions(chunk=int(chunk))
                span = (part.start, part.stop)
                fa = accumulate_span(
                    robot,
                    part.spec,
                    options,
                    ind,
                    run=run,
                    scan=scan,
                    span=span,
                    uncertainty=uncertainty,
                )
            finally:
                scan.discard()
            if fa.n_samples == 0:
                raise DataError(f"block [{part.start}, {part.stop}) holds no samples of the file")
    except Exception as exc:
        raise named_error(part.spec.label, exc) from exc
    if fa.accumulator.blocks is not None:
        fa.accumulator.blocks.set_stream(part.file)
    return PartSums(fa.accumulator, {part.file: fa.record()}, dict(fa.timings), fa.still, fa.raw)


def _processed_rows(robot: Robot, spec: FileSpec, options: PreprocessOptions):
    """The whole preprocessed stream of one file in memory, ``(t, q, dq, tau)`` and settings."""
    scan = scan_file(robot, spec, options)
    settings, blocks = iter_processed(robot, spec, options, scan)
    rows = np.vstack(list(blocks))
    f = Layout(robot.nq, robot.nv, rows.shape[1] > 1 + robot.nq + 2 * robot.nv).unpack(rows)
    return f, scan, settings


def model_plan(robot: Robot, spec: FileSpec, options: PreprocessOptions) -> tuple[int, float]:
    """Samples and sample time [s] of a file's preprocessed stream (energy blocks)."""
    try:
        f, _, _ = _processed_rows(robot, spec, options)
        t = f["t"]
        return int(t.size), float((t[-1] - t[0]) / max(t.size - 1, 1))
    except Exception as exc:
        raise named_error(spec.label, exc) from exc


def model_sums(
    robot: Robot,
    part: FilePart,
    columns,
    options: PreprocessOptions,
    model: str,
    window_length: float | None = None,
    uncertainty: UncertaintyOptions | None = None,
) -> PartSums:
    """Task body of the acceleration-free models: one file's (or block's) rows, accumulated.

    The file's preprocessed stream is held in memory (as the local energy and
    momentum paths do); a block ``[start, stop)`` of it holds whole energy
    windows, its last sample being the next block's first (the windows share
    their end points), so the blocks' rows are exactly the file's. The rows' per-block
    sums (``uncertainty``) are numbered by the file, from the block's first row.
    """
    try:
        f, scan, settings = _processed_rows(robot, part.spec, options)
        sl = slice(part.start, part.stop)
        t, q, dq, tau = f["t"][sl], f["q"][sl], f["dq"][sl], f["tau"][sl]
        if t.size < 2:
            raise DataError(f"{t.size} sample(s) in block [{part.start}, {part.stop})")
        steps = np.diff(t)
        dt = float((t[-1] - t[0]) / (t.size - 1))  # [s]
        if np.ptp(steps) > 1e-6 * dt:
            raise DataError(
                f"the {model} model needs uniform samples; steps range over "
                f"[{steps.min():g}, {steps.max():g}] s (give a cut-off to resample)"
            )
        t0 = time.perf_counter()
        accumulate = accumulate_energy if model == "energy" else accumulate_momentum
        first_row = part.start // window_samples(window_length, dt) if model == "energy" else 0
        record = replace(UncertaintyOptions.from_value(uncertainty), block_length=1).blocks(
            len(columns), 1 if model == "energy" else robot.nv, stream=part.file, offset=first_row
        )
        acc = accumulate(
            robot, q, dq, tau, dt=dt, window_length=window_length, columns=columns, blocks=record
        )
    except Exception as exc:
        raise named_error(part.spec.label, exc) from exc
    # a block ends on the next block's first sample (stop=None: the file's last block)
    n = t.size - (0 if part.stop is None else 1)
    info = FileRecord(part.spec, int(n), np.zeros(robot.nv, np.int64), scan.quality, settings)
    return PartSums(acc, {part.file: info}, {"accumulate": time.perf_counter() - t0})


def blocks_sums(
    robot: Robot,
    func: Callable,
    args: tuple,
    columns,
    chunk: int,
    uncertainty: UncertaintyOptions | None = None,
    stream: int = 0,
) -> PartSums:
    """Task body of a generic part ``(func, args)``: accumulate the blocks ``func(*args)``
    (with the per-block sums of ``uncertainty``, as record ``stream``)."""
    t0 = time.perf_counter()
    ind = np.asarray(columns, np.intp)
    record = UncertaintyOptions.from_value(uncertainty).blocks(ind.size, robot.nv, stream=stream)
    acc, times = accumulate_blocks(robot, func(*args), ind, int(chunk), record=record)
    return PartSums(acc, {}, {**times, "task": time.perf_counter() - t0})


@dataclass(frozen=True)
class PartitionOptions:
    """How the files of a distributed run are cut into tasks and added.

    Attributes
    ----------
    block : int or None
        Samples (of the preprocessed stream) per task: a longer file is cut into
        blocks, each one task (default: one task per file).
    split_every : int
        Parts added by one reduction task (>= 2).
    per_file : bool
        Also fetch each file's own sums (its own estimate and errors).
    """

    block: int | None = None
    split_every: int = SPLIT_EVERY
    per_file: bool = False

    def __post_init__(self):
        if self.block is not None and int(self.block) < 1:
            raise InputError(f"block must be a positive number of samples, got {self.block}")
        if int(self.split_every) < 2:
            raise InputError(f"split_every must be >= 2, got {self.split_every}")


@dataclass
class DistributedSums:
    """What a distributed run brings back: the problem, and each file's own sums.

    Attributes
    ----------
    problem : Problem
        The pooled training sums, the validation files' sums and the file records.
    per_file : list of PartSums or None
        Each training file's sums (``PartitionOptions.per_file``), in file order.
    """

    problem: Problem
    per_file: list[PartSums] | None = None


def file_specs(files, what: str, window=None) -> list[FileSpec]:
    """Parsed file specs (``window`` for those without one); none twice, at least one."""
    if isinstance(files, (str, os.PathLike, FileSpec)):
        files = [files]
    specs = [parse_file_spec(f, window=window) for f in files]
    if not specs:
        raise InputError(f"{what}: no files given")
    seen: set[tuple] = set()
    for s in specs:
        key = (os.path.realpath(s.path), None if s.window is None else str(s.window))
        if key in seen:
            raise InputError(f"{what}: {s.label} is given twice (its samples would count twice)")
        seen.add(key)
    return specs


def _energy_layout(backend: Backend, light, specs, options, block: int, window_length):
    plans = backend.gather(backend.map(model_plan, [(light, s, options) for s in specs]))
    layout = []
    for i, (s, (n, dt)) in enumerate(zip(specs, plans, strict=True)):
        w = window_samples(window_length, dt)
        n_win, per_task = (n - 1) // w, max(1, int(block) // w)  # windows
        cuts = list(range(0, n_win, per_task)) + [n_win]
        spans = list(zip(cuts[:-1], cuts[1:], strict=True)) or [(0, 0)]
        layout.append(
            [
                FilePart(s, i, a * w, None if k == len(spans) - 1 else b * w + 1)
                for k, (a, b) in enumerate(spans)
            ]
        )
    return layout


def plan_parts(backend: Backend, light: Robot, specs, options, model: ModelOptions, block):
    """The tasks of each file: one per file, or blocks of ``block`` samples (whole energy
    windows for the energy model; the momentum filter runs through a file: no blocks)."""
    if block is None:
        return [[FilePart(s, i)] for i, s in enumerate(specs)]
    if model.name == "momentum":
        raise InputError("the momentum model's filter runs through each file: no blocks")
    if model.name == "energy":
        return _energy_layout(backend, light, specs, options, block, model.window_length)
    lengths = backend.gather(backend.map(file_length, [(light, s, options) for s in specs]))
    layout = []
    for i, (s, n) in enumerate(zip(specs, lengths, strict=True)):
        if n < 1:
            raise DataError(f"{s.label}: no samples left after preprocessing")
        cuts = list(range(0, n, int(block))) + [n]
        layout.append([FilePart(s, i, a, b) for a, b in zip(cuts[:-1], cuts[1:], strict=True)])
    return layout


def _chosen_window(backend, light, specs, options, model: ModelOptions, n_base: int):
    """``model`` with the window chosen from the files (:func:`~manip_id.models.choose_window`
    on their samples together, at their mean sample time)."""
    plans = backend.gather(backend.map(model_plan, [(light, s, options) for s in specs]))
    n = sum(int(k) for k, _ in plans)
    dt = sum(float(k) * float(d) for k, d in plans) / max(n, 1)
    energy = model.name == "energy"
    choice = choose_window(
        n - len(plans) + 1, dt, n_base, rows_per_window=1 if energy else light.nv, even=energy
    )
    return replace(model, window_length=choice.length)


def distributed_problem(
    robot: Robot,
    files,
    validation,
    base: BaseParameters,
    options: PreprocessOptions,
    *,
    window=None,
    timings: dict | None = None,
    run: RunOptions | None = None,
    model: ModelOptions | None = None,
    partition: PartitionOptions | None = None,
    uncertainty: UncertaintyOptions | None = None,
) -> DistributedSums:
    """The problem of ``files`` (and ``validation`` files), each file a task or blocks of
    tasks on the run's back-end (serial without a scheduler, else Dask), added in a tree.

    ``model``: "dynamic", or "energy" / "momentum" (their rows from the unfiltered
    torques); the validation error is always the dynamic model's torque error.
    ``uncertainty``: the per-block sums its covariance needs travel with the sums (each
    file a record of its own, its parts merged exactly).
    """
    run = run or RunOptions()
    model = model or ModelOptions()
    partition = partition or PartitionOptions()
    timings = {} if timings is None else timings
    t_start = time.perf_counter()
    specs = file_specs(files, "paths", window)
    vspecs = None if validation is None else file_specs(validation, "validation", window)
    mopts = replace(options, filter_torque=False)  # the models integrate the raw torques
    ind = np.asarray(base.independent, dtype=np.intp)
    light = portable_robot(robot)
    every, chunk = int(partition.split_every), int(run.chunk)
    with open_backend(scheduler=run.scheduler) as backend:
        t0 = time.perf_counter()
        if model.name != "dynamic" and model.window_length is None:
            model = _chosen_window(backend, light, specs, mopts, model, base.n_base)
        layout = plan_parts(backend, light, specs, mopts, model, partition.block)
        if model.name == "dynamic":
            args = [[(light, pt, ind, chunk, options, uncertainty) for pt in lp] for lp in layout]
            leaves = [backend.map(part_sums, a) for a in args]
        else:
            mo = (mopts, model.name, model.window_length, uncertainty)
            leaves = [
                backend.map(model_sums, [(light, pt, ind, *mo) for pt in lp]) for lp in layout
            ]
        per = [reduce_tree(backend, lv, every) for lv in leaves]
        total = reduce_tree(backend, per, every)
        vparts = backend.map(
            part_sums,
            [
                (light, FilePart(s, i), ind, chunk, options, UncertaintyOptions(method="white"))
                for i, s in enumerate(vspecs or [])
            ],
        )
        fetched = backend.gather([total, *vparts, *(per if partition.per_file else [])])
        timings["distributed"] = time.perf_counter() - t0
    sums: PartSums = fetched[0]
    vsums: list[PartSums] = fetched[1 : 1 + len(vparts)]
    timings.update(sums.timings)
    check_equations(
        sums.acc.n_rows, base.n_base, f"{sums.acc.n} {model.name}-model samples or rows"
    )
    records = [sums.files[i] for i in range(len(specs))]
    vfiles = None
    if vspecs is not None:
        vfiles = [FileSums(vs.files[i], vs.acc, vs.still, vs.raw) for i, vs in enumerate(vsums)]
    problem = Problem(
        robot,
        base,
        sums.acc,
        sum(f.n_samples for f in records),
        timings,
        t_start,
        validation_files=vfiles,
        files={
            "train": records,
            "validation": None if vfiles is None else [v.record for v in vfiles],
        },
        model=model.name,
        chunk=chunk,
        still=sums.still,
        raw=sums.raw,
    )
    return DistributedSums(problem, fetched[1 + len(vparts) :] if partition.per_file else None)


__all__ = [
    "DistributedSums",
    "FilePart",
    "PartSums",
    "PartitionOptions",
    "blocks_sums",
    "distributed_problem",
    "file_length",
    "file_specs",
    "model_plan",
    "model_sums",
    "named_error",
    "part_sums",
    "plan_parts",
]
