"""Report folders: claimed atomically before the work, built aside, swapped into place.

Rules (issue 14):

- **Claimed atomically before the work** (:func:`claim_report`): the folder is created
  if missing and a claim file ``.manip-id-claim`` is created in it with ``O_EXCL``; of
  two concurrent runs into one folder exactly one gets the claim, the other gets
  :class:`~manip_id.errors.ReportBusyError`.
- **Never half-written**: the report is built in a temporary sibling folder
  (``.<name>.tmp-*``, registered for removal on signals, :meth:`ReportFolder.build`) and
  renamed into place at the end.
- **Only our own folders are replaced**: every report folder holds a manifest,
  ``.manip-id-report.json``, listing the files manip_id wrote. An existing non-empty
  folder is replaced only with ``force=True``, and only when it has a manifest and holds
  nothing the manifest does not list; anything else is refused, never deleted.

What a report holds is rendered by :mod:`manip_id.viz.report`; this module only
claims, stages and publishes the folder.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

import psutil

from ..errors import InputError, OutputError, ReportBusyError, ReportExistsError
from .files import (
    atomic_write_text,
    check_output_dir,
    json_text,
    register_temporary,
    unregister_temporary,
)

#: The package that writes the manifests (``written_by``).
PACKAGE = __name__.split(".")[0]
#: The manifest that marks a folder written by manip_id, and the claim of a run in progress.
MANIFEST, CLAIM = ".manip-id-report.json", ".manip-id-claim"


def _manifest_files(path: Path) -> set[str] | None:
    """The files a report folder's manifest lists, or None without a (readable) manifest."""
    try:
        data = json.loads((path / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("written_by") != PACKAGE:
        return None
    files = data.get("files")
    if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
        return None
    return set(files)


def check_report_target(directory, force: bool = False, *, inputs=(), what="report folder") -> Path:
    """Raise unless ``directory`` may receive a report; call it before the long work.

    Refused (:class:`~manip_id.errors.OutputError`): a file in the way, a missing
    parent, the current directory or an ancestor of it or of an input. A non-empty
    folder needs ``force`` (:class:`ReportExistsError`) and, even then, a manifest
    listing everything it holds (a folder manip_id did not write is never removed).
    A folder another run has claimed raises :class:`~manip_id.errors.ReportBusyError`.
    """
    try:
        path = check_output_dir(directory, inputs=inputs, what=what)
    except OutputError as exc:
        if "not a folder" in str(exc):
            raise OutputError(f"report folder {directory} exists and is not a folder") from exc
        raise
    if not path.is_dir():
        return path
    try:
        entries = sorted(p.name for p in path.iterdir())
    except OSError as exc:
        raise OutputError(f"cannot read the report folder {path}: {exc.strerror}") from exc
    if CLAIM in entries:
        raise ReportBusyError(_busy_message(path))
    if not entries:
        return path
    if not force:
        raise ReportExistsError(path)
    listed = _manifest_files(path)
    if listed is None:
        raise OutputError(
            f"report folder {path} was not written by manip-id (no {MANIFEST}); "
            "--force only replaces folders manip-id wrote: remove it yourself or choose another"
        )
    extra = [e for e in entries if e not in listed and e != MANIFEST]
    if extra:
        raise OutputError(
            f"report folder {path} holds files manip-id did not write ({', '.join(extra[:5])}"
            f"{', ...' if len(extra) > 5 else ''}); --force will not delete them"
        )
    return path


def _busy_message(path: Path) -> str:
    """Who holds the claim of ``path``: a running process, or a dead one (then: remove it)."""
    claim = path / CLAIM
    try:
        pid = int(claim.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        pid = None
    if pid is not None:
        if not psutil.pid_exists(pid):
            return (
                f"report folder {path} was claimed by manip-id process {pid}, which is no "
                f"longer running (killed?): remove {claim} and run again"
            )
        return f"report folder {path} is being written by another manip-id run (process {pid})"
    return (
        f"report folder {path} is being written by another manip-id run "
        f"(if none is running, remove {claim})"
    )


class ReportFolder:
    """A report folder claimed by this run: built by :meth:`write`, then :meth:`publish`-ed.

    Made by :func:`claim_report`. Until published, the target holds only the claim file
    (or its old manifest-listed contents); :meth:`discard` gives the folder back as it was.
    """

    def __init__(self, path: Path, force: bool, created: bool, claim: Path):
        self.path = path
        self.force = force
        self._created = created
        self._claim = claim
        self._tmp: Path | None = None

    def build(self, fill: Callable[[Path], object]) -> Path:
        """Build the report in a temporary sibling folder: ``fill(folder)`` writes its files.

        The manifest listing every file ``fill`` wrote is added here; on any error the
        temporary folder is removed. Published by :meth:`publish`; returns the target path.
        """
        if self._tmp is not None:
            raise InputError(f"report {self.path} was already written")
        try:
            tmp = Path(tempfile.mkdtemp(dir=self.path.parent, prefix=f".{self.path.name}.tmp-"))
        except OSError as exc:
            raise OutputError(f"cannot create a folder beside {self.path}: {exc.strerror}") from exc
        register_temporary(tmp)
        try:
            os.chmod(tmp, 0o755)
            fill(tmp)
            files = sorted(p.name for p in tmp.iterdir())
            atomic_write_text(tmp / MANIFEST, json_text({"written_by": PACKAGE, "files": files}))
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            unregister_temporary(tmp)
            raise
        self._tmp = tmp
        return self.path

    def publish(self) -> None:
        """Rename the built report into place (nothing is built: give the folder back)."""
        if self._tmp is None:
            self.discard()
            return
        tmp, self._tmp = self._tmp, None
        try:
            _swap(tmp, self.path)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            unregister_temporary(tmp)
            self.discard()
            raise
        unregister_temporary(tmp)
        unregister_temporary(self._claim)
        if self._created:
            unregister_temporary(self.path)

    def discard(self) -> None:
        """Remove the temporary build and the claim (and the folder if this run created it)."""
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            unregister_temporary(self._tmp)
            self._tmp = None
        if self._claim.exists():
            self._claim.unlink(missing_ok=True)
        unregister_temporary(self._claim)
        if self._created:
            try:
                self.path.rmdir()
            except OSError:
                pass
            unregister_temporary(self.path)


def claim_report(
    directory, *, force: bool = False, inputs=(), what="report folder"
) -> ReportFolder:
    """Check ``directory`` (:func:`check_report_target`) and claim it for this run.

    The claim is a file created with ``O_CREAT | O_EXCL`` in the folder (created here
    if missing): of two runs, exactly one succeeds; the other raises
    :class:`~manip_id.errors.ReportBusyError`.
    """
    path = check_report_target(directory, force, inputs=inputs, what=what)
    created = False
    try:
        path.mkdir()
        created = True
        register_temporary(path)
    except FileExistsError:
        pass
    except OSError as exc:
        raise OutputError(f"cannot create the report folder {path}: {exc.strerror}") from exc
    claim = path / CLAIM
    try:
        fd = os.open(claim, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    except FileExistsError as exc:
        raise ReportBusyError(_busy_message(path)) from exc
    except OSError as exc:
        if created:
            path.rmdir()
            unregister_temporary(path)
        raise OutputError(f"cannot write into the report folder {path}: {exc.strerror}") from exc
    register_temporary(claim)
    with os.fdopen(fd, "w") as fh:
        fh.write(f"{os.getpid()}\n")
    if not created:  # re-check under the claim: the folder may have changed meanwhile
        try:
            check_report_target_claimed(path, force)
        except BaseException:
            claim.unlink(missing_ok=True)
            unregister_temporary(claim)
            raise
    return ReportFolder(path, force, created, claim)


def check_report_target_claimed(path: Path, force: bool) -> None:
    """:func:`check_report_target`'s content rules on a folder that holds our claim."""
    entries = [p.name for p in path.iterdir() if p.name != CLAIM]
    if not entries:
        return
    if not force:
        raise ReportExistsError(path)
    listed = _manifest_files(path)
    if listed is None or any(e not in listed and e != MANIFEST for e in entries):
        raise OutputError(
            f"report folder {path} was not written by manip-id or holds other files; "
            "--force only replaces folders manip-id wrote"
        )


def _swap(new: Path, target: Path) -> None:
    """Move the complete folder ``new`` to ``target``, replacing it (renamed aside first)."""
    if not target.exists():
        os.replace(new, target)
        return
    old = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.old-"))
    old.rmdir()
    os.replace(target, old)
    try:
        os.replace(new, target)
    except BaseException:
        os.replace(old, target)
        raise
    shutil.rmtree(old, ignore_errors=True)
