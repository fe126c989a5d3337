"""Fleet scale: identification over many logs, accumulated on Dask and solved on the client.

Least squares over a fleet of logs is a map-reduce, because the information
sums of disjoint data add (:class:`~manip_id.estimators.InformationAccumulator`
is a monoid). For files ``f`` cut into blocks ``b`` (each one task), per joint ``j``::

    A_j  = sum_f sum_b  Y_fbj^T Y_fbj        (r, r)    on the workers
    b_j  = sum_f sum_b  Y_fbj^T tau_fbj      (r,)
    zz_j = sum_f sum_b  tau_fbj^T tau_fbj
    theta_b = solve(sum_j A_j, sum_j b_j)              on the client

Each task is the real-log pipeline's unit of work
(:func:`manip_id.pipeline.accumulate_file`): it reads its file in chunks,
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
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .datasets import FileSpec, parse_file_spec
from .errors import DataError, InputError, ManipIdError, RankDeficiencyError
from .estimators import InformationAccumulator
from .execution import (
    DEFAULT_LOCAL_WORKERS,
    SPLIT_EVERY,
    WORKER_ENV,
    DaskBackend,
    SerialBackend,
    open_backend,
    parse_scheduler,
    portable_robot,
    reduce_tree,
)
from .identifiability import BaseParameters
from .identification import (
    IdentificationResult,
    RelativeError,
    _accumulate_blocks,
    _finish,
    _resolve_base,
)
from .pipeline import PreprocessOptions
from .regressor import DEFAULT_CHUNK
from .robot import Robot

#: Methods that accumulate (the online laws need the samples in order).
FLEET_METHODS: tuple[str, ...] = ("ols", "wls")

# Temporary aliases for manip_id.payload until it uses the public names of
# manip_id.execution (the payload package switches to them).
_Serial, _Dask, _tree = SerialBackend, DaskBackend, reduce_tree


# ------------------------------------------------------------------ the parts
@dataclass(frozen=True)
class FilePart:
    """One task: the samples ``[start, stop)`` of one file's preprocessed stream.

    ``stop=None``: to the end of the file. ``file`` is the index of the file
    in the list given to :func:`identify_files`.
    """

    spec: FileSpec
    file: int
    start: int = 0
    stop: int | None = None


@dataclass
class FileInfo:
    """What the client learns about one file besides its sums (small).

    The fields of :class:`~manip_id.pipeline.FileAccumulation` but its sums.

    Attributes
    ----------
    spec: the file and its window
    n_samples: samples accumulated (after preprocessing)
    excluded: rows left out per joint by the velocity deadband, shape (nv,)
    quality: its data-quality summary (:class:`~manip_id.datasets.quality.DataQuality`)
    settings: the preprocessing applied (None: the file's ddq used as is)
    torque_scale: the per-joint torque scale applied, shape (nv,), or None
    n_tasks: tasks (blocks) it was cut into
    """

    spec: FileSpec
    n_samples: int
    excluded: np.ndarray
    quality: Any = None
    settings: Any = None
    torque_scale: np.ndarray | None = None
    n_tasks: int = 1

    @property
    def label(self) -> str:
        """The file spec as written: ``path[@window]``."""
        return self.spec.label

    def merged(self, other: FileInfo) -> FileInfo:
        """Two blocks of the same file."""
        return replace(
            self,
            n_samples=self.n_samples + other.n_samples,
            excluded=self.excluded + other.excluded,
            n_tasks=self.n_tasks + other.n_tasks,
        )

    def summary(self, joints: Sequence[str]) -> dict:
        """JSON-ready, as :meth:`~manip_id.pipeline.FileAccumulation.summary` (file, window,
        samples, rows left out per joint, preprocessing, torque scale), and the tasks."""
        s = self.settings
        return {
            "file": str(self.spec.path),
            "window": None if self.spec.window is None else str(self.spec.window),
            "n_samples": int(self.n_samples),
            "excluded_rows": dict(zip(joints, map(int, self.excluded), strict=True)),
            "preprocess": None if s is None else {k: getattr(s, k) for k in s.__dataclass_fields__},
            "torque_scale": None if self.torque_scale is None else self.torque_scale.tolist(),
            "n_tasks": int(self.n_tasks),
        }


@dataclass
class PartSums:
    """The value carried through the reduction: the information sums of some parts.

    Attributes
    ----------
    acc: the accumulated base-column information (``acc.n`` samples)
    files: per file index, what is known of it (:class:`FileInfo`)
    timings: seconds per stage, summed over the tasks [s]
    """

    acc: InformationAccumulator
    files: dict[int, FileInfo] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)

    def __add__(self, other: PartSums) -> PartSums:
        times = dict(self.timings)
        for k, v in other.timings.items():
            times[k] = times.get(k, 0.0) + v
        files = dict(self.files)
        for i, info in other.files.items():
            files[i] = files[i].merged(info) if i in files else info
        return PartSums(self.acc + other.acc, files, times)

    @property
    def n_parts(self) -> int:
        """Number of tasks summed."""
        return sum(f.n_tasks for f in self.files.values())


@dataclass(frozen=True)
class FileEstimate:
    """One file's own identification, from its own sums (fleet monitoring).

    Attributes
    ----------
    path: the file (spec label)
    n_samples: samples accumulated from it (after preprocessing)
    n_tasks: tasks (blocks) it was cut into
    result: its identification (same base parameters and method as the pooled
        one), or None when the file alone cannot be solved
    error: why it cannot (e.g. it does not excite every base parameter), else None
    summary: samples, rows left out, preprocessing and data quality (:meth:`FileInfo.summary`)
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


# --------------------------------------------------------------- task bodies
def _named(label: str, exc: BaseException) -> DataError:
    msg = str(exc) if isinstance(exc, ManipIdError) else f"{type(exc).__name__}: {exc}"
    path = label.partition("@")[0]
    return DataError(msg if path in msg else f"{label}: {msg}")


def file_length(robot: Robot, spec: FileSpec, options: PreprocessOptions) -> int:
    """Samples of a file's preprocessed stream (what its blocks partition)."""
    from .pipeline import iter_processed, scan_file

    try:
        scan = scan_file(robot, spec, options)
        if not options.preprocesses(scan.layout.has_ddq):
            return int(scan.n)
        _, blocks = iter_processed(robot, spec, options, scan)
        return int(sum(b.shape[0] for b in blocks))
    except Exception as exc:
        raise _named(spec.label, exc) from exc


def _block_accumulation(robot, spec, options, ind, chunk, start: int, stop: int | None):
    """Rows ``[start, stop)`` of the file's preprocessed stream, accumulated.

    The stream is the one :func:`~manip_id.pipeline.accumulate_file` accumulates
    (:func:`~manip_id.pipeline.iter_processed`); only the rows of this block
    enter the sums. Returns (accumulator, samples, excluded rows (nv,), quality,
    settings, torque scale, timings).
    """
    from .datasets import Layout
    from .datasets.stream import torque_scale_vector
    from .pipeline import iter_processed, scan_file

    t0 = time.perf_counter()
    scan = scan_file(robot, spec, options)
    settings, blocks = iter_processed(robot, spec, options, scan)
    lay = Layout(robot.nq, robot.nv, True)
    eps = options.velocity_deadband
    deadband = None if eps is None else np.full(robot.nv, float(eps))
    excluded = np.zeros(robot.nv, dtype=np.int64)
    count = {"n": 0}

    def states():
        pos = 0
        for rows in blocks:
            a = max(start - pos, 0)
            b = rows.shape[0] if stop is None else min(stop - pos, rows.shape[0])
            pos += rows.shape[0]
            if a < b:
                f = lay.unpack(rows[a:b])
                if deadband is not None:
                    excluded[:] += (np.abs(f["dq"]) < deadband).sum(axis=0)
                count["n"] += b - a
                yield f["q"], f["dq"], f["ddq"], f["tau"]
            if stop is not None and pos >= stop:
                return

    acc, times = _accumulate_blocks(robot, states(), ind, int(chunk), deadband=deadband)
    if count["n"] == 0:
        raise DataError(f"block [{start}, {stop}) holds no samples of the file")
    times["accumulate_total"] = time.perf_counter() - t0
    scale = torque_scale_vector(options.torque_scale, robot.nv, "--torque-scale")
    return acc, count["n"], excluded, scan.quality, settings, scale, times


def part_sums(
    robot: Robot,
    part: FilePart,
    columns: np.ndarray,
    chunk: int = DEFAULT_CHUNK,
    options: PreprocessOptions | None = None,
) -> PartSums:
    """The task body: read, preprocess and accumulate one part of one file.

    Parameters
    ----------
    robot: the robot (:func:`portable_robot` for a worker)
    part: the file and the block of its preprocessed samples
    columns: the base parameters' independent columns, shape (r,)
    chunk: samples per regressor chunk
    options: how files are read and preprocessed (:class:`~manip_id.pipeline.PreprocessOptions`)

    Raises
    ------
    DataError: naming the file, whatever went wrong with it.
    """
    from .pipeline import accumulate_file

    options = options or PreprocessOptions()
    ind = np.asarray(columns, dtype=np.intp)
    try:
        if part.start == 0 and part.stop is None:
            fa = accumulate_file(robot, part.spec, options, ind, chunk=int(chunk))
            acc, n, excluded = fa.accumulator, fa.n_samples, fa.excluded
            quality, settings, scale = fa.quality, fa.settings, fa.torque_scale
            times = dict(fa.timings)
        else:
            acc, n, excluded, quality, settings, scale, times = _block_accumulation(
                robot, part.spec, options, ind, chunk, part.start, part.stop
            )
    except Exception as exc:
        raise _named(part.spec.label, exc) from exc
    info = FileInfo(part.spec, int(n), np.asarray(excluded), quality, settings, scale)
    return PartSums(acc, {part.file: info}, times)


def _processed_rows(robot: Robot, spec: FileSpec, options: PreprocessOptions):
    """The whole preprocessed stream of one file in memory, ``(t, q, dq, tau)`` and settings."""
    from .datasets import Layout
    from .pipeline import iter_processed, scan_file

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
        raise _named(spec.label, exc) from exc


def model_sums(
    robot: Robot,
    part: FilePart,
    columns,
    options: PreprocessOptions,
    model: str,
    window_length: float | None = None,
) -> PartSums:
    """Task body of the acceleration-free models: one file's (or block's) rows, accumulated.

    The file's preprocessed stream is held in memory (as the local energy and
    momentum paths do); a block ``[start, stop)`` of it holds whole energy
    windows, its last sample being the next block's first (the windows share
    their end points), so the blocks' rows are exactly the file's.
    """
    from .models import accumulate_energy, accumulate_momentum

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
        acc = accumulate(robot, q, dq, tau, dt=dt, window_length=window_length, columns=columns)
    except Exception as exc:
        raise _named(part.spec.label, exc) from exc
    # a block ends on the next block's first sample (stop=None: the file's last block)
    n = t.size - (0 if part.stop is None else 1)
    info = FileInfo(part.spec, int(n), np.zeros(robot.nv, np.int64), scan.quality, settings)
    return PartSums(acc, {part.file: info}, {"accumulate": time.perf_counter() - t0})


def _blocks_sums(robot: Robot, func: Callable, args: tuple, columns, chunk: int) -> PartSums:
    """Task body of a generic part ``(func, args)``: accumulate the blocks ``func(*args)``."""
    t0 = time.perf_counter()
    acc, times = _accumulate_blocks(robot, func(*args), np.asarray(columns, np.intp), int(chunk))
    return PartSums(acc, {}, {**times, "task": time.perf_counter() - t0})


def accumulate_parts(
    robot: Robot,
    parts: Sequence[tuple[Callable, tuple]],
    columns,
    chunk: int = DEFAULT_CHUNK,
    scheduler=None,
    split_every: int = SPLIT_EVERY,
) -> tuple[InformationAccumulator, dict[str, float]]:
    """The Dask back-end of :func:`manip_id.identification.identify_chunks`.

    ``parts``: ``(func, args)`` pairs, ``func(*args)`` yielding blocks
    ``(q, dq, ddq, tau)``; ``func`` must be importable on the workers (a
    module-level function) and ``args`` picklable. Each part is one task; the
    sums are added in a tree; returns the accumulator and the summed task times.
    """
    parts = list(parts)
    if not parts:
        raise InputError("no parts to accumulate")
    light = portable_robot(robot)
    with open_backend(scheduler=scheduler) as backend:
        leaves = backend.map(
            _blocks_sums, [(light, func, tuple(args), columns, chunk) for func, args in parts]
        )
        (total,) = backend.gather([reduce_tree(backend, leaves, int(split_every))])
    return total.acc, dict(total.timings)


# --------------------------------------------------------------------- entry
def _specs(files, what: str, window=None) -> list[FileSpec]:
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


def _options(options) -> PreprocessOptions:
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
    scheduler=None,
    method: str = "ols",
    per_file: bool = False,
    block: int | None = None,
    options: PreprocessOptions | Mapping | None = None,
    window=None,
    validation: Sequence[str | os.PathLike | FileSpec] | None = None,
    chunk: int = DEFAULT_CHUNK,
    base: BaseParameters | None = None,
    minimum_norm: bool = False,
    split_every: int = SPLIT_EVERY,
    consistent: bool = False,
    solver: str = "sdp",
    prior: str = "nominal",
    prior_weight: float | None = None,
    bounds=None,
    model: str = "dynamic",
    window_length: float | None = None,
) -> IdentificationResult:
    """Identify the base parameters of ``robot`` from many files, each file a task.

    Parameters
    ----------
    robot: the robot
    paths: data files, as file specs (``PATH``, ``PATH@START:STOP``,
        ``PATH@#A:#B`` or :class:`~manip_id.datasets.FileSpec`), any format the
        real-log pipeline reads; each preprocessed on its own
    scheduler: None (this process, no Dask), ``"local[:N]"``, ``"tcp://HOST:PORT"``,
        a scheduler JSON file, or a ``distributed.Client``
    method: ``"ols"`` or ``"wls"``
    per_file: also each file's own estimate and errors
        (``result.per_file``, a list of :class:`FileEstimate`)
    block: samples (of the preprocessed stream) per task: a longer file is cut
        into blocks, each one task (default: one task per file)
    options: :class:`~manip_id.pipeline.PreprocessOptions` (or a mapping of its
        fields) for every file; default: files without ``ddq`` are
        preprocessed with the default settings, the others used as they are
    window: a window for every file that has none
    validation: files for the validation error (each one task)
    chunk: samples per regressor chunk
    base: base parametrization; default the structural one
    minimum_norm: solve rank-deficient data with the minimum-norm solution
    split_every: parts added by one reduction task (>= 2)
    consistent, solver, prior, prior_weight, bounds: a physically consistent pooled
        estimate, as :func:`~manip_id.identification.identify` (solved on the
        client from the reduced sums)
    model: "dynamic" (``tau = Y(q, dq, ddq) theta``), or "energy" / "momentum"
        (:mod:`manip_id.models`, no accelerations; the torques are integrated
        unfiltered); energy blocks hold whole windows, momentum runs one task per
        file (its filter runs through the file). The validation error is the
        torque error of the dynamic model on the validation files
    window_length: energy window / momentum row spacing [s] (default the models')

    Returns
    -------
    The usual :class:`~manip_id.identification.IdentificationResult`, equal to
    the local run's (:func:`~manip_id.identification.identify_datasets`) to
    round-off whatever the workers or the partition. ``files`` is
    ``{"train": [FileInfo], "validation": [FileInfo] or None}`` (samples, rows
    left out, preprocessing, data quality of each file; no sums), ``per_file``
    the files' own estimates when asked. Its timings hold the task times summed
    over the tasks and ``distributed`` (the wall time of the map-reduce) [s].

    Raises
    ------
    DataError: a file that cannot be read or used, named (no partial result).
    RankDeficiencyError: the pooled data do not excite every base parameter.
    """
    timings: dict[str, float] = {}
    t_start = time.perf_counter()
    if method not in FLEET_METHODS:
        raise InputError(
            f"fleet identification accumulates {list(FLEET_METHODS)}, got {method!r} "
            "(the online laws need the samples in order)"
        )
    specs = _specs(paths, "paths", window)
    vspecs = None if validation is None else _specs(validation, "validation", window)
    if block is not None and int(block) < 1:
        raise InputError(f"block must be a positive number of samples, got {block}")
    if int(chunk) < 1:
        raise InputError(f"chunk must be a positive number of samples, got {chunk}")
    if int(split_every) < 2:
        raise InputError(f"split_every must be >= 2, got {split_every}")
    opts = _options(options)
    from .models import MODELS

    if model not in MODELS:
        raise InputError(f"model must be one of {list(MODELS)}, got {model!r}")
    if model == "momentum" and block is not None:
        raise InputError("the momentum model's filter runs through each file: no blocks")
    mopts = replace(opts, filter_torque=False)  # the models integrate the raw torques
    base = _resolve_base(robot, base, timings)
    ind = np.asarray(base.independent, dtype=np.intp)
    light = portable_robot(robot)

    with open_backend(scheduler=scheduler) as backend:
        t0 = time.perf_counter()
        if block is None:
            layout = [[FilePart(s, i)] for i, s in enumerate(specs)]
        elif model == "energy":
            from .models import window_samples

            plans = backend.gather([backend.submit(model_plan, light, s, mopts) for s in specs])
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
        else:
            lengths = backend.gather([backend.submit(file_length, light, s, opts) for s in specs])
            layout = []
            for i, (s, n) in enumerate(zip(specs, lengths, strict=True)):
                if n < 1:
                    raise DataError(f"{s.label}: no samples left after preprocessing")
                cuts = list(range(0, n, int(block))) + [n]
                layout.append(
                    [FilePart(s, i, a, b) for a, b in zip(cuts[:-1], cuts[1:], strict=True)]
                )

        def leaf(pt: FilePart):
            if model == "dynamic":
                return backend.submit(part_sums, light, pt, ind, chunk, opts)
            return backend.submit(model_sums, light, pt, ind, mopts, model, window_length)

        per = [reduce_tree(backend, [leaf(pt) for pt in lp], split_every) for lp in layout]
        total = reduce_tree(backend, list(per), split_every)
        vparts = (
            []
            if vspecs is None
            else [
                backend.submit(part_sums, light, FilePart(s, i), ind, chunk, opts)
                for i, s in enumerate(vspecs)
            ]
        )
        fetched = backend.gather([total, *vparts, *(per if per_file else [])])
        timings["distributed"] = time.perf_counter() - t0

    sums: PartSums = fetched[0]
    vsums: list[PartSums] = fetched[1 : 1 + len(vparts)]
    timings.update(sums.timings)
    if sums.acc.n_rows <= base.n_base:
        raise InputError(
            f"{sums.acc.n} {model}-model samples or rows give {sums.acc.n_rows} equations for "
            f"{base.n_base} base parameters: need more samples"
        )
    from .identification import DEFAULT_PRIOR_WEIGHT

    weight = DEFAULT_PRIOR_WEIGHT if prior_weight is None else prior_weight
    result = _finish(
        robot,
        sums.acc,
        base,
        method,
        timings,
        t_start,
        chunk=int(chunk),
        minimum_norm=minimum_norm,
        consistent=(consistent, solver, prior, weight, bounds),
    )
    files = [sums.files[i] for i in range(len(specs))]
    result = _as_model(robot, result, model, sum(f.n_samples for f in files))
    vfiles = None if vspecs is None else [vs.files[i] for i, vs in enumerate(vsums)]
    if vspecs is not None:
        result = replace(result, relative_error=_validation(robot, result, vsums))
    estimates = []
    if per_file:
        for info, fs in zip(files, fetched[1 + len(vparts) :], strict=True):
            estimates.append(_file_estimate(robot, info, fs, base, method, chunk, model))
    result = replace(
        result,
        per_file=estimates if per_file else None,
        files={"train": files, "validation": vfiles},
    )
    result.timings["total"] = time.perf_counter() - t_start
    return result


def _validation(robot: Robot, result: IdentificationResult, vsums: list[PartSums]):
    """Pooled and per-file validation errors of the estimate, from the files' sums.

    ``||tau_j - Y_j theta||^2 = zz_j - 2 b_j.theta + theta.A_j.theta`` per file
    (floor about 1e-8 relative on the error, as for the training error).
    """
    est = np.asarray(result.estimate, dtype=float)
    sse, zz = np.zeros(robot.nv), np.zeros(robot.nv)
    per_vfile = []
    for vs in vsums:
        s, z = vs.acc.residual_sum_of_squares(est), vs.acc.zz_joint
        sse += s
        zz += z
        err, err_j = _relative(s, z)
        (info,) = vs.files.values()
        per_vfile.append(
            {
                "file": info.label,
                "n_samples": int(info.n_samples),
                "error": _finite(err),
                "per_joint": dict(zip(robot.dof_names, map(_finite, err_j), strict=True)),
            }
        )
    val, val_j = _relative(sse, zz)
    re = result.relative_error
    return RelativeError(re.train, re.train_per_joint, val, val_j, validation_per_file=per_vfile)


def _relative(sse: np.ndarray, zz: np.ndarray) -> tuple[float, np.ndarray]:
    """``sqrt(sum e^2 / sum tau^2)`` overall and per joint."""
    with np.errstate(divide="ignore", invalid="ignore"):
        per_joint = np.sqrt(sse / zz)
    total = float(np.sqrt(sse.sum() / zz.sum())) if zz.sum() > 0 else float("nan")
    return total, per_joint


def _finite(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def _as_model(robot: Robot, result: IdentificationResult, model: str, n_samples: int):
    """The result of an energy / momentum fit labelled as :func:`identify` labels it."""
    if model == "dynamic":
        return result
    outputs = ["energy"] if model == "energy" else list(robot.dof_names)
    return replace(result, model=model, output_names=outputs, n_samples=int(n_samples))


def _file_estimate(robot, info: FileInfo, fs: PartSums, base, method, chunk, model="dynamic"):
    summary = info.summary(robot.dof_names)
    n = info.n_samples
    try:
        res = _finish(
            robot, fs.acc, base, method, dict(fs.timings), time.perf_counter(), chunk=int(chunk)
        )
        res = _as_model(robot, res, model, n)
        return FileEstimate(info.label, n, info.n_tasks, res, summary=summary)
    except (RankDeficiencyError, InputError) as exc:
        return FileEstimate(info.label, n, info.n_tasks, None, str(exc), summary=summary)


__all__ = [
    "DEFAULT_LOCAL_WORKERS",
    "SPLIT_EVERY",
    "WORKER_ENV",
    "FileEstimate",
    "FileInfo",
    "FilePart",
    "PartSums",
    "accumulate_parts",
    "file_length",
    "identify_files",
    "parse_scheduler",
    "part_sums",
    "portable_robot",
]
