"""The real Franka Emika Panda excitation log (Gaz et al., RA-L 2019), read whole (4 MB)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._io.reading import check_readable
from ..errors import DataError
from .core import Dataset

PANDA_FILES = {
    "t": "rbt_log_time.txt",
    "q": "rbt_log_positions.txt",
    "dq": "rbt_log_velocity.txt",
    "tau": "rbt_log_torques.txt",
}
PANDA_JOINTS: tuple[str, ...] = tuple(f"panda_joint{i}" for i in range(1, 8))


def is_panda_log(path: Path) -> bool:
    """Whether the folder ``path`` holds the four files of the Panda log."""
    return path.is_dir() and all((path / f).is_file() for f in PANDA_FILES.values())


def _build(path, **kwargs) -> Dataset:
    try:
        return Dataset(**kwargs, meta={"source": str(path)})
    except DataError as exc:
        raise DataError(f"{path}: {exc}") from exc


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
    for name, fname in PANDA_FILES.items():
        f = folder / fname
        if not f.exists():
            raise DataError(f"the Panda log folder {folder} lacks {fname}")
        check_readable(f, "Panda log file", "data")
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
                f"{folder / PANDA_FILES[name]} has {size} values but 7 x {n} time stamps "
                f"= {7 * n} were expected"
            )
        arrays[name] = arrays[name].reshape(n, 7)
    ds = _build(folder, joint_names=PANDA_JOINTS, **arrays)
    ds.meta["format"] = "panda_gaz2019"
    return ds
