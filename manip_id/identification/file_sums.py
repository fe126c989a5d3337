"""Log files -> their information sums, memory bounded.

For each file (or window of it) :func:`accumulate_file` makes two passes: the scan
(:func:`~manip_id.identification.reading.scan_file`: checked rows, data-quality
summary) and the accumulation of the preprocessed rows
(:func:`~manip_id.identification.reading.iter_processed`) into the per-joint sums
``A_j = sum Y_j^T Y_j``, ``b_j = sum Y_j^T tau_j``, ``zz_j = sum tau_j^2`` of the samples
where ``|dq_j| >= eps`` (velocity deadband; all samples without one). Files merge by
adding their sums, so they can be processed anywhere (forked processes, Dask workers);
the validation error of a file for any estimate follows from its sums alone.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..datasets import FileSpec, parse_file_spec
from ..datasets.stream import torque_scale_vector
from ..errors import DataError, InputError
from ..estimators import InformationAccumulator
from ..execution import ForkBackend
from ..identifiability import analyze
from ..regressor import DEFAULT_CHUNK
from ..robot import Robot
from .options import PreprocessOptions
from .problem import FileRecord, FileSums, accumulate_blocks
from .reading import FileScan, iter_processed, processed_count, scan_file


@dataclass(kw_only=True)
class FileAccumulation(FileRecord):
    """The information of one file: its record (:class:`FileRecord`) and its sums.

    Attributes
    ----------
    accumulator : InformationAccumulator
        Per-joint sums of the base-column regressor rows (r columns).
    timings : dict
        Seconds per stage ("scan", "accumulate", ...) [s].
    """

    accumulator: InformationAccumulator
    timings: dict = field(default_factory=dict)

    def validation_sums(self, estimate) -> tuple[np.ndarray, np.ndarray]:
        """Per joint ``||tau_j - Y_j theta||^2`` and ``||tau_j||^2`` on this file, each (nv,).

        From the sums alone (``zz_j - 2 b_j.theta + theta.A_j.theta``): no pass
        over the data, floor about 1e-8 relative on the error.
        """
        acc = self.accumulator
        return acc.residual_sum_of_squares(estimate), acc.zz_joint

    def sums(self) -> FileSums:
        """The record and the sums (what a problem keeps of a validation file)."""
        return FileSums(self.record(), self.accumulator)


def accumulate_file(
    robot: Robot,
    spec,
    options: PreprocessOptions | None = None,
    base_columns=None,
    *,
    chunk: int = DEFAULT_CHUNK,
    scan: FileScan | None = None,
    progress=None,
    part: tuple[int, int] | None = None,
    discard: bool = True,
) -> FileAccumulation:
    """The information sums of one file (see the module docstring).

    Parameters
    ----------
    robot: the robot (its joint terms decide the columns).
    spec: a :class:`~manip_id.datasets.FileSpec`, or its text ``PATH[@START:STOP|@#A:#B]``.
    options: :class:`PreprocessOptions` (default: all defaults).
    base_columns: indices of the regressor columns to accumulate, shape (r,)
        (``analyze(robot).base.independent``); default the structural base.
    chunk: samples per regressor chunk.
    scan: the file's :func:`scan_file`, when already made.
    progress: called as ``progress(samples_done)`` after each block.
    part: ``(k, K)``: accumulate only the k-th of K contiguous parts of the
        file's preprocessed samples (the file is still preprocessed whole, so
        the K parts add up to the whole file's sums); for workers sharing a file.
    discard: remove the scan's spill file afterwards (keep it for other parts).

    Returns
    -------
    :class:`FileAccumulation`. Raises :class:`DataError` naming the file.
    """
    timings: dict[str, float] = {}
    spec = parse_file_spec(spec)
    options = options or PreprocessOptions()
    if base_columns is None:
        base_columns = analyze(robot).base.independent
    ind = np.asarray(base_columns, dtype=np.intp)
    if scan is None:
        t0 = time.perf_counter()
        scan = scan_file(robot, spec, options)
        timings["scan"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    settings, blocks = iter_processed(robot, spec, options, scan)
    nv, nq = robot.nv, robot.nq
    eps = options.velocity_deadband
    deadband = None if eps is None else np.full(nv, float(eps))
    excluded = np.zeros(nv, dtype=np.int64)
    state = {"n": 0}

    lo, hi = 0, None
    if part is not None:
        k, parts = int(part[0]), int(part[1])
        if not 0 <= k < parts:
            raise InputError(f"part must be (k, K) with 0 <= k < K, got {part}")
        total = processed_count(scan, settings, options)
        lo, hi = (k * total) // parts, ((k + 1) * total) // parts
    seen = [0]

    def states():
        for rows in blocks:
            g0 = seen[0]
            seen[0] += rows.shape[0]
            if part is not None:
                if hi is not None and g0 >= hi:
                    break
                rows = rows[max(lo - g0, 0) : (hi if hi is not None else g0 + len(rows)) - g0]
                if not rows.shape[0]:
                    continue
            q = rows[:, 1 : 1 + nq]
            dq = rows[:, 1 + nq : 1 + nq + nv]
            tau = rows[:, 1 + nq + nv : 1 + nq + 2 * nv]
            ddq = rows[:, 1 + nq + 2 * nv : 1 + nq + 3 * nv]
            if deadband is not None:
                excluded[:] += (np.abs(dq) < deadband).sum(axis=0)
            state["n"] += rows.shape[0]
            yield q, dq, ddq, tau
            if progress is not None:
                progress(state["n"])

    try:
        acc, times = accumulate_blocks(robot, states(), ind, int(chunk), deadband=deadband)
    except (InputError, DataError) as exc:
        msg = str(exc)
        raise DataError(msg if str(spec.path) in msg else f"{spec.label}: {msg}") from exc
    finally:
        if discard:
            scan.discard()
    timings.update(times)
    timings["accumulate_total"] = time.perf_counter() - t0
    scale = torque_scale_vector(options.torque_scale, nv, "--torque-scale")
    return FileAccumulation(
        spec=spec,
        accumulator=acc,
        quality=scan.quality,
        n_samples=state["n"],
        excluded=excluded,
        settings=settings,
        torque_scale=scale,
        timings=timings,
    )


def _file_task(robot, spec, options, ind, chunk, scan, part=None, discard=True):
    """One task of :func:`accumulate_files`: one file, or one part of it."""
    return accumulate_file(
        robot, spec, options, ind, chunk=chunk, scan=scan, part=part, discard=discard
    )


def accumulate_files(
    robot: Robot,
    files,
    options: PreprocessOptions | None = None,
    base_columns=None,
    *,
    window=None,
    chunk: int = DEFAULT_CHUNK,
    workers: int = 1,
    progress=None,
    scans: dict | None = None,
) -> list[FileAccumulation]:
    """:func:`accumulate_file` for every file of ``files`` (specs or their texts), in order.

    ``window`` (text or :class:`~manip_id.datasets.Window`) applies to each file
    that has none. With ``workers > 1`` and several files, the files are
    accumulated in up to ``workers`` forked processes (one file per task); with
    one file, each process accumulates one contiguous part of its preprocessed
    samples (``part=``), the parts merged by addition.
    Every file is scanned (checked against ``robot``, its quality summary made)
    before any is accumulated, so a bad file fails first, naming it (a file of
    another robot, other joints, NaN rows, a window outside it). ``progress(done,
    total)`` is called as samples go by (total: the rows the scans counted).
    ``scans``: :class:`FileSpec` -> :class:`FileScan` of files already scanned.
    """
    scans = dict(scans or {})
    if isinstance(files, (str, FileSpec)) or not hasattr(files, "__iter__"):
        files = [files]
    specs = [parse_file_spec(f, window=window) for f in files]
    if not specs:
        raise InputError("no data files given")
    options = options or PreprocessOptions()
    if base_columns is None:
        base_columns = analyze(robot).base.independent
    ind = np.asarray(base_columns, dtype=np.intp)
    for spec in specs:
        if spec not in scans:
            scans[spec] = scan_file(robot, spec, options)
    total = sum(scans[s].n for s in specs)
    if int(workers) > 1 and len(specs) == 1:  # one file: its samples in parts
        spec = specs[0]
        scan = scans.get(spec) or scan_file(robot, spec, options)
        k_parts = int(workers)
        try:
            with ForkBackend(k_parts) as backend:
                parts = backend.map(
                    _file_task,
                    [
                        (robot, spec, options, ind, int(chunk), scan, (i, k_parts), False)
                        for i in range(k_parts)
                    ],
                )
        finally:
            scan.discard()
        first = parts[0]
        for other in parts[1:]:
            first.accumulator.merge(other.accumulator)
            first.excluded += other.excluded
            first.n_samples += other.n_samples
            for key, v in other.timings.items():
                first.timings[key] = first.timings.get(key, 0.0) + v
        if progress is not None:
            progress(total, total)
        return [first]
    if int(workers) > 1 and len(specs) > 1:

        def report(k: int, _value) -> None:
            if progress is not None:
                progress(sum(scans[s].n for s in specs[: k + 1]), total)

        with ForkBackend(int(workers)) as backend:
            return backend.map(
                _file_task,
                [(robot, s, options, ind, int(chunk), scans.get(s)) for s in specs],
                on_result=report,
            )
    out: list[FileAccumulation] = []
    done = 0
    last = [0]

    def report_samples(n: int, before: int) -> None:
        last[0] = min(before + n, total)
        if last[0] < total:  # the end is reported once, below
            progress(last[0], total)

    for spec in specs:
        report = None if progress is None else (lambda n, d=done: report_samples(n, d))
        out.append(
            accumulate_file(
                robot, spec, options, ind, chunk=chunk, scan=scans[spec], progress=report
            )
        )
        done += scans[spec].n
    if progress is not None:
        progress(total, total)
    return out


def merge_accumulations(parts: list[FileAccumulation]) -> InformationAccumulator:
    """The sum of the files' accumulators (the information of their concatenation)."""
    acc = parts[0].accumulator.copy()
    for p in parts[1:]:
        acc.merge(p.accumulator)
    return acc


__all__ = [
    "FileAccumulation",
    "accumulate_file",
    "accumulate_files",
    "merge_accumulations",
]
