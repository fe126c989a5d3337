"""The outputs of one command: checked at once, published together, or none at all."""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import ClassVar, Protocol

from ..errors import OutputError
from .files import StagedFile, as_path, is_ancestor, json_text, same_file
from .report_folder import ReportFolder, claim_report


# -------------------------------------------------------------- publishing
class Pending(Protocol):
    """An output staged in a temporary: published by renaming, or discarded."""

    def publish(self) -> None: ...

    def discard(self) -> None: ...


class OutputSet:
    """The outputs of one command: checked at once, published together, or none at all.

    >>> with OutputSet(inputs=[data_path]) as out:     # doctest: +SKIP
    ...     js = out.file(json_path, "--json")          # checked now, before the work
    ...     rep = out.report(report_dir, "--report", force=False)
    ...     ...                                          # the work
    ...     out.write_json(json_path, result)
    ...     write_report(rep, ReportContent(title=..., ...))
    ...     out.publish()                                # every output appears now

    Leaving the ``with`` block without :meth:`publish` (an exception, a signal)
    discards every temporary.
    """

    #: Called before anything is published (process-wide, set by the command line's
    #: ``main``): raises when a termination signal arrived whose exception was swallowed
    #: (one delivered inside a weakref callback or a ``__del__`` is printed and ignored by
    #: Python), so that a terminated run publishes nothing. None: no check.
    before_publish: ClassVar[Callable[[], None] | None] = None

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
            if same_file(other, path) or is_ancestor(other, path) or is_ancestor(path, other):
                raise OutputError(f"{what} {path} collides with another output ({other})")

    def file(self, path, what: str = "output") -> Path:
        """Check and reserve a file output (its temporary is created now)."""
        p = as_path(path, what)
        self._check_distinct(p, what)
        staged = StagedFile(p, inputs=self.inputs, what=what)
        self._files[p] = staged
        self._items.append(staged)
        return p

    def report(self, directory, what: str = "--report", force: bool = False) -> ReportFolder:
        """Check and claim a report folder (:func:`.claim_report`)."""
        p = as_path(directory, what)
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
        check = OutputSet.before_publish
        if check is not None:
            try:
                check()
            except BaseException:
                self.discard()
                raise
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
    held = {getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n)}
    if not hasattr(signal, "pthread_sigmask"):  # pragma: no cover - not POSIX
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
