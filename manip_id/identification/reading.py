"""One data file as a fit sees it: scanned, checked, preprocessed, split.

The unit of work of offline identification from logs is one file (or one window of
it), processed on its own: its own filter edges and trimming, its own data-quality
summary. For a file spec (path and optional window, :class:`~manip_id.datasets.FileSpec`)
and :class:`~manip_id.identification.PreprocessOptions`:

1. :func:`scan_file`: the rows a fit sees (window, NaN rows refused or dropped, torque
   scale ``tau_j <- G_j tau_j``), checked block by block, with the data-quality summary
   (:class:`~manip_id.datasets.quality.DataQuality`) and the statistics that fix the
   sampling grid (count, first and last stamp, smallest and largest step);
2. :func:`iter_processed`: the rows again, preprocessed in overlapping blocks when the
   file has no accelerations or filtering was asked for
   (:func:`manip_id.signals.preprocess_blocks`, equal to the in-memory
   :func:`~manip_id.signals.preprocess` to round-off).

Memory is O(block * width) whatever the number of samples.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from .._io import register_temporary, unregister_temporary
from ..datasets import (
    FileSpec,
    Layout,
    RowCache,
    RowCounts,
    Window,
    iter_rows,
    open_source,
    parse_file_spec,
)
from ..datasets.core import check_position_range
from ..datasets.quality import DataQuality, QualityAccumulator
from ..datasets.stream import torque_scale_vector
from ..errors import DataError, InputError
from ..robot.friction import TemperatureStats
from ..robot.model import Robot
from ..signals import (
    DEFAULT_CUTOFF,
    PreprocessSettings,
    SignalOptions,
    StreamStats,
    preprocess_blocks,
    read_start,
    uniform_grid,
)
from ..signals.bandwidth import CutoffChoice, VelocitySpectrum
from .options import PreprocessOptions


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
    temperature: TemperatureStats | None = None  # the temp field's sums (None: no field)
    #: the cut-off chosen from the file (``cutoff="auto"``), else None
    cutoff: CutoffChoice | None = None
    #: whether the file has no velocities (dq differentiated from the positions)
    derived_velocity: bool = False

    def discard(self) -> None:
        """Remove the spill file (the scanned rows of a slow format), if any."""
        if self.spill is not None:
            Path(self.spill).unlink(missing_ok=True)
            unregister_temporary(self.spill)


#: Formats whose rows are parsed slowly (text, CDR messages; also compressed NPZ): the scan
#: keeps a binary copy of the rows it checked in a temporary file, read back by the second pass.
SPILL_FORMATS = ("csv", "rosbag")


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


def open_checked(robot: Robot, spec: FileSpec, cache: RowCache | None = None):
    """The file's row source, checked against ``robot`` (joints, their order); its joints.

    ``cache``: a :class:`~manip_id.datasets.RowCache` whose recordings serve (and keep)
    the parsed rows of a slow format."""
    try:
        src = open_source(spec, joint_names=list(robot.dof_names), cache=cache)
    except DataError as exc:
        msg = str(exc)
        raise DataError(msg if str(spec.path) in msg else f"{spec.label}: {msg}") from exc
    return src, _check_layout(robot, src, spec)


def read_rows(
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


def scan_file(
    robot: Robot,
    spec,
    options: PreprocessOptions | None = None,
    *,
    cache: RowCache | None = None,
) -> FileScan:
    """The first pass over one file: its rows checked, its quality summary (see module).

    ``cache``: a :class:`~manip_id.datasets.RowCache` holding the rows of a slow format
    already parsed by an earlier pass of the run (the pre-fit audit): they are read
    back instead of parsed again."""
    spec = parse_file_spec(spec)
    options = options or PreprocessOptions()
    src, joints = open_checked(robot, spec, cache)
    qa = QualityAccumulator(
        src.layout,
        joints,
        file=str(spec.path),
        format=src.format,
        window=None if spec.window is None else str(spec.window),
        robot=robot,
        standstill_eps=options.velocity_deadband,
    )
    counts = RowCounts()
    spectrum = VelocitySpectrum(robot.nv) if options.cutoff == "auto" else None
    temp = src.layout.slices.get("temp")
    temperature: TemperatureStats | None = None
    spill = fh = None
    if src.format in SPILL_FORMATS or getattr(src, "compressed", False):
        fd, spill = tempfile.mkstemp(prefix="manip_id_rows_", suffix=".f64")
        register_temporary(spill)
        fh = os.fdopen(fd, "wb")
    try:
        for rows in read_rows(src, spec, options, counts):
            qa.add(rows)
            if spectrum is not None:
                spectrum.add(rows[:, 0], robot.dofs.angles(rows[:, src.layout.slices["q"]]))
            if temp is not None and rows.shape[0]:  # the sums of the reference T0
                part = TemperatureStats.of(rows[:, temp])
                temperature = part if temperature is None else temperature + part
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
    quality = qa.finish(counts.n_dropped, counts.first_dropped, counts.reasons)
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
        temperature=temperature,
        cutoff=None if spectrum is None else spectrum.choose(options.decimate, robot.dof_names),
        derived_velocity=_derived_velocity(src),
    )


def _derived_velocity(src) -> bool:
    """Whether a source (or the one it wraps) differentiates dq from q (the file has none)."""
    while src is not None:
        if getattr(src, "derive_dq", False):
            return True
        src = getattr(src, "inner", None)
    return False


def _spilled_rows(path: str, width: int, chunk: int, start: int = 0) -> Iterator[np.ndarray]:
    """Packed rows ``start:`` read back from a spill file, ``chunk`` at a time (plain reads)."""
    with open(path, "rb") as fh:
        fh.seek(int(start) * width * 8)
        while True:
            block = np.fromfile(fh, dtype="<f8", count=chunk * width)
            if not block.size:
                return
            yield block.reshape(-1, width)


def _checked_rows(src, scan: FileScan, options: PreprocessOptions, start: int):
    """The scanned rows ``start:`` of a file (row 0: the first row the scan kept): from the
    spill by a seek; from the source at raw row ``window start + start`` when no row was
    dropped and the window (if any) is in rows; else read from the first row and skipped."""
    spec, lay = scan.spec, src.layout
    if scan.spill is not None and Path(scan.spill).is_file():
        return _spilled_rows(scan.spill, lay.width, options.read_chunk, start)
    w = spec.window
    if start and not scan.counts.n_dropped and (w is None or w.unit == "index"):
        w0 = 0 if w is None else int(w.start or 0)
        spec = spec.with_window(Window(w0 + start, None if w is None else w.stop, "index"))
        start = 0
    # the scan checked these rows' values: only window, drops, order and scale again
    rows = read_rows(src, spec, options, RowCounts(), checked=True)
    return rows if not start else _skip_rows(rows, start)


def _skip_rows(blocks, n: int) -> Iterator[np.ndarray]:
    """``blocks`` (row arrays) without their first ``n`` rows."""
    for b in blocks:
        if n >= b.shape[0]:
            n -= b.shape[0]
            continue
        yield b[n:] if n else b
        n = 0


def iter_processed(
    robot: Robot,
    spec,
    options: PreprocessOptions | None = None,
    scan: FileScan | None = None,
    *,
    start: int = 0,
) -> tuple[PreprocessSettings | None, Iterator[np.ndarray]]:
    """The rows of one file as the fit sees them: packed ``t | q | dq | tau | ddq [| temp]``
    blocks (:meth:`~manip_id.datasets.Layout.processed`).

    Returns ``(settings, blocks)``; ``settings`` is None when the file's own
    ddq is used as is. ``scan`` (from :func:`scan_file`) is made when not given.
    ``start``: the blocks hold the processed rows from row ``start`` on, bit for bit
    those of the whole pass; the file is read from one filter margin before them
    (:func:`~manip_id.signals.blocks.read_start`; from its first row when resampled).
    """
    spec = parse_file_spec(spec)
    options = options or PreprocessOptions()
    scan = scan_file(robot, spec, options) if scan is None else scan
    src, _ = open_checked(robot, spec)
    lay = src.layout
    start = max(int(start), 0)
    if not options.preprocesses(lay.has_ddq):
        return None, _checked_rows(src, scan, options, start)
    cutoff, reason = options.cutoff, ""
    if scan.cutoff is not None:  # "auto": the file's own
        cutoff, reason = scan.cutoff.cutoff, scan.cutoff.reason
    elif cutoff is None or cutoff == "auto":
        cutoff = DEFAULT_CUTOFF
    try:
        signal_options = SignalOptions(
            cutoff=float(cutoff),
            order=options.order,
            rate=options.rate,
            decimate=options.decimate,
            trim=options.trim,
            # a file without velocities: dq from the filtered q, as ddq from dq
            velocity="differentiate" if scan.derived_velocity else options.velocity,
            filter_torque=options.filter_torque,
        )
        stats = StreamStats(scan.n, scan.t_first, scan.t_last, scan.dt_min, scan.dt_max)
        first = read_start(stats, signal_options, options.block, start)
        rows = _checked_rows(src, scan, options, first)
        settings, blocks = preprocess_blocks(
            rows,
            lay.nq,
            lay.nv,
            stats,
            options=signal_options,
            block=options.block,
            n_temp=lay.n_temp,
            start=start,
            first_row=first,
        )
        if reason:
            settings = replace(settings, cutoff_reason=reason)
    except (InputError, DataError) as exc:
        raise type(exc)(f"{spec.label}: {exc}") from exc
    return settings, blocks


def processed_count(
    scan: FileScan, settings: PreprocessSettings | None, options: PreprocessOptions
) -> int:
    """Number of samples the preprocessing of a scanned file yields (before any deadband)."""
    if settings is None:
        return scan.n
    n = scan.n
    if settings.resampled:
        n = uniform_grid(scan.t_first, scan.t_last, settings.rate).shape[0]
    return len(range(settings.trim, n - settings.trim, settings.decimate))


def split_file(
    robot: Robot,
    spec,
    fraction: float,
    options: PreprocessOptions | None = None,
    scan=None,
    *,
    cache: RowCache | None = None,
) -> tuple[FileSpec, FileSpec]:
    """Two windows of one file: its first ``fraction`` of samples, then the rest.

    As :meth:`~manip_id.datasets.Dataset.split` on the rows a fit sees: ``k =
    round(fraction N)`` (at least 2 on each side). The windows are in seconds
    (or rows, for a file cut by rows), so each part is preprocessed on its own.
    ``cache``: see :func:`scan_file`.
    """
    spec = parse_file_spec(spec)
    options = options or PreprocessOptions()
    if not 0.0 < float(fraction) < 1.0:
        raise InputError(f"split fraction must be in (0, 1), got {fraction}")
    scan = scan_file(robot, spec, options, cache=cache) if scan is None else scan
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
    src, _ = open_checked(robot, spec, cache)
    seen, t_k = 0, None
    for rows in read_rows(src, spec, options, RowCounts()):
        if seen + rows.shape[0] > k:
            t_k = float(rows[k - seen, 0])
            break
        seen += rows.shape[0]
    t0 = scan.counts.t_file_start
    cut = t_k - t0
    start = None if w is None else w.start
    stop = None if w is None else w.stop
    return spec.with_window(Window(start, cut, "s")), spec.with_window(Window(cut, stop, "s"))


__all__ = [
    "SPILL_FORMATS",
    "FileScan",
    "iter_processed",
    "open_checked",
    "processed_count",
    "read_rows",
    "scan_file",
    "split_file",
]
