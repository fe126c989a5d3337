"""Report folders: claimed atomically before the work, built aside, swapped into place.

Rules (issue 14):

- **Claimed atomically before the work** (:func:`claim_report`): the folder is created
  if missing and a claim file ``.manip-id-claim`` is created in it with ``O_EXCL``; of
  two concurrent runs into one folder exactly one gets the claim, the other gets
  :class:`~manip_id.errors.ReportBusyError`.
- **Never half-written**: the report is built in a temporary sibling folder
  (``.<name>.tmp-*``, registered for removal on signals, :meth:`ReportFolder.build`) and
  renamed into place at the end.
- **Only our own folders are replaced, unchanged** (issue 29): every report folder holds
  a manifest, ``.manip-id-report.json``, listing each file manip_id wrote with its size
  [bytes] and SHA-256. An existing non-empty folder is replaced only with ``force=True``,
  and only when every entry it holds is a regular file the manifest lists, of the listed
  size and hash; the first foreign, edited or non-file entry is named in the refusal and
  nothing is deleted. A manifest of an older manip-id (names without hashes) cannot prove
  the files unchanged: such a folder is refused, the message says to delete it by hand.
- **A file saved during the run survives** (issue 41): the check above is made when the
  folder is claimed; at the end only the entries that are still ours (the claim, the
  manifest, listed files of the listed size and hash) are deleted; anything that appeared
  or changed meanwhile is moved into the new folder and named in an
  :class:`~manip_id.errors.OutputWarning`.
- **A killed run's staging folder is named**: temporaries are called ``.NAME.tmp-PID-*``
  (``.NAME.old-PID-*`` while swapping); the next run into ``NAME`` names those whose
  process is gone (:func:`~.files.stale_temporaries`) and leaves them to the user.
- **A report path that is a symbolic link is refused** (never followed, never replaced):
  nothing is created, neither beside it nor in its target.

What a report holds is rendered by :mod:`manip_id.viz.report`; this module only
claims, stages and publishes the folder.
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import stat
import tempfile
import warnings
from collections.abc import Callable
from pathlib import Path

import psutil

from ..errors import (
    InputError,
    OutputError,
    OutputWarning,
    ReportBusyError,
    ReportExistsError,
)
from .files import (
    atomic_write_text,
    check_output_dir,
    json_text,
    register_temporary,
    temporary_prefix,
    unregister_temporary,
    warn_stale_temporaries,
)
from .reading import read_json

#: The package that writes the manifests (``written_by``).
PACKAGE = __name__.split(".")[0]
#: The manifest that marks a folder written by manip_id, and the claim of a run in progress.
MANIFEST, CLAIM = ".manip-id-report.json", ".manip-id-claim"


def file_digest(path: Path) -> str:
    """The SHA-256 of a file's bytes (hex), read in blocks of 1 MiB."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(2**20), b""):
            h.update(block)
    return h.hexdigest()


def _manifest_entries(path: Path) -> dict[str, tuple[int, str]]:
    """The files a report folder's manifest lists: name -> (size [bytes], sha256).

    Raises :class:`~manip_id.errors.OutputError` without a readable manifest of ours, or
    with an old one that lists names without hashes.
    """
    manifest = path / MANIFEST
    try:
        if not stat.S_ISREG(manifest.lstat().st_mode) or manifest.lstat().st_size > 2**20:
            raise ValueError("not a small regular file")
        data = read_json(manifest, f"report manifest {MANIFEST}", OutputError)
    except (OSError, ValueError, OutputError) as exc:
        raise OutputError(
            f"report folder {path} was not written by manip-id (no readable {MANIFEST}); "
            "--force only replaces folders manip-id wrote: remove it yourself or choose another"
        ) from exc
    files = data.get("files") if isinstance(data, dict) else None
    if not isinstance(data, dict) or data.get("written_by") != PACKAGE:
        raise OutputError(
            f"report folder {path} was not written by manip-id ({MANIFEST} is not ours); "
            "--force only replaces folders manip-id wrote: remove it yourself or choose another"
        )
    if isinstance(files, list):
        raise OutputError(
            f"report folder {path} was written by an older manip-id whose manifest has no "
            "checksums, so --force cannot tell your edits from ours: delete the folder "
            "yourself or choose another"
        )
    entries: dict[str, tuple[int, str]] = {}
    for name, item in (files or {}).items() if isinstance(files, dict) else ():
        size = item.get("size") if isinstance(item, dict) else None
        digest = item.get("sha256") if isinstance(item, dict) else None
        if (
            isinstance(size, int)
            and not isinstance(size, bool)
            and isinstance(digest, str)
            and re.fullmatch(r"[0-9a-f]{64}", digest)
        ):
            entries[name] = (size, digest)
    if not isinstance(files, dict) or len(entries) != len(files):
        raise OutputError(f"report folder {path}: {MANIFEST} is malformed; remove it yourself")
    return entries


def _check_own_entries(path: Path, names: list[str]) -> None:
    """Raise unless every entry ``names`` of ``path`` is a listed, unchanged regular file."""
    listed = _manifest_entries(path)
    for name in names:
        if name in (MANIFEST, CLAIM):
            continue
        entry = path / name
        try:
            info = entry.lstat()
        except OSError as exc:
            raise OutputError(f"cannot read {entry}: {exc.strerror}") from exc
        if name not in listed:
            reason = "is a file manip-id did not write"
        elif not stat.S_ISREG(info.st_mode):
            reason = "is not a regular file (manip-id writes only files)"
        elif info.st_size != listed[name][0] or file_digest(entry) != listed[name][1]:
            reason = "was changed since manip-id wrote it"
        else:
            continue
        raise OutputError(
            f"report folder {path}: {name} {reason}; --force will not delete it "
            "(move it away or choose another folder)"
        )


def _refuse_symlink(directory, what: str) -> None:
    """Raise if the path of the report folder is itself a symbolic link."""
    p = Path(os.fsdecode(directory)) if isinstance(directory, (str, bytes, os.PathLike)) else None
    if p is not None and p.is_symlink():
        raise OutputError(
            f"{what} {p} is a symbolic link; give the real folder ({os.path.realpath(p)}) "
            "or another path"
        )


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
    _refuse_symlink(directory, what)
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
    _check_own_entries(path, entries)
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
            tmp = Path(tempfile.mkdtemp(dir=self.path.parent, prefix=temporary_prefix(self.path)))
        except OSError as exc:
            raise OutputError(f"cannot create a folder beside {self.path}: {exc.strerror}") from exc
        register_temporary(tmp)
        try:
            os.chmod(tmp, 0o755)
            fill(tmp)
            files = {
                p.name: {"size": p.stat().st_size, "sha256": file_digest(p)}
                for p in sorted(tmp.iterdir())
            }
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
    warn_stale_temporaries(path)
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
    entries = sorted(p.name for p in path.iterdir() if p.name != CLAIM)
    if not entries:
        return
    if not force:
        raise ReportExistsError(path)
    _check_own_entries(path, entries)


def _swap(new: Path, target: Path) -> None:
    """Move the complete folder ``new`` to ``target``; of the old folder, delete only ours.

    The old folder is renamed aside (readers see the old report or the new one, never a
    mix), the new one renamed into place, and then the aside folder is emptied entry by
    entry: the claim, the manifest and the files the manifest lists, unchanged, are
    deleted; anything else (a file the user saved into the folder while this run worked,
    or edited) is moved back into ``target``, under its own name when the new report has
    none such, else as ``NAME.user-K``, and named in an :class:`~manip_id.errors.OutputWarning`.
    """
    if not target.exists():
        os.replace(new, target)
        return
    old = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.old-{os.getpid()}-"))
    old.rmdir()
    os.replace(target, old)
    try:
        os.replace(new, target)
    except BaseException:
        os.replace(old, target)
        raise
    _empty_aside(old, target)


def _empty_aside(old: Path, target: Path) -> None:
    """Delete our own entries of the aside folder ``old``; move the others into ``target``."""
    try:
        listed = _manifest_entries(old)
    except OutputError:  # a folder this run created holds no manifest: nothing but the claim
        listed = {}
    for _ in range(3):  # entries may still appear (a writer with the old folder open)
        for entry in sorted(old.iterdir()):
            name = entry.name
            info = entry.lstat()
            ours = name in (MANIFEST, CLAIM) or (
                name in listed
                and stat.S_ISREG(info.st_mode)
                and info.st_size == listed[name][0]
                and file_digest(entry) == listed[name][1]
            )
            if ours:
                entry.unlink()
                continue
            dest, k = target / name, 1
            while dest.exists() or dest.is_symlink():
                dest, k = target / f"{name}.user-{k}", k + 1
            os.rename(entry, dest)
            warnings.warn(
                f"{entry.name} appeared in {target} while manip-id was writing it (or was "
                f"changed): kept, as {dest}; the report's own files were replaced",
                OutputWarning,
                stacklevel=5,
            )
        try:
            old.rmdir()
            return
        except OSError:
            continue
    warnings.warn(
        f"the previous contents of {target} could not all be moved back: they are in {old}",
        OutputWarning,
        stacklevel=5,
    )
