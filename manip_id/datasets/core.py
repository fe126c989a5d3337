"""Measured data: the :class:`Dataset` type and its validation.

A dataset is a time series of joint states and torques::

    t    time stamps [s], shape (N,), strictly increasing
    q    positions [rad or m], shape (N, nq)
    dq   velocities [rad/s or m/s], shape (N, nv)
    tau  joint torques [N m or N], shape (N, nv)
    ddq  accelerations [rad/s^2 or m/s^2], shape (N, nv), optional
    joint_names  one name per velocity coordinate, optional

Validation on construction: at least 2 samples, one row per time stamp,
consistent widths, strictly increasing time (the error names the first
offending stamp), NaN/Inf reported with sample and column, and a warning when
positions look like degrees. :func:`check_robot` checks a dataset against a
robot (joint count and names).

Input and output: :func:`load_dataset` reads NPZ (the interchange format
below), CSV (default header or a column map) and the real Panda log folder
(:func:`load_panda_gaz2019`); :func:`save_dataset` writes NPZ or CSV through a
temporary file renamed into place, so a crash never leaves a partial file.
Raw logs carry no accelerations: see :func:`manip_id.signals.preprocess`.
"""

from __future__ import annotations

import fnmatch
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ._checks import as_float_array, check_finite
from ._io import atomic_write
from .errors import DataError


@dataclass(frozen=True)
class Dataset:
    """Joint-space measurements, validated on construction (see module docstring)."""

    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    tau: np.ndarray
    ddq: np.ndarray | None = None
    joint_names: tuple[str, ...] | None = None
    meta: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        arrays = {"t": (self.t, 1), "q": (self.q, 2), "dq": (self.dq, 2), "tau": (self.tau, 2)}
        if self.ddq is not None:
            arrays["ddq"] = (self.ddq, 2)
        clean = {}
        for name, (value, ndim) in arrays.items():
            try:
                arr = as_float_array(value, name, ndim=ndim)
            except Exception as exc:
                raise DataError(str(exc)) from exc
            clean[name] = arr
        n = clean["t"].shape[0]
        if n < 2:
            raise DataError(f"a dataset needs at least 2 samples, got t.shape={clean['t'].shape}")
        for name, arr in clean.items():
            if arr.shape[0] != n:
                raise DataError(
                    f"t.shape={clean['t'].shape} but {name}.shape={arr.shape}: "
                    "every array needs one row per time stamp"
                )
        nv = clean["dq"].shape[1]
        for name in ("tau", "ddq"):
            if name in clean and clean[name].shape[1] != nv:
                raise DataError(
                    f"dq.shape={clean['dq'].shape} but {name}.shape={clean[name].shape}"
                )
        if clean["q"].shape[1] < nv:
            raise DataError(
                f"q.shape={clean['q'].shape} has fewer columns than dq.shape={clean['dq'].shape}"
            )
        names = None
        if self.joint_names is not None:
            names = tuple(str(j) for j in self.joint_names)
            if len(names) != nv:
                raise DataError(f"{len(names)} joint_names for nv={nv} velocity columns")
        for name, arr in clean.items():
            try:
                check_finite(arr, name, names if name != "q" else None)
            except Exception as exc:
                raise DataError(str(exc)) from exc
        dt = np.diff(clean["t"])
        if np.any(dt <= 0):
            k = int(np.argmax(dt <= 0)) + 1
            raise DataError(
                f"time must increase strictly: t[{k}]={clean['t'][k]} "
                f"after t[{k - 1}]={clean['t'][k - 1]}"
            )
        if np.nanmax(np.abs(clean["q"])) > 2 * np.pi * 4:
            warnings.warn(
                f"positions reach {np.abs(clean['q']).max():.1f}: are they in degrees? "
                "manip_id expects radians (meters for prismatic joints)",
                stacklevel=3,
            )
        for name, arr in clean.items():
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "joint_names", names)

    @property
    def n_samples(self) -> int:
        """Number of samples N."""
        return self.t.shape[0]

    @property
    def nv(self) -> int:
        """Number of velocity coordinates."""
        return self.dq.shape[1]

    @property
    def duration(self) -> float:
        """t[-1] - t[0] [s]."""
        return float(self.t[-1] - self.t[0])

    def slice(self, start: int, stop: int) -> Dataset:
        """Samples ``start:stop`` as a new dataset."""
        return replace(
            self,
            t=self.t[start:stop],
            q=self.q[start:stop],
            dq=self.dq[start:stop],
            tau=self.tau[start:stop],
            ddq=None if self.ddq is None else self.ddq[start:stop],
        )

    def split(self, fraction: float) -> tuple[Dataset, Dataset]:
        """Split in time: the first ``fraction`` of samples, then the rest (for validation)."""
        if not 0.0 < fraction < 1.0:
            raise DataError(f"split fraction must be in (0, 1), got {fraction}")
        k = int(round(fraction * self.n_samples))
        k = min(max(k, 2), self.n_samples - 2)
        return self.slice(0, k), self.slice(k, self.n_samples)


# ======================================================================== IO
#
# NPZ interchange format (what ``save_dataset`` writes and ``load_dataset`` reads):
#
#     t            float (N,)      time stamps [s]
#     q            float (N, nq)   positions [rad or m]
#     dq           float (N, nv)   velocities [rad/s or m/s]
#     tau          float (N, nv)   torques [N m or N]
#     ddq          float (N, nv)   accelerations, optional
#     joint_names  str   (nv,)     optional
#
# CSV layout (default header, comma-separated, one sample per row):
#
#     t,q_<joint>...,dq_<joint>...,tau_<joint>...[,ddq_<joint>...]
#
# Columns are found by prefix (``t`` or ``time``; ``q_``, ``dq_``, ``tau_``,
# ``ddq_``) in header order, so any column order works; joint names come from
# the ``dq_`` columns. Other layouts load with a column map.

#: Formats :func:`load_dataset` knows, by name.
FORMATS: tuple[str, ...] = ("npz", "csv", "panda_gaz2019")
_FIELDS = ("t", "q", "dq", "tau", "ddq")
_PANDA_FILES = {
    "t": "rbt_log_time.txt",
    "q": "rbt_log_positions.txt",
    "dq": "rbt_log_velocity.txt",
    "tau": "rbt_log_torques.txt",
}
PANDA_JOINTS: tuple[str, ...] = tuple(f"panda_joint{i}" for i in range(1, 8))


def _infer_format(path: Path) -> str:
    if path.is_dir():
        if all((path / f).is_file() for f in _PANDA_FILES.values()):
            return "panda_gaz2019"
        raise DataError(
            f"{path} is a folder but not a Panda log (expected {', '.join(_PANDA_FILES.values())})"
        )
    suffix = path.suffix.lower()
    if suffix == ".npz":
        return "npz"
    if suffix in (".csv", ".txt"):
        return "csv"
    raise DataError(
        f"unknown data format of {path} (suffix {suffix!r}); expected one of .npz, .csv "
        "or a Panda log folder, or pass format= one of " + ", ".join(FORMATS)
    )


def load_dataset(
    path: str | Path, *, format: str | None = None, columns: Mapping | None = None
) -> Dataset:
    """Load measurements from a file or folder.

    Parameters
    ----------
    path: an ``.npz`` file (interchange format above), a ``.csv`` file, or a
        folder holding the real Panda log (:func:`load_panda_gaz2019`).
    format: ``"npz"``, ``"csv"`` or ``"panda_gaz2019"``; default from the path.
    columns: CSV only, a column map for other layouts: field -> column(s).
        Fields ``t`` (one column), ``q``, ``dq``, ``tau``, ``ddq`` (lists of
        columns, or one glob pattern such as ``"pos*"``), optional
        ``joint_names`` (list of names). Columns are header names or 0-based
        indices (indices also work on files without a header). Fields left
        out are looked up by the default prefixes; ``dq`` may be absent, in
        which case it is computed from ``q`` by central differences.

    Raises
    ------
    DataError: missing file, unknown format, a column map that does not fit
        the file, or data failing :class:`Dataset` validation.
    """
    path = Path(path).expanduser()
    if not path.exists():
        raise DataError(f"no such data file or folder: {path}")
    fmt = _infer_format(path) if format is None else str(format).lower()
    if fmt not in FORMATS:
        raise DataError(f"unknown data format {format!r}; expected one of {', '.join(FORMATS)}")
    if columns is not None and fmt != "csv":
        raise DataError(f"a column map applies to CSV files only, not to format {fmt!r}")
    if fmt == "npz":
        return _load_npz(path)
    if fmt == "csv":
        return _load_csv(path, columns)
    return load_panda_gaz2019(path)


def _load_npz(path: Path) -> Dataset:
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except Exception as exc:
        raise DataError(f"cannot read {path} as NPZ: {exc}") from exc
    missing = [k for k in ("t", "q", "dq", "tau") if k not in arrays]
    if missing:
        raise DataError(
            f"{path} lacks array(s) {', '.join(missing)}; an NPZ dataset holds t, q, dq, "
            f"tau and optionally ddq, joint_names (found {', '.join(sorted(arrays)) or 'none'})"
        )
    unknown = sorted(set(arrays) - {*_FIELDS, "joint_names"})
    if unknown:
        raise DataError(
            f"{path} holds unexpected array(s) {', '.join(unknown)}; "
            "expected t, q, dq, tau, ddq, joint_names"
        )
    names = arrays.pop("joint_names", None)
    if names is not None:
        names = tuple(str(n) for n in np.atleast_1d(names))
    return _build(path, joint_names=names, **arrays)


def _build(path, **kwargs) -> Dataset:
    try:
        return Dataset(**kwargs, meta={"source": str(path)})
    except DataError as exc:
        raise DataError(f"{path}: {exc}") from exc


def _read_csv_table(path: Path) -> tuple[list[str] | None, np.ndarray]:
    with open(path) as fh:
        first = fh.readline()
    delimiter = "," if "," in first else None
    cells = [c.strip() for c in (first.split(delimiter) if delimiter else first.split())]
    try:
        [float(c) for c in cells]
        header = None
    except ValueError:
        header = cells
    try:
        table = np.loadtxt(path, delimiter=delimiter, skiprows=0 if header is None else 1, ndmin=2)
    except ValueError as exc:
        raise DataError(f"cannot read {path} as a numeric CSV table: {exc}") from exc
    if header is not None and table.shape[1] != len(header):
        raise DataError(
            f"{path}: the header has {len(header)} columns but rows have {table.shape[1]}"
        )
    return header, table


def _column_index(spec, header: list[str] | None, path: Path, field_name: str) -> int:
    if isinstance(spec, (int, np.integer)):
        return int(spec)
    if header is None:
        raise DataError(
            f"{path} has no header row, so column {spec!r} of {field_name!r} must be "
            "given as a 0-based index"
        )
    try:
        return header.index(str(spec))
    except ValueError:
        raise DataError(
            f"column {spec!r} of {field_name!r} is not in {path} (columns: {', '.join(header)})"
        ) from None


def _columns_for(spec, header, path, field_name) -> list[int]:
    if isinstance(spec, str) and header is not None and any(ch in spec for ch in "*?["):
        idx = [i for i, h in enumerate(header) if fnmatch.fnmatchcase(h, spec)]
        if not idx:
            raise DataError(
                f"pattern {spec!r} of {field_name!r} matches no column of {path} "
                f"(columns: {', '.join(header)})"
            )
        return idx
    specs = [spec] if isinstance(spec, (str, int, np.integer)) else list(spec)
    return [_column_index(s, header, path, field_name) for s in specs]


def _load_csv(path: Path, columns: Mapping | None) -> Dataset:
    header, table = _read_csv_table(path)
    columns = dict(columns or {})
    unknown = sorted(set(columns) - {*_FIELDS, "joint_names"})
    if unknown:
        raise DataError(
            f"column map has unknown field(s) {', '.join(unknown)}; "
            f"expected some of {', '.join(_FIELDS)}, joint_names"
        )
    idx: dict[str, list[int]] = {}
    for name in _FIELDS:
        if name in columns:
            idx[name] = _columns_for(columns[name], header, path, name)
        elif header is not None:
            if name == "t":
                found = [i for i, h in enumerate(header) if h.lower() in ("t", "time")]
            else:
                found = [i for i, h in enumerate(header) if h.startswith(name + "_")]
            if found:
                idx[name] = found
    required = ("t", "q", "tau")
    missing = [n for n in required if n not in idx]
    if missing:
        layout = (
            "header t,q_<joint>...,dq_<joint>...,tau_<joint>..."
            if header is not None
            else "no header row: give a column map with 0-based indices"
        )
        raise DataError(f"{path}: cannot find column(s) for {', '.join(missing)} ({layout})")
    if len(idx["t"]) != 1:
        raise DataError(f"{path}: 't' must be one column, got {len(idx['t'])}")
    width = table.shape[1]
    for name, cols in idx.items():
        bad = [c for c in cols if not -width <= c < width]
        if bad:
            raise DataError(
                f"column map: {name!r} refers to column {bad[0]} but {path} has {width} columns"
            )
    data = {name: table[:, cols] for name, cols in idx.items()}
    data["t"] = data["t"][:, 0]
    names = columns.get("joint_names")
    if names is None and header is not None and "dq" in idx and "dq" not in columns:
        names = [header[i][3:] for i in idx["dq"]]
    elif names is None and header is not None and "tau" not in columns:
        names = [header[i][4:] for i in idx["tau"]]
    if "dq" not in data:
        t = data["t"]
        if data["q"].shape[1] != data["tau"].shape[1]:
            raise DataError(
                f"{path}: no dq columns, and q ({data['q'].shape[1]} columns) cannot be "
                f"differentiated into {data['tau'].shape[1]} velocities"
            )
        if t.shape[0] < 3:
            raise DataError(f"{path}: need at least 3 samples to differentiate q, got {t.shape[0]}")
        if np.any(np.diff(t) <= 0):
            return _build(path, t=t, q=data["q"], dq=data["q"], tau=data["tau"])  # raises on t
        data["dq"] = np.gradient(data["q"], t, axis=0, edge_order=2)
    ds = _build(path, joint_names=tuple(names) if names is not None else None, **data)
    if "dq" not in idx:
        ds.meta["dq"] = "central differences of q"
    return ds


def load_panda_gaz2019(folder: str | Path) -> Dataset:
    """The real Franka Emika Panda excitation log (Gaz et al., RA-L 2019).

    ``folder`` holds ``rbt_log_time.txt`` (N stamps [s], about 1 kHz, not
    uniform) and ``rbt_log_positions.txt``, ``rbt_log_velocity.txt``,
    ``rbt_log_torques.txt``: sample-major, one value per line (line ``7 k + j``
    is joint ``j`` of sample ``k``). Returns a :class:`Dataset` with joint
    names ``panda_joint1..7`` and no ddq (see :func:`manip_id.signals.preprocess`).
    """
    folder = Path(folder).expanduser()
    if not folder.is_dir():
        raise DataError(f"no such Panda log folder: {folder}")
    arrays = {}
    for name, fname in _PANDA_FILES.items():
        f = folder / fname
        if not f.is_file():
            raise DataError(f"the Panda log folder {folder} lacks {fname}")
        try:
            values = np.loadtxt(f, ndmin=1)
        except ValueError as exc:
            raise DataError(f"cannot read {f}: {exc}") from exc
        if values.ndim != 1:
            raise DataError(f"{f}: expected one value per line, got rows of {values.shape[1]}")
        arrays[name] = values
    n = arrays["t"].shape[0]
    for name in ("q", "dq", "tau"):
        size = arrays[name].shape[0]
        if size != 7 * n:
            raise DataError(
                f"{folder / _PANDA_FILES[name]} has {size} values but 7 x {n} time stamps "
                f"= {7 * n} were expected"
            )
        arrays[name] = arrays[name].reshape(n, 7)
    ds = _build(folder, joint_names=PANDA_JOINTS, **arrays)
    ds.meta["format"] = "panda_gaz2019"
    return ds


def save_dataset(dataset: Dataset, path: str | Path, *, format: str | None = None) -> Path:
    """Write ``dataset`` as NPZ (interchange format) or CSV (default header), atomically.

    The data go to a temporary file in the target folder, renamed over
    ``path`` once complete: a crash never leaves a partial file. The format
    follows the suffix (``.npz``, ``.csv``) unless ``format`` is given.
    Returns the path written.
    """
    if not isinstance(dataset, Dataset):
        raise DataError(f"save_dataset expects a Dataset, got {type(dataset).__name__}")
    path = Path(path).expanduser()
    fmt = format or {".npz": "npz", ".csv": "csv"}.get(path.suffix.lower())
    if fmt not in ("npz", "csv"):
        raise DataError(
            f"cannot save to {path}: unknown format {format or path.suffix!r}; "
            "expected .npz or .csv"
        )
    names = dataset.joint_names or tuple(f"j{i}" for i in range(dataset.nv))

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            if fmt == "npz":
                arrays = {"t": dataset.t, "q": dataset.q, "dq": dataset.dq, "tau": dataset.tau}
                if dataset.ddq is not None:
                    arrays["ddq"] = dataset.ddq
                if dataset.joint_names is not None:
                    arrays["joint_names"] = np.array(dataset.joint_names, dtype=str)
                np.savez(fh, **arrays)
            else:
                qnames = (
                    names
                    if dataset.q.shape[1] == dataset.nv
                    else [str(i) for i in range(dataset.q.shape[1])]
                )
                head = [
                    "t",
                    *(f"q_{n}" for n in qnames),
                    *(f"dq_{n}" for n in names),
                    *(f"tau_{n}" for n in names),
                ]
                blocks = [dataset.t[:, None], dataset.q, dataset.dq, dataset.tau]
                if dataset.ddq is not None:
                    head += [f"ddq_{n}" for n in names]
                    blocks.append(dataset.ddq)
                np.savetxt(
                    fh,
                    np.hstack(blocks),
                    delimiter=",",
                    header=",".join(head),
                    comments="",
                    fmt="%.17g",
                )

    atomic_write(path, write)
    return path


def check_robot(dataset: Dataset, robot) -> None:
    """Raise :class:`DataError` unless the dataset fits ``robot`` (a :class:`~.robot.Robot`).

    Checks q has ``robot.nq`` columns, dq and tau ``robot.nv``, and, when the
    dataset names its joints, that the names are ``robot.dof_names`` in order.
    """
    if dataset.q.shape[1] != robot.nq or dataset.nv != robot.nv:
        raise DataError(
            f"the data have {dataset.nv} joints (q.shape={dataset.q.shape}, "
            f"dq.shape={dataset.dq.shape}) but robot {robot.name!r} has nq={robot.nq}, "
            f"nv={robot.nv}"
        )
    if dataset.joint_names is not None and list(dataset.joint_names) != list(robot.dof_names):
        if set(dataset.joint_names) == set(robot.dof_names):
            raise DataError(
                f"the data's joints are in the order {list(dataset.joint_names)} but robot "
                f"{robot.name!r} expects {list(robot.dof_names)}"
            )
        extra = [n for n in dataset.joint_names if n not in robot.dof_names]
        raise DataError(
            f"the data name joints {extra} that robot {robot.name!r} does not have "
            f"(its joints: {list(robot.dof_names)})"
        )
