"""Files written by the package: checked before the work, written to a temporary, renamed.

- **Checks before the work** (:func:`check_output_file`, :func:`check_output_dir`): the
  parent folder exists and takes a new file (proved by creating the temporary there), a
  file output is not a folder nor a special file, no output is one of the inputs (same
  resolved path, or same device and inode: hard and symbolic links), and a folder output
  is neither the current directory nor an ancestor of it or of an input.
- **Staged files** (:class:`StagedFile`, :func:`atomic_write`): every output is written to
  a temporary next to its target and renamed into place once complete.
- **A cleanup registry** (:func:`register_temporary`, :func:`remove_temporaries`): every
  temporary file or folder the package creates is registered until it is renamed into
  place, so that an interrupted command (SIGINT, SIGTERM) removes them all.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import stat
import tempfile
import threading
import warnings
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np
import psutil

from ..errors import OutputError, OutputWarning

# ------------------------------------------------------------ cleanup registry
_TEMPORARIES: dict[str, int] = {}  # path -> pid of the process that created it
_LOCK = threading.Lock()


def register_temporary(path) -> None:
    """Remember ``path`` (a file or a folder) for :func:`remove_temporaries`."""
    with _LOCK:
        _TEMPORARIES[os.fspath(path)] = os.getpid()


def unregister_temporary(path) -> None:
    """Forget ``path`` (it was renamed into place or removed)."""
    with _LOCK:
        _TEMPORARIES.pop(os.fspath(path), None)


def temporary_prefix(target: Path) -> str:
    """The name prefix of this process's temporaries beside ``target``: ``.NAME.tmp-PID-``.

    The process id in the name lets a later run tell the leftovers of a killed run
    (:func:`stale_temporaries`) from those of a run still working.
    """
    return f".{target.name}.tmp-{os.getpid()}-"


def stale_temporaries(target) -> list[Path]:
    """The temporaries beside ``target`` left by runs that are no longer alive.

    Those named ``.NAME.tmp-PID-*`` or ``.NAME.old-PID-*`` (:func:`temporary_prefix`) whose
    process ``PID`` does not exist: a run killed with SIGKILL (or a power cut) cannot
    remove its staging folder, so the next run into ``target`` names it (it deletes
    nothing: the folder may hold the only copy of an hour's work).
    """
    target = Path(target)
    pattern = re.compile(rf"\.{re.escape(target.name)}\.(?:tmp|old)-(\d+)-")
    try:
        names = os.listdir(target.parent)
    except OSError:
        return []
    stale = []
    for name in sorted(names):
        m = pattern.match(name)
        if m and int(m.group(1)) != os.getpid() and not psutil.pid_exists(int(m.group(1))):
            stale.append(target.parent / name)
    return stale


def warn_stale_temporaries(target) -> None:
    """An :class:`~manip_id.errors.OutputWarning` naming each of :func:`stale_temporaries`."""
    for p in stale_temporaries(target):
        pid = p.name.split("-")[1]
        warnings.warn(
            f"{p} was left by an earlier manip-id run (process {pid}) that was killed before "
            f"it finished; nothing uses it: look inside, then remove it (rm -r '{p}')",
            OutputWarning,
            stacklevel=3,
        )


def remove_temporaries() -> list[str]:
    """Remove every registered temporary of this process; returns the paths removed.

    Safe to call from a signal handler's aftermath; a forked child never removes its
    parent's temporaries (each entry remembers the pid that created it).
    """
    pid = os.getpid()
    with _LOCK:
        mine = [p for p, owner in _TEMPORARIES.items() if owner == pid]
        for p in mine:
            _TEMPORARIES.pop(p, None)
    removed = []
    for p in mine:
        try:
            if os.path.isdir(p) and not os.path.islink(p):
                shutil.rmtree(p, ignore_errors=True)
            else:
                os.unlink(p)
            removed.append(p)
        except FileNotFoundError:
            pass
        except OSError:  # pragma: no cover - best effort on the way out
            pass
    return removed


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


# ------------------------------------------------------------------- checks
def _stat(path: Path) -> os.stat_result | None:
    try:
        return os.stat(path)
    except OSError:
        return None


def same_file(a: Path, b: Path) -> bool:
    if a.resolve() == b.resolve():
        return True
    sa, sb = _stat(a), _stat(b)
    return sa is not None and sb is not None and (sa.st_dev, sa.st_ino) == (sb.st_dev, sb.st_ino)


def is_ancestor(folder: Path, path: Path) -> bool:
    """True if ``folder`` is ``path`` or contains it (resolved paths)."""
    f, p = folder.resolve(), path.resolve()
    return f == p or f in p.parents


def as_path(path, what: str) -> Path:
    if isinstance(path, bytes):
        raise OutputError(f"{what} must be a path given as text, got bytes")
    try:
        p = Path(path)
    except TypeError as exc:
        raise OutputError(f"{what} must be a path, got {type(path).__name__}") from exc
    if not str(p) or str(path) == "" or "\x00" in str(p):
        raise OutputError(f"{what} must be a non-empty path without NUL bytes, got {str(path)!r}")
    return p


def _check_parent(p: Path, what: str) -> Path:
    parent = p.parent
    if not parent.exists():
        raise OutputError(f"{what} {p}: the folder {parent} does not exist")
    if not parent.is_dir():
        raise OutputError(f"{what} {p}: {parent} is not a folder")
    return parent


def _check_not_input(p: Path, inputs: Iterable, what: str) -> None:
    for item in inputs:
        if item is None:
            continue
        src = Path(item)
        if same_file(p, src):
            raise OutputError(f"{what} {p} is one of the inputs ({src}); choose another path")
        if src.is_dir() and is_ancestor(src, p):
            # an input folder (a log of several files) owns every file in it
            raise OutputError(
                f"{what} {p} is inside the input folder {src}; choose a path outside it"
            )


def _without_os_errors(check: Callable[..., Path], path, inputs: Iterable, what: str) -> Path:
    """``check(path, inputs=inputs, what=what)`` with operating-system errors as OutputErrors."""
    try:
        return check(path, inputs=inputs, what=what)
    except OSError as exc:
        raise OutputError(f"{what} {path}: {exc.strerror or exc}") from exc


def check_output_file(path, *, inputs: Iterable = (), what: str = "output") -> Path:
    """Raise :class:`~manip_id.errors.OutputError` unless a file can be written at ``path``.

    Refused: an existing folder or special file (device, FIFO, socket, ``/proc``), a
    parent that is missing or not a folder, and any of ``inputs`` (same resolved path,
    or same device and inode). Writability is proved by :class:`OutputSet`, which creates
    the temporary at once.
    Operating-system errors (a name too long, a loop of links) are OutputErrors too.
    """
    return _without_os_errors(_check_output_file, path, inputs, what)


def _check_output_file(path, *, inputs: Iterable = (), what: str = "output") -> Path:
    """The checks of :func:`check_output_file` (operating-system errors pass up)."""
    p = as_path(path, what)
    st = _stat(p)
    if st is not None:
        if stat.S_ISDIR(st.st_mode):
            raise OutputError(f"{what} {p} is a folder; give a file name")
        if not stat.S_ISREG(st.st_mode):
            raise OutputError(f"{what} {p} exists and is not a regular file")
    _check_parent(p, what)
    _check_not_input(p, inputs, what)
    return p


def check_output_dir(path, *, inputs: Iterable = (), what: str = "output folder") -> Path:
    """Raise :class:`~manip_id.errors.OutputError` unless a folder may be written at ``path``.

    Refused: an existing file, a missing parent, the current directory or an ancestor
    of it, and a folder that is or contains one of ``inputs``.
    Operating-system errors (a name too long, a loop of links) are OutputErrors too.
    """
    return _without_os_errors(_check_output_dir, path, inputs, what)


def _check_output_dir(path, *, inputs: Iterable = (), what: str = "output folder") -> Path:
    """The checks of :func:`check_output_dir` (operating-system errors pass up)."""
    p = as_path(path, what)
    if p.exists() and not p.is_dir():
        raise OutputError(f"{what} {p} exists and is not a folder")
    if is_ancestor(p, Path.cwd()):
        raise OutputError(
            f"{what} {p} is the current directory or one of its ancestors; give a new folder"
        )
    _check_parent(p, what)
    for item in inputs:
        if item is None:
            continue
        src = Path(item)
        if is_ancestor(p, src) or same_file(p, src):
            raise OutputError(f"{what} {p} holds the input {src}; give another folder")
    return p


class StagedFile:
    """A file output whose temporary exists from the moment the output is checked."""

    def __init__(self, path, *, inputs: Iterable = (), what: str = "output"):
        self.path = check_output_file(path, inputs=inputs, what=what)
        warn_stale_temporaries(self.path)
        try:
            fd, name = tempfile.mkstemp(
                dir=self.path.parent,
                prefix=temporary_prefix(self.path),
                suffix=self.path.suffix or ".tmp",
            )
        except OSError as exc:
            raise OutputError(
                f"{what} {self.path}: cannot create a file in {self.path.parent} "
                f"({exc.strerror or exc})"
            ) from exc
        os.close(fd)
        self.tmp = Path(name)
        register_temporary(self.tmp)
        self.written = False

    def write(self, write: Callable[[Path], object]) -> None:
        """Call ``write(tmp)`` to fill the temporary."""
        try:
            write(self.tmp)
        except OSError as exc:
            raise OutputError(f"cannot write {self.path}: {exc.strerror or exc}") from exc
        self.written = True

    def write_text(self, text: str) -> None:
        """UTF-8; undecodable bytes of file names (surrogates) are written as ``\udcff``."""
        self.write(lambda tmp: tmp.write_text(text, encoding="utf-8", errors="backslashreplace"))

    def publish(self) -> None:
        if not self.written:
            self.discard()
            return
        try:
            os.chmod(self.tmp, 0o666 & ~_umask())
            os.replace(self.tmp, self.path)
        except OSError as exc:
            self.discard()
            raise OutputError(f"cannot write {self.path}: {exc.strerror or exc}") from exc
        unregister_temporary(self.tmp)

    def discard(self) -> None:
        self.tmp.unlink(missing_ok=True)
        unregister_temporary(self.tmp)


# ---------------------------------------------------------- atomic writers
def atomic_write(path, write: Callable[[Path], object]) -> Path:
    """Call ``write(tmp)`` on a temporary file next to ``path``, then rename it to ``path``.

    The file gets the usual permissions (0666 minus the umask); on any error
    the temporary file is removed and ``path`` is left as it was. Missing parent
    folders are created. A folder or a special file at ``path`` is an
    :class:`~manip_id.errors.OutputError`, as is any operating-system error.
    """
    path = as_path(path, "output")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(
            f"cannot create the folder {path.parent} for {path}: {exc.strerror or exc}"
        ) from exc
    staged = StagedFile(path)
    try:
        staged.write(write)
        staged.publish()
    except BaseException:
        staged.discard()
        raise
    return path


def atomic_write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    return atomic_write(
        path, lambda tmp: tmp.write_text(text, encoding="utf-8", errors="backslashreplace")
    )


def jsonable(obj):
    """``json.dumps`` default: numpy arrays and scalars, paths."""
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serializable: {type(obj).__name__}")


def json_text(obj) -> str:
    """``obj`` as indented JSON text (numpy arrays become lists)."""
    return json.dumps(obj, indent=2, default=jsonable) + "\n"


def write_json(path, obj) -> Path:
    """Write ``obj`` as indented JSON atomically."""
    return atomic_write_text(path, json_text(obj))
