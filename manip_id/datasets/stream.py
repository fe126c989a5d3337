"""Streamed reading: any supported file as packed row blocks, windowed, checked and scaled.

:func:`open_source` opens a file by its :class:`~.spec.FileSpec` as a *source*:
an object with ``path``, ``format``, ``layout`` (:class:`~.layout.Layout`),
``joint_names``, ``n_rows`` (None when unknown before a pass) and
``chunks(chunk, start=0, stop=None)``, which yields float64 packed rows (see
:mod:`~.layout`) of raw rows ``start:stop``, a chunk at a time.
:func:`iter_rows` turns a source into the rows a fit sees, in this order:

1. the window: rows ``#A:#B``, or ``START <= t - t_0 < STOP`` [s] with ``t_0``
   the first stamp;
2. bad rows: refused (the error names the file, field, row and joint, or the CSV
   line) or, with ``drop_bad_rows``, dropped and counted per reason
   (:attr:`RowCounts.reasons`): non-finite values, malformed CSV lines (a wrong
   field count), values beyond the magnitude bounds that would refuse the file
   (:data:`~manip_id._checks.MEASURED_LIMITS`, e.g. 1e184), corrupted time stamps and
   isolated position spikes (:mod:`~.outliers`: running medians); a truncated last CSV
   line (no line end: a log cut short) is always dropped, with a note;
3. the value checks of :func:`~.core.check_values` on every field, and time
   increasing strictly across blocks;
4. the torque scale: ``tau_j <- G_j tau_j`` (drive gains [N m / A], gear ratios).

Memory is O(chunk) whatever the file's length.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._checks import MEASURED_LIMITS
from .._io.reading import check_data_path
from ..errors import DataError, DataWarning, InputError
from ..resources import TORQUE_SCALE_RANGE
from .adjust import TIME_UNITS, AdjustedSource, delay_vector
from .core import Dataset, check_time, check_values
from .csv import TRUNCATED, CsvSource
from .layout import Layout
from .npz import NpzSource
from .outliers import bad_time_stamps, position_spikes
from .panda import PANDA_FILES, is_panda_log, load_panda_gaz2019
from .replay import RowCache
from .rosbag import BagSource, is_bag
from .spec import FileSpec, Window

if TYPE_CHECKING:
    from ..robot.transmission import Transmission

#: Rows per block read from a file.
READ_CHUNK = 1 << 15

#: Format names :func:`open_source` and :func:`~manip_id.datasets.load_dataset` know.
FORMATS: tuple[str, ...] = ("npz", "csv", "panda_gaz2019", "rosbag")


def infer_format(path: Path) -> str:
    """The format of ``path`` from its suffix or folder contents."""
    if path.is_dir():
        if is_panda_log(path):
            return "panda_gaz2019"
        if is_bag(path):
            return "rosbag"
        raise DataError(
            f"{path} is a folder but neither a Panda log (expected "
            f"{', '.join(PANDA_FILES.values())}) nor a ROS 2 bag (expected metadata.yaml)"
        )
    suffix = path.suffix.lower()
    if suffix == ".npz":
        return "npz"
    if suffix in (".csv", ".txt"):
        return "csv"
    if suffix in (".mcap", ".db3"):
        return "rosbag"
    raise DataError(
        f"unknown data format of {path} (suffix {suffix!r}); expected one of .npz, .csv, "
        ".mcap, a ROS 2 bag folder or a Panda log folder, or pass format= one of "
        + ", ".join(FORMATS)
    )


class MemorySource:
    """A :class:`~.core.Dataset` in memory as a source (the Panda log, tests)."""

    def __init__(self, dataset: Dataset, path: Path | str = "<memory>", format: str = "memory"):
        self.dataset = dataset
        self.path = Path(path)
        self.format = format
        n_temp = 0 if dataset.temp is None else dataset.temp.shape[1]
        self.layout = Layout(dataset.q.shape[1], dataset.nv, dataset.ddq is not None, n_temp)
        self.joint_names = dataset.joint_names
        self.n_rows = dataset.n_samples

    def chunks(self, chunk: int, start: int = 0, stop: int | None = None) -> Iterator[np.ndarray]:
        d = self.dataset
        stop = self.n_rows if stop is None else min(stop, self.n_rows)
        for s in range(start, stop, chunk):
            e = min(s + chunk, stop)
            yield self.layout.pack(
                d.t[s:e],
                d.q[s:e],
                d.dq[s:e],
                d.tau[s:e],
                None if d.ddq is None else d.ddq[s:e],
                None if d.temp is None else d.temp[s:e],
            )


def open_source(spec: FileSpec, joint_names=None, cache: RowCache | None = None):
    """A streamed source for ``spec`` (see the module docstring).

    ``joint_names``: the robot's joints in order; a ROS bag's messages are
    matched to them by name (other formats keep the file's columns). ``cache``: a
    :class:`~.replay.RowCache` that keeps the rows of a slow format (CSV, ROS bags)
    parsed once for the later passes of the same run.
    """
    spec = spec if isinstance(spec, FileSpec) else FileSpec(Path(spec))
    path = spec.path
    check_data_path(path)
    fmt = infer_format(path) if spec.format is None else str(spec.format).lower()
    if fmt not in FORMATS:
        raise DataError(
            f"unknown data format {spec.format!r}; expected one of {', '.join(FORMATS)}"
        )
    if spec.columns is not None and fmt != "csv":
        raise DataError(f"a column map applies to CSV files only, not to format {fmt!r} ({path})")
    if spec.topic is not None and fmt != "rosbag":
        raise DataError(f"a topic applies to ROS bags only, not to {path} (format {fmt!r})")
    src = _raw_source(spec, fmt, joint_names)
    if cache is not None:
        src = cache.wrap(_source_key(spec, fmt, joint_names), src)
    if spec.time_unit is not None or spec.delay is not None:
        delay = delay_vector(spec.delay, src.layout.nv, f"the delay of {spec.label}")
        src = AdjustedSource(src, TIME_UNITS[spec.time_unit or "s"], delay)
    tr = spec.transmission
    if tr is not None and tr.signals == "motor":
        src = MotorSideSource(src, tr)
    return src


class MotorSideSource:
    """A source whose rows are motor-side, converted to the joint side as they are read
    (:meth:`~manip_id.robot.transmission.Transmission.convert_rows`: ``q = R^-1 theta + offset``,
    ``dq = R^-1 dtheta``, ``ddq = R^-1 ddtheta``, ``tau = R^T tau_motor``)."""

    def __init__(self, inner, transmission: Transmission):
        lay = inner.layout
        if lay.nq != transmission.n or lay.nv != transmission.n:
            raise DataError(
                f"{inner.path}: the transmission has {transmission.n} motors but the log has "
                f"{lay.nq} positions and {lay.nv} velocities"
            )
        self.inner, self.transmission = inner, transmission
        self.path, self.format, self.layout = inner.path, inner.format, lay
        self.joint_names = inner.joint_names
        self.n_rows = inner.n_rows
        self.malformed = getattr(inner, "malformed", {})
        self.compressed = getattr(inner, "compressed", False)
        self.derive_dq = getattr(inner, "derive_dq", False)

    def chunks(self, chunk: int, start: int = 0, stop: int | None = None) -> Iterator[np.ndarray]:
        slices = self.layout.slices
        for block in self.inner.chunks(chunk, start, stop):
            yield self.transmission.convert_rows(block, slices)


def _source_key(spec: FileSpec, fmt: str, joint_names) -> tuple:
    """What a raw source reads: the file (its size and modification time), the format and
    the options that change its rows (column map, topic, the joints a bag is matched to)."""
    path = spec.path.resolve()
    st = path.stat()
    columns = None if spec.columns is None else repr(sorted(dict(spec.columns).items(), key=str))
    names = None if fmt != "rosbag" or joint_names is None else tuple(joint_names)
    return (str(path), st.st_size, st.st_mtime_ns, fmt, columns, spec.topic, names, spec.rate)


def _raw_source(spec: FileSpec, fmt: str, joint_names):
    path = spec.path
    if fmt == "npz":
        return NpzSource(path, rate=spec.rate)
    if fmt == "csv":
        return CsvSource(path, spec.columns, spec.rate)
    if fmt == "rosbag":
        return BagSource(path, spec.topic, joint_names)
    return MemorySource(load_panda_gaz2019(path), path, "panda_gaz2019")


@dataclass
class RowCounts:
    """What :func:`iter_rows` saw: rows read in the window, dropped, where the first bad one was."""

    n_read: int = 0
    n_dropped: int = 0
    first_dropped: int | None = None
    dropped_fields: dict[str, int] = field(default_factory=dict)
    t_file_start: float | None = None
    n_file_rows: int | None = None
    #: rows dropped per reason: "non-finite", "implausible" (beyond the magnitude bounds
    #: of :data:`~manip_id._checks.MEASURED_LIMITS`), "malformed line" (CSV),
    #: "truncated last line" (CSV), "time stamp", "position spike" (:mod:`~.outliers`)
    reasons: dict[str, int] = field(default_factory=dict)

    def drop(self, reason: str, rows: np.ndarray) -> None:
        """Count the raw ``rows`` dropped for ``reason``."""
        if not rows.size:
            return
        self.n_dropped += int(rows.size)
        self.reasons[reason] = self.reasons.get(reason, 0) + int(rows.size)
        first = int(rows.min())
        self.first_dropped = first if self.first_dropped is None else min(self.first_dropped, first)


def torque_scale_vector(scale, nv: int, what: str = "torque scale") -> np.ndarray | None:
    """A per-joint torque scale of shape (nv,) from a scalar or nv values (None: no scale)."""
    if scale is None:
        return None
    arr = np.atleast_1d(np.asarray(scale, dtype=float))
    if arr.ndim != 1 or arr.size not in (1, nv):
        raise InputError(f"{what} takes one value or one per joint ({nv}), got {arr.size} values")
    if not np.isfinite(arr).all() or np.any(arr == 0):
        raise InputError(f"{what} must be finite and non-zero, got {arr.tolist()}")
    lo, hi = TORQUE_SCALE_RANGE
    if np.any(np.abs(arr) < lo) or np.any(np.abs(arr) > hi):
        raise InputError(
            f"{what} must have a magnitude in [{lo:g}, {hi:g}] (a gain from the logged unit "
            f"to N m or N), got {arr.tolist()}"
        )
    return np.broadcast_to(arr, (nv,)).copy()


def _implausible_cells(block: np.ndarray, layout: Layout) -> np.ndarray:
    """Cells beyond the magnitude bounds of their field (``MEASURED_LIMITS``), (k, width)."""
    out = np.zeros(block.shape, dtype=bool)
    for name, s in layout.slices.items():
        if name != "t" and name in MEASURED_LIMITS:
            out[:, s] = np.abs(block[:, s]) > MEASURED_LIMITS[name][1]
    return out


def _implausible(block: np.ndarray, layout: Layout) -> np.ndarray:
    """Rows holding a value beyond the magnitude bounds of its field, shape (k,)."""
    return np.asarray(_implausible_cells(block, layout).any(axis=1))


def _field_of(layout: Layout, col: int) -> tuple[str, int]:
    for name, s in layout.slices.items():
        if s.start <= col < s.stop:
            return name, col - s.start
    return "?", col


def _count_field(counts: RowCounts, layout: Layout, col: int) -> None:
    """One more dropped row whose first bad cell is in column ``col``."""
    fname, _ = _field_of(layout, col)
    counts.dropped_fields[fname] = counts.dropped_fields.get(fname, 0) + 1


def _drop_non_finite(source, block, raw, finite, drop_bad_rows: bool, counts: RowCounts):
    """``(block, raw)`` without the rows holding NaN/Inf (counted per reason and field).

    Without ``drop_bad_rows`` the first bad row is refused instead: its malformed CSV
    line, else the value check naming the field, row and joint (and the file).
    """
    lay: Layout = source.layout
    malformed = getattr(source, "malformed", None) or {}
    bad = np.flatnonzero(~finite)
    cut = np.array([malformed.get(int(r), "").startswith(TRUNCATED) for r in raw[bad]], bool)
    if cut.any():  # a log cut short: its last line goes, whatever drop_bad_rows says
        text = f"{source.path}: {malformed[int(raw[bad[cut][0]])]}: dropped"
        warnings.warn(DataWarning(text), stacklevel=4)
        counts.drop("truncated last line", raw[bad[cut]])
        finite = finite.copy()
        finite[bad[cut]] = True  # not to be seen again below
        keep = np.ones(block.shape[0], dtype=bool)
        keep[bad[cut]] = False
        block, raw, finite, bad = block[keep], raw[keep], finite[keep], bad[~cut]
        bad = np.flatnonzero(~finite)
        if not bad.size:
            return block, raw
    if not drop_bad_rows:
        hint = " (pass --drop-bad-rows / drop_bad_rows=True to drop such rows)"
        lines = [int(r) for r in raw[bad] if int(r) in malformed]
        if lines:
            raise DataError(malformed[lines[0]] + hint)
        for name, s in lay.slices.items():
            cols = source.joint_names if name != "t" and name != "q" else None
            try:
                arr = block[:, s] if name != "t" else block[:, 0]
                check_values(name, arr, arr.ndim, cols, offset=int(raw[0]))
            except DataError as exc:
                raise DataError(f"{source.path}: {exc}{hint}") from exc
    is_line = np.array([int(r) in malformed for r in raw[bad]], dtype=bool)
    counts.drop("malformed line", raw[bad[is_line]])
    counts.drop("non-finite", raw[bad[~is_line]])
    for b in bad[~is_line]:
        _count_field(counts, lay, int(np.flatnonzero(~np.isfinite(block[b]))[0]))
    return block[finite], raw[finite]


def _drop_implausible(lay: Layout, block, raw, counts: RowCounts):
    """``(block, raw)`` without the rows beyond the magnitude bounds (counted)."""
    wild = _implausible(block, lay)
    if not wild.any():
        return block, raw
    counts.drop("implausible", raw[wild])
    for b in np.flatnonzero(wild):
        _count_field(
            counts, lay, int(np.flatnonzero(_implausible_cells(block[b : b + 1], lay)[0])[0])
        )
    return block[~wild], raw[~wild]


def _drop_outliers(lay: Layout, block, raw, counts: RowCounts, previous_t):
    """``(block, raw)`` without corrupted time stamps and position spikes (counted)."""
    stamps = bad_time_stamps(block[:, 0], previous_t)
    spikes = position_spikes(block[:, lay.slices["q"]]) & ~stamps
    for reason, rows, name in (("time stamp", stamps, "t"), ("position spike", spikes, "q")):
        if rows.any():
            counts.drop(reason, raw[rows])
            counts.dropped_fields[name] = counts.dropped_fields.get(name, 0) + int(rows.sum())
    bad = stamps | spikes
    return (block[~bad], raw[~bad]) if bad.any() else (block, raw)


def _seconds_window(block: np.ndarray, raw: np.ndarray, window: Window, t0):
    """The rows of ``block`` inside a window in seconds from the file's first stamp
    ``t0``, and whether the block's last row is already past its stop."""
    rel = block[:, 0] - t0
    inside = np.ones(rel.shape, dtype=bool)
    if window.start is not None:
        inside &= rel >= window.start
    if window.stop is not None:
        inside &= rel < window.stop
    past = window.stop is not None and bool(rel[-1] >= window.stop)
    return block[inside], raw[inside], past


def iter_rows(
    source,
    window: Window | None = None,
    *,
    torque_scale=None,
    drop_bad_rows: bool = False,
    chunk: int = READ_CHUNK,
    counts: RowCounts | None = None,
    checked: bool = False,
) -> Iterator[np.ndarray]:
    """Packed rows of ``source`` as a fit sees them (see the module docstring).

    ``counts`` (a :class:`RowCounts`) is filled as the rows go by. Errors name
    the file; raw row indices are 0-based rows of the file. ``checked``: the
    same rows already passed these checks (a first pass over the same file):
    step 3's value checks are skipped, the window, the dropping of non-finite
    rows, the time order and the scale still apply.
    """
    lay: Layout = source.layout
    path = source.path
    names = source.joint_names
    scale = torque_scale_vector(torque_scale, lay.nv)
    counts = RowCounts() if counts is None else counts
    t_col = 0
    start = stop = None
    if window is not None and window.unit == "index":
        start, stop = window.start or 0, window.stop
    previous_t: float | None = None
    previous_row = -1
    row = int(start or 0)  # raw index of the next row
    t0 = None
    kept_any = False
    for block in source.chunks(int(chunk), row, None if stop is None else int(stop)):
        k = block.shape[0]
        raw = np.arange(row, row + k)
        row += k
        finite = np.isfinite(block).all(axis=1)
        if t0 is None:
            ft = np.flatnonzero(np.isfinite(block[:, t_col]))
            if ft.size:
                t0 = float(block[ft[0], t_col])
                counts.t_file_start = t0
        if not finite.all():
            block, raw = _drop_non_finite(source, block, raw, finite, drop_bad_rows, counts)
        if drop_bad_rows and block.shape[0]:
            block, raw = _drop_implausible(lay, block, raw, counts)
            block, raw = _drop_outliers(lay, block, raw, counts, previous_t)
        if window is not None and window.unit == "s" and block.shape[0]:
            block, raw, past = _seconds_window(block, raw, window, t0)
            if past and not block.shape[0]:
                break
        if not block.shape[0]:
            continue
        try:
            for name, s in () if checked else lay.slices.items():
                if name == "t":
                    check_values("t", block[:, 0], 1, offset=int(raw[0]))
                else:
                    check_values(name, block[:, s], 2, names if name != "q" else None, int(raw[0]))
        except DataError as exc:
            if drop_bad_rows:
                raise
            raise DataError(
                f"{exc} (pass --drop-bad-rows / drop_bad_rows=True to drop such rows)"
            ) from exc
        t = block[:, t_col]
        try:
            check_time(t, previous=previous_t, rows=raw, previous_row=previous_row)
        except DataError as exc:
            raise DataError(f"{path}: {exc}") from exc
        previous_t, previous_row = float(t[-1]), int(raw[-1])
        if scale is not None:
            block = block.copy() if not block.flags.writeable else block
            block[:, lay.slices["tau"]] *= scale
        counts.n_read += block.shape[0]
        kept_any = True
        yield block
        if window is not None and window.unit == "s" and window.stop is not None:
            if block[-1, t_col] - t0 >= window.stop:
                break
    counts.n_file_rows = row if window is None or window.unit == "index" else None
    _check_window(source, window, counts, row, t0, previous_t, kept_any)


def _check_window(source, window, counts: RowCounts, rows_seen: int, t0, t_last, kept: bool):
    path = source.path
    if window is None:
        if not kept:
            raise DataError(f"{path} holds no usable samples")
        return
    if window.unit == "index":
        n = source.n_rows if source.n_rows is not None else rows_seen
        if (window.start or 0) >= n:
            raise DataError(
                f"the window @{window} of {path} starts after its {n} samples (rows 0 .. {n - 1})"
            )
        if window.stop is not None and window.stop > n:
            warnings.warn(
                DataWarning(
                    f"the window @{window} of {path} ends after its {n} samples: kept rows "
                    f"{window.start or 0} .. {n - 1}"
                ),
                stacklevel=3,
            )
    if not kept:
        span = ""
        if t0 is not None and window.unit == "s":
            span = f" (its first stamp is t_0 = {t0:g} s)"
        raise DataError(f"the window @{window} of {path} holds no sample{span}")


def collect(rows: Iterator[np.ndarray], layout: Layout, joint_names, meta=None) -> Dataset:
    """A :class:`~.core.Dataset` from packed row blocks (everything in memory).

    Each block is split into its fields as it comes, and each field is joined into one
    contiguous array on its own, so that the peak is about one copy of the data plus one
    field (not the blocks, their stack and the fields' contiguous copies at once).
    """
    parts: dict[str, list[np.ndarray]] = {}
    for block in rows:
        for name, view in layout.unpack(block).items():
            parts.setdefault(name, []).append(np.array(view, dtype=float, order="C"))
    if not parts:
        parts = {name: [v] for name, v in layout.unpack(np.empty((0, layout.width))).items()}
    f = {}
    for name in list(parts):
        f[name] = np.concatenate(parts.pop(name), axis=0)
    return Dataset(
        t=f["t"],
        q=f["q"],
        dq=f["dq"],
        tau=f["tau"],
        ddq=f.get("ddq"),
        joint_names=joint_names,
        meta=dict(meta or {}),
        temp=f.get("temp"),
    )
