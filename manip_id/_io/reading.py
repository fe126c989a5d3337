"""The one door for every file the package reads: checked by ``stat`` before it is read.

Data logs (CSV, NPZ, ROS 2 bags), URDF files, JSON (results, sidecars, thresholds, robot
settings) and TOML (profiles) all pass :func:`check_readable` before anything opens them:

- the path must name a **regular file** (a FIFO would block the read forever, a device
  such as ``/dev/zero`` would never end, a folder is no file): anything else is refused
  with one line naming the path and what it is;
- its size must be within the **budget of its kind** (:data:`READ_BUDGET`, bytes), checked
  before one byte is read, so that a 10 GB "JSON" file is refused rather than read.

:func:`read_text`, :func:`read_json` and :func:`read_toml` then read the file through a
descriptor opened with ``O_NONBLOCK`` and checked again with ``fstat`` (a path swapped
for a FIFO between the ``stat`` and the ``open`` is still refused), and turn every
decoding failure (bytes that are not UTF-8, a JSON or TOML syntax error, nesting deeper
than :data:`MAX_DEPTH`) into one :class:`~manip_id.errors.DataError` line (or the class
the caller names).
"""

from __future__ import annotations

import json
import os
import stat
import sys
from pathlib import Path
from typing import Any

from ..errors import DataError, ManipIdError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10 (the tomli backport is a dependency there)
    import tomli as tomllib

_MB = 1 << 20

#: Size budget per kind of file [bytes]: checked by ``stat`` before the file is read.
READ_BUDGET: dict[str, int] = {
    "json": 64 * _MB,  # results, sidecars, thresholds, settings
    "toml": 4 * _MB,  # profiles
    "urdf": 256 * _MB,  # robot descriptions (meshes are separate files)
    "data": 1 << 40,  # logs: read in row blocks, so only a sanity bound (1 TiB)
}

#: Deepest nesting of lists and objects accepted in a JSON or TOML input (a result file
#: nests 3 deep; anything deeper than this is no file of ours).
MAX_DEPTH = 32


def _kind_of(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _check_stat(st: os.stat_result, path, what: str, kind: str, error: type[ManipIdError]) -> None:
    if not stat.S_ISREG(st.st_mode):
        raise error(f"{what} {path} is {_kind_of(st.st_mode)}, not a regular file")
    budget = READ_BUDGET[kind]
    if st.st_size > budget:
        raise error(
            f"{what} {path} holds {st.st_size} bytes, more than the {budget} bytes a "
            f"{kind} input may hold"
        )


def check_readable(
    path, what: str = "file", kind: str = "data", error: type[ManipIdError] = DataError
) -> Path:
    """``path`` as a :class:`~pathlib.Path` once ``stat`` shows a regular file within budget.

    Parameters
    ----------
    path : str or os.PathLike
        The file to be read (symbolic links are followed).
    what : str
        What the file is, for the messages (``"result file"``, ``"URDF"``).
    kind : str
        A key of :data:`READ_BUDGET`: ``"json"``, ``"toml"``, ``"urdf"`` or ``"data"``.
    error : type
        The :class:`~manip_id.errors.ManipIdError` subclass raised.
    """
    p = Path(path)
    try:
        st = os.stat(p)
    except FileNotFoundError as exc:
        raise error(f"cannot read {what} {p}: no such file") from exc
    except (OSError, ValueError) as exc:
        raise error(f"cannot read {what} {p}: {exc}") from exc
    _check_stat(st, p, what, kind, error)
    return p


def check_data_path(path) -> Path:
    """A data path: a folder (a ROS 2 bag, a Panda log folder) or a regular file within
    the data budget (:func:`check_readable`); :class:`~manip_id.errors.DataError` otherwise."""
    p = Path(path)
    try:
        if stat.S_ISDIR(os.stat(p).st_mode):
            return p
    except FileNotFoundError as exc:
        raise DataError(f"no such data file or folder: {p}") from exc
    except (OSError, ValueError) as exc:
        raise DataError(f"cannot read data file {p}: {exc}") from exc
    return check_readable(p, "data file", "data")


def read_bytes(
    path, what: str = "file", kind: str = "json", error: type[ManipIdError] = DataError
) -> bytes:
    """The bytes of a regular file within the budget of ``kind`` (see :func:`check_readable`)."""
    p = check_readable(path, what, kind, error)
    try:
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as exc:
        raise error(f"cannot read {what} {p}: {exc.strerror or exc}") from exc
    try:
        _check_stat(os.fstat(fd), p, what, kind, error)  # the file opened is the one checked
        with os.fdopen(fd, "rb") as fh:
            fd = -1
            data = fh.read(READ_BUDGET[kind] + 1)
    except OSError as exc:
        raise error(f"cannot read {what} {p}: {exc.strerror or exc}") from exc
    finally:
        if fd >= 0:
            os.close(fd)
    if len(data) > READ_BUDGET[kind]:  # grew after the stat
        raise error(f"{what} {p} is larger than the {READ_BUDGET[kind]} bytes of a {kind} input")
    return data


def read_text(
    path, what: str = "file", kind: str = "json", error: type[ManipIdError] = DataError
) -> str:
    """The UTF-8 text of a regular file; bytes that are not UTF-8 as one ``error`` line."""
    data = read_bytes(path, what, kind, error)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{what} {path} is not UTF-8 text (byte {exc.start})") from exc


def nesting_depth(value: Any) -> int:
    """The deepest nesting of lists and dicts in a parsed document (iterative: no recursion)."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict):
            children = list(item.values())
        elif isinstance(item, list):
            children = item
        else:
            continue
        deepest = max(deepest, depth)
        if depth > MAX_DEPTH:
            return depth
        stack.extend((c, depth + 1) for c in children)
    return deepest


def _check_depth(doc: Any, path, what: str, error: type[ManipIdError]) -> None:
    if nesting_depth(doc) > MAX_DEPTH:
        raise error(f"{what} {path} nests deeper than {MAX_DEPTH} levels")


def read_json(path, what: str = "JSON file", error: type[ManipIdError] = DataError) -> Any:
    """The parsed JSON of a regular file (see :func:`check_readable`), syntax errors and
    nesting deeper than :data:`MAX_DEPTH` as one ``error`` line."""
    text = read_text(path, what, "json", error)
    try:
        doc = json.loads(text)
    except RecursionError as exc:
        raise error(f"{what} {path} nests deeper than {MAX_DEPTH} levels") from exc
    except ValueError as exc:
        raise error(f"cannot read {what} {path} as JSON: {exc}") from exc
    _check_depth(doc, path, what, error)
    return doc


def read_toml(path, what: str = "TOML file", error: type[ManipIdError] = DataError) -> dict:
    """The parsed TOML of a regular file, syntax errors and deep nesting as one ``error`` line."""
    text = read_text(path, what, "toml", error)
    try:
        doc = tomllib.loads(text)
    except RecursionError as exc:
        raise error(f"{what} {path} nests deeper than {MAX_DEPTH} levels") from exc
    except (tomllib.TOMLDecodeError, ValueError) as exc:
        raise error(f"cannot read {what} {path} as TOML: {exc}") from exc
    _check_depth(doc, path, what, error)
    return doc
