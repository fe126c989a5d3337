"""File output shared by the package: checked before the work, published together at the end.

Three mechanisms, used by every command and by the API writers:

- **Checks before the work** (:func:`check_output_file`, :func:`check_output_dir`): the
  parent folder exists and takes a new file (proved by creating the temporary there), a
  file output is not a folder nor a special file, no output is one of the inputs (same
  resolved path, or same device and inode: hard and symbolic links), and a folder output
  is neither the current directory nor an ancestor of it or of an input.
- **Publication together** (:class:`OutputSet`): every output is written to a temporary
  next to its target; :meth:`OutputSet.publish` renames them all into place once all are
  complete; :meth:`OutputSet.discard` (also on any exception) removes them.
- **A cleanup registry** (:func:`register_temporary`, :func:`remove_temporaries`): every
  temporary file or folder the package creates is registered until it is renamed into
  place, so that an interrupted command (SIGINT, SIGTERM) removes them all.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import stat
import tempfile
import threading
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Protocol

import numpy as np

from .errors import OutputError

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


def _same_file(a: Path, b: Path) -> bool:
    if a.resolve() == b.resolve():
        return True
    sa, sb = _stat(a), _stat(b)
    return sa is not None and sb is not None and (sa.st_dev, sa.st_ino) == (sb.st_dev, sb.st_ino)


def _is_ancestor(folder: Path, path: Path) -> bool:
    """True if ``folder`` is ``path`` or contains it (resolved paths)."""
    f, p = folder.resolve(), path.resolve()
    return f == p or f in p.parents


def _as_path(path, what: str) -> Path:
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
        if _same_file(p, src):
            raise OutputError(f"{what} {p} is one of the inputs ({src}); choose another path")
        if src.is_dir() and _is_ancestor(src, p):
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
    p = _as_path(path, what)
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
    p = _as_path(path, what)
    if p.exists() and not p.is_dir():
        raise OutputError(f"{what} {p} exists and is not a folder")
    if _is_ancestor(p, Path.cwd()):
        raise OutputError(
            f"{what} {p} is the current directory or one of its ancestors; give a new folder"
        )
    _check_parent(p, what)
    for item in inputs:
        if item is None:
            continue
        src = Path(item)
        if _is_ancestor(p, src) or _same_file(p, src):
            raise OutputError(f"{what} {p} holds the input {src}; give another folder")
    return p


# -------------------------------------------------------------- publishing
class Pending(Protocol):
    """An output staged in a temporary: published by renaming, or discarded."""

    def publish(self) -> None: ...

    def discard(self) -> None: ...


class StagedFile:
    """A file output whose temporary exists from the moment the output is checked."""

    def __init__(self, path, *, inputs: Iterable = (), what: str = "output"):
        self.path = check_output_file(path, inputs=inputs, what=what)
        try:
            fd, name = tempfile.mkstemp(
                dir=self.path.parent,
                prefix=f".{self.path.name}.",
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


class OutputSet:
    """The outputs of one command: checked at once, published together, or none at all.

    >>> with OutputSet(inputs=[data_path]) as out:     # doctest: +SKIP
    ...     js = out.file(json_path, "--json")          # checked now, before the work
    ...     rep = out.report(report_dir, "--report", force=False)
    ...     ...                                          # the work
    ...     out.write_json(json_path, result)
    ...     rep.write(title=..., ...)
    ...     out.publish()                                # every output appears now

    Leaving the ``with`` block without :meth:`publish` (an exception, a signal)
    discards every temporary.
    """

    def __init__(self, inputs: Iterable = ()):
        self.inputs = [Path(p) for p in inputs if p is not None]
        self._items: list[Pending] = []
        self._files: dict[Path, StagedFile] = {}
        self.published = False

    def add_inputs(self, inputs: Iterable) -> None:
        """More input paths to protect (checked by the outputs reserved afterwards)."""
        self.inputs += [Path(p) for p in inputs if p is not None]

    def _check_distinct(self, path: Path, what: str) -> None:
        for other in self._files:
            if _same_file(other, path) or _is_ancestor(other, path) or _is_ancestor(path, other):
                raise OutputError(f"{what} {path} collides with another output ({other})")

    def file(self, path, what: str = "output") -> Path:
        """Check and reserve a file output (its temporary is created now)."""
        p = _as_path(path, what)
        self._check_distinct(p, what)
        staged = StagedFile(p, inputs=self.inputs, what=what)
        self._files[p] = staged
        self._items.append(staged)
        return p

    def report(self, directory, what: str = "--report", force: bool = False):
        """Check and claim a report folder (see :func:`manip_id.viz.report.claim_report`)."""
        from .viz.report import claim_report

        p = _as_path(directory, what)
        self._check_distinct(p, what)
        claim = claim_report(p, force=force, inputs=self.inputs, what=what)
        self._files[p] = claim  # type: ignore[assignment]
        self._items.append(claim)
        return claim

    def add(self, pending: Pending) -> None:
        """Publish or discard ``pending`` with the others."""
        self._items.append(pending)

    def _staged(self, path) -> StagedFile:
        staged = self._files.get(Path(path))
        if not isinstance(staged, StagedFile):
            raise OutputError(f"output {path} was not reserved before the work")
        return staged

    def write(self, path, write: Callable[[Path], object]) -> None:
        self._staged(path).write(write)

    def write_text(self, path, text: str) -> None:
        self._staged(path).write_text(text)

    def write_json(self, path, obj) -> None:
        self._staged(path).write_text(json_text(obj))

    def publish(self) -> None:
        """Rename every complete output into place (in the order they were reserved).

        SIGINT, SIGTERM and SIGHUP are held back during the renames (they take effect
        right after), so an interrupt never publishes half of the outputs.
        """
        with _signals_held():
            try:
                for item in self._items:
                    item.publish()
            except BaseException:
                self.discard()
                raise
            self.published = True
            self._items = []

    def discard(self) -> None:
        """Remove every temporary not yet published."""
        for item in self._items:
            try:
                item.discard()
            except OSError:  # pragma: no cover - best effort
                pass
        self._items = []

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.discard()


@contextlib.contextmanager
def _signals_held():
    """Block SIGINT, SIGTERM and SIGHUP in this thread meanwhile (POSIX; else nothing)."""
    import signal

    held = {getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n)}
    if not hasattr(signal, "pthread_sigmask"):  # pragma: no cover - not POSIX
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


# ---------------------------------------------------------- atomic writers
def atomic_write(path, write: Callable[[Path], object]) -> Path:
    """Call ``write(tmp)`` on a temporary file next to ``path``, then rename it to ``path``.

    The file gets the usual permissions (0666 minus the umask); on any error
    the temporary file is removed and ``path`` is left as it was. Missing parent
    folders are created. A folder or a special file at ``path`` is an
    :class:`~manip_id.errors.OutputError`, as is any operating-system error.
    """
    path = _as_path(path, "output")
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
