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
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..datasets import FileSpec, Layout, parse_file_spec
from ..datasets.stream import torque_scale_vector
from ..errors import DataError, InputError
from ..estimators import InformationAccumulator
from ..execution import ForkBackend
from ..identifiability import analyze
from ..robot.compiled_regressor import planned_samples
from ..robot.model import Robot
from ..robot.regressor import DEFAULT_CHUNK
from .options import PreprocessOptions, RunOptions, UncertaintyOptions
from .problem import FileRecord, FileSums, RowSums, accumulate_rows
from .reading import FileScan, iter_processed, processed_count, scan_file


@dataclass(kw_only=True)
class FileAccumulation(FileRecord):
    """The information of one file: its record (:class:`FileRecord`) and its sums.

    Attributes
    ----------
    accumulator : InformationAccumulator
        Per-joint sums of the base-column regressor rows of the fit (r columns).
    still, raw : InformationAccumulator or None
        The rows inside the velocity deadband (Coulomb column zero), and every row
        against the raw torques when the fit's were filtered
        (:class:`~manip_id.identification.problem.RowSums`).
    timings : dict
        Seconds per stage ("scan", "accumulate", ...) [s].
    """

    accumulator: InformationAccumulator
    still: InformationAccumulator | None = None
    raw: InformationAccumulator | None = None
    timings: dict = field(default_factory=dict)

    def validation_sums(self, estimate) -> tuple[np.ndarray, np.ndarray]:
        """Per joint ``||tau_j - Y_j theta||^2`` and ``||tau_j||^2`` on this file's fit rows,
        each (nv,), from the sums alone (floor about 1e-8 relative on the error)."""
        acc = self.accumulator
        return acc.residual_sum_of_squares(estimate), acc.zz_joint

    def sums(self) -> FileSums:
        """The record and the sums (what a problem keeps of a validation file)."""
        return FileSums(self.record(), self.accumulator, self.still, self.raw)

    def merged(self, other: FileRecord) -> FileAccumulation:
        """Two parts of the same file, their sums added."""
        assert isinstance(other, FileAccumulation)
        times = dict(self.timings)
        for k, v in other.timings.items():
            times[k] = times.get(k, 0.0) + v
        rows = RowSums(self.accumulator, self.still, self.raw) + RowSums(
            other.accumulator, other.still, other.raw
        )
        return FileAccumulation(
            **vars(FileRecord.merged(self, other)),
            accumulator=rows.fit,
            still=rows.still,
            raw=rows.raw,
            timings=times,
        )


def file_stream(
    robot: Robot, spec: FileSpec, options: PreprocessOptions, scan: FileScan, start: int = 0
):
    """``(settings, blocks)``: the file's packed rows ``t | q | dq | tau | ddq [| temp]`` as
    the fit sees them (from processed row ``start`` on), each block paired with the same
    rows' raw torques (nv columns) when the preprocessing filters the torques (a second,
    unfiltered preprocessing of the same rows: the states are the same), else with None."""
    settings, blocks = iter_processed(robot, spec, options, scan, start=start)
    if settings is None or not options.filter_torque:
        return settings, ((b, None) for b in blocks)
    raw_options = replace(options, filter_torque=False)
    _, raw = iter_processed(robot, spec, raw_options, scan, start=start)
    nq, nv = robot.nq, robot.nv
    tau = slice(1 + nq + nv, 1 + nq + 2 * nv)

    def pairs():
        for b, r in zip(blocks, raw, strict=True):
            if b.shape != r.shape or not np.array_equal(b[:, : 1 + nq], r[:, : 1 + nq]):
                raise DataError(f"{spec.label}: the raw-torque pass gave other samples")
            yield b, r[:, tau]

    return settings, pairs()


def _span_states(pairs, robot: Robot, span, deadband, counts: dict, progress=None, first=0):
    """The states ``(q, dq, ddq, tau[, tau_raw[, temp]])`` of rows ``[lo, hi)`` of a file
    stream whose first row is row ``first``; counts the samples and the rows the deadband
    leaves out."""
    nq, nv = robot.nq, robot.nv
    lay = None
    lo, hi = span
    seen = int(first)
    history = robot.evaluator.needs_history
    for rows, raw in pairs:
        g0, seen = seen, seen + rows.shape[0]
        if hi is not None and g0 >= hi:
            break
        a, b = max(lo - g0, 0), rows.shape[0] if hi is None else min(hi - g0, rows.shape[0])
        if history:  # the rows before the span: the hysteresis state runs over them
            robot.evaluator.advance(rows[: min(a, rows.shape[0]), 1 : 1 + nq])
        if a >= b:
            continue
        lay = lay or Layout.processed(nq, nv, rows.shape[1])
        f = lay.unpack(rows[a:b])
        dq = f["dq"]
        if deadband is not None:
            counts["excluded"] += (np.abs(dq) < deadband).sum(axis=0)
        counts["n"] += b - a
        states = (f["q"], dq, f["ddq"], f["tau"], None if raw is None else raw[a:b])
        yield states + (f["temp"],) if "temp" in f else states
        if progress is not None:
            progress(counts["n"])


def accumulate_span(
    robot: Robot,
    spec: FileSpec,
    options: PreprocessOptions,
    ind: np.ndarray,
    *,
    run: RunOptions,
    scan: FileScan,
    span: tuple[int, int | None] = (0, None),
    uncertainty: UncertaintyOptions | None = None,
) -> FileAccumulation:
    """The sums of rows ``[lo, hi)`` of one scanned file's preprocessed stream (each row as
    the whole file's preprocessing makes it, so spans add up to the file);
    ``run.progress(samples_done)``. The file is read and filtered from one filter margin
    before ``lo`` (:func:`~manip_id.identification.reading.iter_processed` ``start``), from
    its first row when a history-dependent friction law must run over the rows before. The
    fit's sums carry the per-block sums ``uncertainty`` needs (record 0 from offset ``lo``;
    :meth:`~manip_id.estimators.blocks.ScoreBlocks.set_stream` numbers the file)."""
    t0 = time.perf_counter()
    first = 0 if robot.evaluator.needs_history else int(span[0])
    settings, pairs = file_stream(robot, spec, options, scan, first)
    eps = options.velocity_deadband
    deadband = None if eps is None else np.full(robot.nv, float(eps))
    counts: dict[str, Any] = {"n": 0, "excluded": np.zeros(robot.nv, dtype=np.int64)}
    states = _span_states(pairs, robot, span, deadband, counts, run.progress, first)
    try:
        record = UncertaintyOptions.from_value(uncertainty).blocks(
            len(ind), robot.nv, offset=int(span[0])
        )
        sums = accumulate_rows(robot, states, ind, int(run.chunk), deadband=deadband, record=record)
    except (InputError, DataError) as exc:
        msg = str(exc)
        raise DataError(msg if str(spec.path) in msg else f"{spec.label}: {msg}") from exc
    timings = {**sums.timings, "accumulate_total": time.perf_counter() - t0}
    return FileAccumulation(
        spec,
        counts["n"],
        counts["excluded"],
        scan.quality,
        settings,
        torque_scale_vector(options.torque_scale, robot.nv, "--torque-scale"),
        accumulator=sums.fit,
        still=sums.still,
        raw=sums.raw,
        timings=timings,
    )


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
    uncertainty: UncertaintyOptions | None = None,
) -> FileAccumulation:
    """The information sums of one file (see the module docstring).

    Parameters
    ----------
    robot : Robot
        The robot (its joint terms decide the columns).
    spec : FileSpec or str
        The file, or its text ``PATH[@START:STOP|@#A:#B]``.
    options : PreprocessOptions or None
        Preprocessing (default: all defaults).
    base_columns : array_like or None
        Indices of the regressor columns to accumulate, shape (r,); default the
        structural base's ``independent``.
    chunk : int
        Samples per regressor chunk.
    scan : FileScan or None
        The file's :func:`scan_file`, when already made.
    progress : callable or None
        Called as ``progress(samples_done)`` after each block.
    part : tuple or None
        ``(k, K)``: only the k-th of K contiguous parts of the file's preprocessed
        samples (the K parts add up to the whole file's sums); the scan's spill file
        is then kept for the other parts (else removed at the end).
    uncertainty : UncertaintyOptions or None
        The per-block sums its covariance needs (default ``"auto"``: recorded).

    Returns
    -------
    FileAccumulation
        Raises :class:`DataError` naming the file.
    """
    spec = parse_file_spec(spec)
    options = options or PreprocessOptions()
    if base_columns is None:
        base_columns = analyze(robot).base.independent
    ind = np.asarray(base_columns, dtype=np.intp)
    t0 = time.perf_counter()
    scanned = scan is None
    scan = scan_file(robot, spec, options) if scan is None else scan
    t_scan = time.perf_counter() - t0
    span: tuple[int, int | None] = (0, None)
    try:
        if part is not None:
            k, parts = int(part[0]), int(part[1])
            if not 0 <= k < parts:
                raise InputError(f"part must be (k, K) with 0 <= k < K, got {part}")
            settings, _ = iter_processed(robot, spec, options, scan)
            total = processed_count(scan, settings, options)
            span = ((k * total) // parts, ((k + 1) * total) // parts)
        run = RunOptions(chunk=int(chunk), progress=progress)
        fa = accumulate_span(
            robot, spec, options, ind, run=run, scan=scan, span=span, uncertainty=uncertainty
        )
    finally:
        if part is None:
            scan.discard()
    if scanned:
        fa.timings["scan"] = t_scan
    return fa


def _file_task(robot, spec, options, ind, chunk, scan, part=None, uncertainty=None):
    """One task of :func:`accumulate_files`: one file, or one part of it."""
    return accumulate_file(
        robot, spec, options, ind, chunk=chunk, scan=scan, part=part, uncertainty=uncertainty
    )


def _one_file_in_parts(
    robot, spec, options, ind, run: RunOptions, scan, k_parts: int, uncertainty=None
) -> FileAccumulation:
    """One file's samples in ``k_parts`` contiguous parts, in forked processes."""
    try:
        with ForkBackend(k_parts) as backend:
            parts = backend.map(
                _file_task,
                [
                    (robot, spec, options, ind, run.chunk, scan, (i, k_parts), uncertainty)
                    for i in range(k_parts)
                ],
            )
    finally:
        scan.discard()
    first = parts[0]
    for other in parts[1:]:
        first = first.merged(other)
    first.n_tasks = 1
    return first


def accumulate_files(
    robot: Robot,
    files,
    options: PreprocessOptions | None = None,
    base_columns=None,
    *,
    window=None,
    run: RunOptions | None = None,
    scans: dict | None = None,
    uncertainty: UncertaintyOptions | None = None,
) -> list[FileAccumulation]:
    """:func:`accumulate_file` for every file of ``files`` (specs or their texts), in order.

    ``window`` (text or :class:`~manip_id.datasets.Window`) applies to each file that
    has none. With ``run.workers_for(total) > 1`` (``total``: the files' samples) and
    several files, the files are accumulated in up to that many forked processes (one
    file per task); with one file, each process
    accumulates one contiguous part of its preprocessed samples, the parts merged by
    addition. Every file is scanned (checked against ``robot``, its quality summary
    made) before any is accumulated, so a bad file fails first, naming it.
    ``run.progress(done, total)`` is called as samples go by (total: the rows the scans
    counted). ``scans``: :class:`FileSpec` -> :class:`FileScan` of files already scanned.
    ``uncertainty``: the per-block sums its covariance needs (default recorded); each
    file's blocks are numbered by its place in ``files``.
    """
    run = run or RunOptions()
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
    with planned_samples(total):
        return _accumulate_specs(robot, specs, options, ind, run, scans, total, uncertainty)


def _accumulate_specs(
    robot, specs, options, ind, run: RunOptions, scans, total: int, uncertainty=None
):
    """The body of :func:`accumulate_files` (the files scanned, ``total`` their rows)."""
    progress = run.progress
    workers = run.workers_for(total)
    if workers > 1 and len(specs) == 1:  # one file: its samples in parts
        spec = specs[0]
        out = [
            _one_file_in_parts(robot, spec, options, ind, run, scans[spec], workers, uncertainty)
        ]
    elif workers > 1:

        def report(k: int, _value) -> None:
            if progress is not None:
                progress(sum(scans[s].n for s in specs[: k + 1]), total)

        with ForkBackend(workers) as backend:
            args = [(robot, s, options, ind, run.chunk, scans[s], None, uncertainty) for s in specs]
            return _numbered(backend.map(_file_task, args, on_result=report))
    else:
        out = [
            _serial_file(
                robot,
                s,
                options,
                ind,
                run,
                scans[s],
                sum(scans[x].n for x in specs[:i]),
                total,
                uncertainty=uncertainty,
            )
            for i, s in enumerate(specs)
        ]
    if progress is not None:
        progress(total, total)
    return _numbered(out)


def _numbered(files: list[FileAccumulation]) -> list[FileAccumulation]:
    """Each file's per-block sums numbered by its place in the run (record ``i``)."""
    for i, fa in enumerate(files):
        if fa.accumulator.blocks is not None:
            fa.accumulator.blocks.set_stream(i)
    return files


def _serial_file(
    robot,
    spec,
    options,
    ind,
    run: RunOptions,
    scan,
    before: int,
    total: int,
    *,
    uncertainty: UncertaintyOptions | None = None,
):
    """One file in this process, its progress reported as samples of all files (the end
    is reported once, by the caller)."""
    progress = run.progress

    def report(n: int) -> None:
        done = min(before + n, total)
        if progress is not None and done < total:
            progress(done, total)

    return accumulate_file(
        robot,
        spec,
        options,
        ind,
        chunk=run.chunk,
        scan=scan,
        progress=report,
        uncertainty=uncertainty,
    )


def merge_accumulations(parts: list[FileAccumulation]) -> RowSums:
    """The sum of the files' sums (the information of their concatenation)."""
    total = RowSums(parts[0].accumulator.copy(), parts[0].still, parts[0].raw)
    for p in parts[1:]:
        total = total + RowSums(p.accumulator, p.still, p.raw)
    return total


__all__ = [
    "FileAccumulation",
    "accumulate_file",
    "accumulate_files",
    "accumulate_span",
    "file_stream",
    "merge_accumulations",
]
