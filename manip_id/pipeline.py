"""One data file -> its information sums, read in chunks with bounded memory.

The unit of work of offline identification from logs is one file (or one
window of it), processed on its own: its own filter edges and trimming, its
own data-quality summary. For a file spec (path and optional window,
:class:`~manip_id.datasets.FileSpec`) and :class:`PreprocessOptions`,
:func:`accumulate_file` makes two passes over the file:

1. scan (:func:`scan_file`): the rows a fit sees (window, NaN rows refused or
   dropped, torque scale ``tau_j <- G_j tau_j``), checked block by block, with
   the data-quality summary (:class:`~manip_id.datasets.quality.DataQuality`)
   and the statistics that fix the sampling grid (count, first and last stamp,
   smallest and largest step);
2. accumulate: the rows again, preprocessed in overlapping blocks when the file
   has no accelerations or filtering was asked for
   (:func:`manip_id.signals.preprocess_blocks`, equal to the in-memory
   :func:`~manip_id.signals.preprocess` to round-off), the base-column
   regressor rows and the per-joint sums ``A_j = sum Y_j^T Y_j``,
   ``b_j = sum Y_j^T tau_j``, ``zz_j = sum tau_j^2`` of the samples where
   ``|dq_j| >= eps`` (velocity deadband; all samples without one).

Memory is O(block * width + nv r^2) whatever the number of samples. Files
merge by adding their accumulators (:meth:`InformationAccumulator.merge`), so
files can be processed anywhere (processes, Dask workers) and summed; the
validation error of a file for any estimate follows from its sums alone
(:meth:`FileAccumulation.validation_sums`).
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from .datasets import FileSpec, Layout, RowCounts, iter_rows, open_source, parse_file_spec
from .datasets.core import check_position_range
from .datasets.quality import DataQuality, QualityAccumulator
from .datasets.stream import READ_CHUNK, torque_scale_vector
from .errors import DataError, InputError
from .estimators import InformationAccumulator
from .regressor import DEFAULT_CHUNK
from .robot import Robot
from .signals import DEFAULT_BLOCK, DEFAULT_CUTOFF, DEFAULT_ORDER, PreprocessSettings


@dataclass(frozen=True)
class PreprocessOptions:
    """How each file is read and preprocessed (one set for every file of a run).

    Attributes
    ----------
    cutoff: low-pass cut-off [Hz]; None: :data:`~manip_id.signals.DEFAULT_CUTOFF`
        when the file has no ddq, no filtering when it has.
    order: Butterworth order of the one-way filter.
    trim: seconds dropped at each end of each file (window); None: the filter's
        edge transient.
    decimate: keep every D-th sample after filtering.
    rate: resampling rate [Hz]; None: the file's mean rate when its steps jitter.
    velocity: "measured" (filter the logged dq) or "differentiate" (dq from q).
    filter_torque: low-pass the torques too.
    torque_scale: one gain, or one per joint (nv): ``tau_j <- G_j tau_j``
        (drive gains [N m/A] from currents, gear ratios); None: 1.
    velocity_deadband: eps [rad/s or m/s]; the rows of joint j with
        ``|dq_j| < eps`` are left out of the fit and of the error figures.
    drop_bad_rows: drop (and count) rows holding NaN/Inf instead of refusing the file.
    read_chunk: rows per block read from the file.
    block: rows per block of the blocked preprocessing.
    """

    cutoff: float | None = None
    order: int = DEFAULT_ORDER
    trim: float | None = None
    decimate: int = 1
    rate: float | None = None
    velocity: str = "measured"
    filter_torque: bool = True
    torque_scale: float | tuple[float, ...] | None = None
    velocity_deadband: float | None = None
    drop_bad_rows: bool = False
    read_chunk: int = READ_CHUNK
    block: int = DEFAULT_BLOCK

    def __post_init__(self):
        ts = self.torque_scale
        if ts is not None and not np.isscalar(ts):
            object.__setattr__(self, "torque_scale", tuple(float(g) for g in np.ravel(ts)))
        eps = self.velocity_deadband
        if eps is not None and not (np.isfinite(eps) and eps > 0):
            raise InputError(f"the velocity deadband must be positive [rad/s], got {eps}")
        if int(self.decimate) != self.decimate or self.decimate < 1:
            raise InputError(f"decimate must be a positive integer, got {self.decimate}")
        if self.trim is not None and not self.trim >= 0:
            raise InputError(f"trim must be >= 0 seconds, got {self.trim}")
        if self.cutoff is not None and not self.cutoff > 0:
            raise InputError(f"the cut-off must be positive [Hz], got {self.cutoff}")

    def preprocesses(self, has_ddq: bool) -> bool:
        """Whether a file with (or without) ddq is filtered and differentiated."""
        return (
            not has_ddq
            or self.cutoff is not None
            or self.decimate != 1
            or self.trim is not None
            or self.rate is not None
        )

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True)
class FileScan:
    """The first pass over one file: what it holds, its quality, its time statistics."""

    spec: FileSpec
    format: str
    layout: Layout
    joint_names: tuple[str, ...]
    quality: DataQuality
    n: int
    t_first: float
    t_last: float
    dt_min: float
    dt_max: float
    counts: RowCounts
    spill: str | None = None

    def discard(self) -> None:
        """Remove the spill file (the scanned rows of a slow format), if any."""
        if self.spill is not None:
            from ._io import unregister_temporary

            Path(self.spill).unlink(missing_ok=True)
            unregister_temporary(self.spill)


#: Formats whose rows are parsed slowly (text, CDR messages; also compressed NPZ): the scan
#: keeps a binary copy of the rows it checked in a temporary file, read back by the second pass.
SPILL_FORMATS = ("csv", "rosbag")


@dataclass
class FileAccumulation:
    """The information of one file: sums, quality summary, preprocessing, rows left out.

    Attributes
    ----------
    spec: the file and its window.
    accumulator: per-joint sums of the base-column regressor rows (r columns).
    quality: the data-quality summary of the rows read.
    n_samples: samples accumulated (after preprocessing: trimmed, decimated).
    excluded: rows left out per joint by the velocity deadband, shape (nv,).
    settings: the preprocessing applied (None: the file's ddq used as is).
    torque_scale: the per-joint scale applied, shape (nv,), or None.
    timings: seconds per stage ("scan", "accumulate", ...).
    """

    spec: FileSpec
    accumulator: InformationAccumulator
    quality: DataQuality
    n_samples: int
    excluded: np.ndarray
    settings: PreprocessSettings | None
    torque_scale: np.ndarray | None
    timings: dict = field(default_factory=dict)

    def validation_sums(self, estimate) -> tuple[np.ndarray, np.ndarray]:
        """Per joint ``||tau_j - Y_j theta||^2`` and ``||tau_j||^2`` on this file, each (nv,).

        From the sums alone (``zz_j - 2 b_j.theta + theta.A_j.theta``): no pass
        over the data, floor about 1e-8 relative on the error.
        """
        acc = self.accumulator
        return acc.residual_sum_of_squares(estimate), acc.zz_joint

    def relative_error(self, estimate) -> tuple[float, np.ndarray]:
        """``||tau - tau_hat|| / ||tau||`` over the file and per joint (nv,)."""
        sse, zz = self.validation_sums(estimate)
        with np.errstate(divide="ignore", invalid="ignore"):
            per = np.sqrt(sse / zz)
        return (float(np.sqrt(sse.sum() / zz.sum())) if zz.sum() > 0 else float("nan")), per

    def summary(self, joints) -> dict:
        """JSON-ready: file, window, samples, rows left out per joint, preprocessing."""
        s = self.settings
        return {
            "file": str(self.spec.path),
            "window": None if self.spec.window is None else str(self.spec.window),
            "n_samples": int(self.n_samples),
            "excluded_rows": dict(zip(joints, map(int, self.excluded), strict=True)),
            "preprocess": None if s is None else {k: getattr(s, k) for k in s.__dataclass_fields__},
            "torque_scale": None if self.torque_scale is None else self.torque_scale.tolist(),
        }


def _check_layout(robot: Robot, src, spec: FileSpec) -> tuple[str, ...]:
    lay = src.layout
    if lay.nq != robot.nq or lay.nv != robot.nv:
        raise DataError(
            f"{spec.label}: the data have {lay.nv} joints ({lay.nq} positions) but robot "
            f"{robot.name!r} has nq={robot.nq}, nv={robot.nv}"
        )
    names = src.joint_names
    if names is not None and list(names) != list(robot.dof_names):
        if set(names) == set(robot.dof_names):
            raise DataError(
                f"{spec.label}: the data's joints are in the order {list(names)} but robot "
                f"{robot.name!r} expects {list(robot.dof_names)}"
            )
        extra = [n for n in names if n not in robot.dof_names]
        raise DataError(
            f"{spec.label}: the data name joints {extra} that robot {robot.name!r} does not "
            f"have (its joints: {list(robot.dof_names)})"
        )
    return tuple(robot.dof_names)


def _open(robot: Robot, spec: FileSpec):
    try:
        src = open_source(spec, joint_names=list(robot.dof_names))
    except DataError as exc:
        msg = str(exc)
        raise DataError(msg if str(spec.path) in msg else f"{spec.label}: {msg}") from exc
    return src, _check_layout(robot, src, spec)


def _rows(
    src, spec: FileSpec, options: PreprocessOptions, counts: RowCounts, checked: bool = False
):
    scale = torque_scale_vector(options.torque_scale, src.layout.nv, "--torque-scale")
    return iter_rows(
        src,
        spec.window,
        torque_scale=scale,
        drop_bad_rows=options.drop_bad_rows,
        chunk=options.read_chunk,
        counts=counts,
        checked=checked,
    )


def scan_file(robot: Robot, spec, options: PreprocessOptions | None = None) -> FileScan:
    """The first pass over one file: its rows checked, its quality summary (see module)."""
    spec = parse_file_spec(spec)
    options = options or PreprocessOptions()
    src, joints = _open(robot, spec)
    qa = QualityAccumulator(
        src.layout,
        joints,
        file=str(spec.path),
        format=src.format,
        window=None if spec.window is None else str(spec.window),
        lower=robot.lower,
        upper=robot.upper,
        effort_limit=robot.effort_limit,
        standstill_eps=options.velocity_deadband,
    )
    counts = RowCounts()
    spill = fh = None
    if src.format in SPILL_FORMATS or getattr(src, "compressed", False):
        import os
        import tempfile

        from ._io import register_temporary

        fd, spill = tempfile.mkstemp(prefix="manip_id_rows_", suffix=".f64")
        register_temporary(spill)
        fh = os.fdopen(fd, "wb")
    try:
        for rows in _rows(src, spec, options, counts):
            qa.add(rows)
            if fh is not None:
                fh.write(np.ascontiguousarray(rows, dtype="<f8").tobytes())
    except BaseException as exc:
        if fh is not None:
            fh.close()
            FileScan.discard(SimpleNamespace(spill=spill))  # type: ignore[arg-type]
        if isinstance(exc, DataError):
            msg = str(exc)
            raise DataError(msg if str(spec.path) in msg else f"{spec.label}: {msg}") from exc
        raise
    if fh is not None:
        fh.close()
    quality = qa.finish(counts.n_dropped, counts.first_dropped)
    if quality.n_samples:  # far outside the joint limits: refused (slightly: a warning)
        try:
            check_position_range(robot, quality.q_min, quality.q_max, spec.label)
        except DataError:
            if fh is not None:
                FileScan.discard(SimpleNamespace(spill=spill))  # type: ignore[arg-type]
            raise
    if quality.n_samples < 2:
        FileScan.discard(SimpleNamespace(spill=spill))  # type: ignore[arg-type]
        raise DataError(f"{spec.label}: {quality.n_samples} usable sample(s); need at least 2")
    return FileScan(
        spec=spec,
        format=src.format,
        layout=src.layout,
        joint_names=joints,
        quality=quality,
        n=quality.n_samples,
        t_first=quality.t_start,
        t_last=quality.t_end,
        dt_min=quality.dt_min,
        dt_max=quality.dt_max,
        counts=counts,
        spill=spill,
    )


def _spilled_rows(path: str, width: int, chunk: int) -> Iterator[np.ndarray]:
    """Packed rows read back from a spill file, ``chunk`` at a time (plain reads)."""
    with open(path, "rb") as fh:
        while True:
            block = np.fromfile(fh, dtype="<f8", count=chunk * width)
            if not block.size:
                return
            yield block.reshape(-1, width)


def iter_processed(
    robot: Robot, spec, options: PreprocessOptions | None = None, scan: FileScan | None = None
) -> tuple[PreprocessSettings | None, Iterator[np.ndarray]]:
    """The rows of one file as the fit sees them: packed ``t | q | dq | tau | ddq`` blocks.

    Returns ``(settings, blocks)``; ``settings`` is None when the file's own
    ddq is used as is. ``scan`` (from :func:`scan_file`) is made when not given.
    """
    spec = parse_file_spec(spec)
    options = options or PreprocessOptions()
    scan = scan_file(robot, spec, options) if scan is None else scan
    src, _ = _open(robot, spec)
    lay = src.layout
    if scan.spill is not None and Path(scan.spill).is_file():
        rows = _spilled_rows(scan.spill, lay.width, options.read_chunk)
    else:  # the scan checked these rows' values: only window, drops, order and scale again
        rows = _rows(src, spec, options, RowCounts(), checked=True)
    if not options.preprocesses(lay.has_ddq):
        return None, rows
    from .signals import SignalOptions, StreamStats, preprocess_blocks

    try:
        signal_options = SignalOptions(
            cutoff=DEFAULT_CUTOFF if options.cutoff is None else options.cutoff,
            order=options.order,
            rate=options.rate,
            decimate=options.decimate,
            trim=options.trim,
            velocity=options.velocity,
            filter_torque=options.filter_torque,
        )
        stats = StreamStats(scan.n, scan.t_first, scan.t_last, scan.dt_min, scan.dt_max)
        settings, blocks = preprocess_blocks(
            rows, lay.nq, lay.nv, stats, options=signal_options, block=options.block
        )
    except (InputError, DataError) as exc:
        raise type(exc)(f"{spec.label}: {exc}") from exc
    return settings, blocks


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
    from .identification import _accumulate_blocks

    timings: dict[str, float] = {}
    spec = parse_file_spec(spec)
    options = options or PreprocessOptions()
    if base_columns is None:
        from .identifiability import analyze

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
        acc, times = _accumulate_blocks(robot, states(), ind, int(chunk), deadband=deadband)
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


__all__ = [
    "FileAccumulation",
    "FileScan",
    "PreprocessOptions",
    "accumulate_file",
    "iter_processed",
    "scan_file",
]


def processed_count(
    scan: FileScan, settings: PreprocessSettings | None, options: PreprocessOptions
) -> int:
    """Number of samples the preprocessing of a scanned file yields (before any deadband)."""
    if settings is None:
        return scan.n
    n = scan.n
    if settings.resampled:
        from .signals import uniform_grid

        n = uniform_grid(scan.t_first, scan.t_last, settings.rate).shape[0]
    return len(range(settings.trim, n - settings.trim, settings.decimate))


# State handed to forked worker processes (inherited, never pickled).
_JOB: dict = {}


def _job_file(i: int) -> FileAccumulation:
    robot, specs, options, ind, chunk, scans = _JOB["job"]
    return accumulate_file(robot, specs[i], options, ind, chunk=chunk, scan=scans.get(specs[i]))


def _job_part(i: int) -> FileAccumulation:
    robot, spec, options, ind, chunk, scan, parts = _JOB["job"]
    return accumulate_file(
        robot, spec, options, ind, chunk=chunk, scan=scan, part=(i, parts), discard=False
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
        from .identifiability import analyze

        base_columns = analyze(robot).base.independent
    ind = np.asarray(base_columns, dtype=np.intp)
    for spec in specs:
        if spec not in scans:
            scans[spec] = scan_file(robot, spec, options)
    total = sum(scans[s].n for s in specs)
    if int(workers) > 1 and len(specs) == 1:  # one file: its samples in parts
        import multiprocessing as mp

        spec = specs[0]
        scan = scans.get(spec) or scan_file(robot, spec, options)
        _JOB["job"] = (robot, spec, options, ind, int(chunk), scan, int(workers))
        try:
            with mp.get_context("fork").Pool(int(workers)) as pool:
                parts = pool.map(_job_part, range(int(workers)))
        finally:
            _JOB.pop("job", None)
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
        import multiprocessing as mp

        _JOB["job"] = (robot, specs, options, ind, int(chunk), scans)
        try:
            with mp.get_context("fork").Pool(min(int(workers), len(specs))) as pool:
                forked: list[FileAccumulation] = []
                for k, fa in enumerate(pool.imap(_job_file, range(len(specs)))):
                    forked.append(fa)
                    if progress is not None:
                        progress(sum(scans[s].n for s in specs[: k + 1]), total)
                return forked
        finally:
            _JOB.pop("job", None)
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


def validation_errors(parts: list[FileAccumulation], estimate, joints) -> dict:
    """Pooled and per-file relative torque errors of ``estimate`` on ``parts``.

    Returns ``{"error", "per_joint" (nv,), "per_file": [{"file", "window",
    "n_samples", "error", "per_joint": {joint: error}}]}``; the pooled error is
    ``sqrt(sum_files SSE / sum_files ||tau||^2)`` (every sample weighs the same).
    """
    sse = np.zeros(len(joints))
    zz = np.zeros(len(joints))
    per_file = []
    for p in parts:
        s, z = p.validation_sums(estimate)
        sse += s
        zz += z
        err, per = p.relative_error(estimate)
        per_file.append(
            {
                "file": str(p.spec.path),
                "window": None if p.spec.window is None else str(p.spec.window),
                "n_samples": int(p.n_samples),
                "error": _finite(err),
                "per_joint": dict(zip(joints, map(_finite, per), strict=True)),
            }
        )
    with np.errstate(divide="ignore", invalid="ignore"):
        per_joint = np.sqrt(sse / zz)
    pooled = float(np.sqrt(sse.sum() / zz.sum())) if zz.sum() > 0 else float("nan")
    return {"error": pooled, "per_joint": per_joint, "per_file": per_file}


def _finite(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


__all__ += ["accumulate_files", "merge_accumulations", "processed_count", "validation_errors"]


def split_file(
    robot: Robot, spec, fraction: float, options: PreprocessOptions | None = None, scan=None
) -> tuple[FileSpec, FileSpec]:
    """Two windows of one file: its first ``fraction`` of samples, then the rest.

    As :meth:`~manip_id.datasets.Dataset.split` on the rows a fit sees: ``k =
    round(fraction N)`` (at least 2 on each side). The windows are in seconds
    (or rows, for a file cut by rows), so each part is preprocessed on its own.
    """
    from .datasets import Window

    spec = parse_file_spec(spec)
    options = options or PreprocessOptions()
    if not 0.0 < float(fraction) < 1.0:
        raise InputError(f"split fraction must be in (0, 1), got {fraction}")
    scan = scan_file(robot, spec, options) if scan is None else scan
    n = scan.n
    if n < 4:
        raise DataError(f"{spec.label}: {n} samples cannot be split in two parts of 2")
    k = min(max(int(round(float(fraction) * n)), 2), n - 2)
    w = spec.window
    if w is not None and w.unit == "index":
        if scan.counts.n_dropped:
            raise InputError(
                f"{spec.label}: cannot split a row window with dropped bad rows; "
                "give the two windows explicitly"
            )
        a = w.start or 0
        return (
            spec.with_window(Window(a, a + k, "index")),
            spec.with_window(Window(a + k, w.stop, "index")),
        )
    src, _ = _open(robot, spec)
    seen, t_k = 0, None
    for rows in _rows(src, spec, options, RowCounts()):
        if seen + rows.shape[0] > k:
            t_k = float(rows[k - seen, 0])
            break
        seen += rows.shape[0]
    t0 = scan.counts.t_file_start
    cut = t_k - t0
    start = None if w is None else w.start
    stop = None if w is None else w.stop
    return spec.with_window(Window(start, cut, "s")), spec.with_window(Window(cut, stop, "s"))


__all__ += ["split_file"]
