"""Whole-file reading and writing: :func:`load_dataset` and :func:`save_dataset`.

Formats: NPZ (:mod:`~.npz`), CSV (:mod:`~.csv`), ROS 2 bags of
``sensor_msgs/msg/JointState`` (:mod:`~.rosbag`) and the real Panda log folder
(:mod:`~.panda`). Files are written through a temporary renamed into place, so
a crash never leaves a partial file. For long logs read in chunks instead
(:func:`~.stream.open_source`, :func:`manip_id.identification.accumulate_file`).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

from .._checks import memory_budget
from .._io import atomic_write
from .._io.reading import check_data_path
from ..errors import DataError
from .core import Dataset
from .csv import load_csv, write_csv
from .layout import Layout
from .npz import load_npz, write_npz
from .panda import load_panda_gaz2019
from .rosbag import BagSource, write_bag
from .stream import FORMATS, MemorySource, collect, infer_format, iter_rows

#: Largest memory budget of a whole-file NPZ read [bytes] (also at most half the free memory).
MEMORY_BUDGET = 8 * 2**30


def load_dataset(
    path: str | Path,
    *,
    format: str | None = None,
    columns: Mapping | None = None,
    topic: str | None = None,
    joint_names=None,
    rate: float | None = None,
) -> Dataset:
    """Load measurements from a file or folder, whole.

    Parameters
    ----------
    path: an ``.npz`` file (interchange format, :mod:`~.npz`), a ``.csv`` file,
        a ROS 2 bag (a rosbag2 folder with MCAP or sqlite3 storage, or a bare
        ``.mcap`` file), or a folder holding the real Panda log
        (:func:`load_panda_gaz2019`).
    format: ``"npz"``, ``"csv"``, ``"rosbag"`` or ``"panda_gaz2019"``; default from the path.
    columns: CSV only, a column map for other layouts: field -> column(s).
        Fields ``t`` (one column), ``q``, ``dq``, ``tau``, ``ddq`` (lists of
        columns, or one glob pattern such as ``"pos*"``), optional
        ``joint_names`` (list of names). Columns are header names or 0-based
        indices (indices also work on files without a header). Fields left
        out are looked up by the default prefixes; ``dq`` may be absent, in
        which case it is computed from ``q`` by central differences.
    topic: ROS bags only, the ``sensor_msgs/msg/JointState`` topic (default the only one).
    joint_names: ROS bags only, the joints to read, in order (default those of
        the first message).
    rate: NPZ and CSV files without a time column: their sampling rate [Hz]
        (``t_k = k / rate``); an NPZ file without ``dq`` has it from central differences.

    Raises
    ------
    DataError: missing file, unknown format, a column map that does not fit
        the file, or data failing :class:`Dataset` validation.
    """
    if not isinstance(path, str | os.PathLike) or not str(path):
        raise DataError(f"a data path must be a non-empty str or os.PathLike, got {path!r}")
    path = Path(path).expanduser()
    check_data_path(path)
    fmt = infer_format(path) if format is None else str(format).lower()
    if fmt not in FORMATS:
        raise DataError(f"unknown data format {format!r}; expected one of {', '.join(FORMATS)}")
    if columns is not None and fmt != "csv":
        raise DataError(f"a column map applies to CSV files only, not to format {fmt!r}")
    if fmt == "npz":
        return load_npz(path, memory_budget(cap=MEMORY_BUDGET), rate)  # and half the free memory
    if fmt == "csv":
        return load_csv(path, columns, rate)
    if fmt == "rosbag":
        src = BagSource(path, topic, joint_names)
        try:
            return collect(
                iter_rows(src),
                src.layout,
                src.joint_names,
                {"source": str(path), "format": "rosbag"},
            )
        except DataError as exc:
            raise DataError(f"{path}: {exc}") from exc
    return load_panda_gaz2019(path)


def save_dataset(dataset: Dataset, path: str | Path, *, format: str | None = None) -> Path:
    """Write ``dataset`` as NPZ, CSV (default header) or a ROS 2 bag with MCAP storage.

    The data go to a temporary next to ``path``, renamed over it once
    complete: a crash never leaves a partial file. The format follows the
    suffix (``.npz``, ``.csv``, ``.mcap``) unless ``format`` is given
    (``"npz"``, ``"csv"``, ``"mcap"``). An MCAP bag is a rosbag2 folder
    (``metadata.yaml`` and one ``.mcap``) of ``sensor_msgs/msg/JointState``
    messages on ``/joint_states``, stamped with ``t`` (it does not carry ddq).
    Returns the path written.
    """
    if not isinstance(dataset, Dataset):
        raise DataError(f"save_dataset expects a Dataset, got {type(dataset).__name__}")
    src = MemorySource(dataset)
    return write_rows(
        lambda: src.chunks(1 << 15),
        dataset.n_samples,
        src.layout,
        dataset.joint_names,
        path,
        format,
    )


def output_format(path: Path, format: str | None) -> str:
    """``"npz"``, ``"csv"`` or ``"mcap"`` from ``format`` or the suffix of ``path``; a
    ``format`` that contradicts the path's own suffix (NPZ bytes into ``run.csv``) is
    refused with :class:`DataError`."""
    by_suffix = {".npz": "npz", ".csv": "csv", ".mcap": "mcap"}.get(path.suffix.lower())
    if format is not None and by_suffix is not None and format != by_suffix:
        raise DataError(
            f"cannot save to {path}: its suffix says {by_suffix} but the format asked is "
            f"{format!r}; name the file for its format (or leave the format out)"
        )
    fmt = format or by_suffix
    if fmt not in ("npz", "csv", "mcap"):
        raise DataError(
            f"cannot save to {path}: unknown format {format or path.suffix!r}; "
            "expected .npz, .csv or .mcap"
        )
    return fmt


def write_rows(blocks, n: int, layout: Layout, joint_names, path, format=None) -> Path:
    """Write packed row blocks (``blocks()`` returns a fresh iterator) to ``path``, atomically.

    ``format`` "mcap" on a path without the ``.mcap`` suffix writes a rosbag2 folder.
    """
    path = Path(path).expanduser()
    fmt = output_format(path, format)
    if fmt == "mcap" and path.suffix.lower() != ".mcap":
        return write_bag(path, blocks, layout, joint_names, bare=False)
    atomic_write(path, lambda tmp: write_rows_to(tmp, fmt, blocks, n, layout, joint_names))
    return path


def write_rows_to(tmp: Path, fmt: str, blocks, n: int, layout: Layout, joint_names) -> None:
    """Write packed row blocks to the file ``tmp`` (replaced) as ``fmt`` ("npz", "csv", "mcap").

    ``n`` rows in total (the NPZ headers need it); ``blocks()`` returns a fresh iterator.
    """
    tmp = Path(tmp)
    if fmt == "npz":
        with open(tmp, "wb") as fh:
            write_npz(fh, blocks, n, layout, joint_names)
    elif fmt == "csv":
        with open(tmp, "w") as fh:
            write_csv(fh, blocks(), layout, joint_names)
    elif fmt == "mcap":
        write_bag(tmp, blocks, layout, joint_names, bare=True)
    else:
        raise DataError(f"unknown output format {fmt!r}; expected npz, csv or mcap")
