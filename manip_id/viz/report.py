"""A report folder: result.json, PNG figures, scene.html and an index.html that shows them.

Rules (issue 14):

- **Claimed atomically before the work** (:func:`claim_report`): the folder is created
  if missing and a claim file ``.manip-id-claim`` is created in it with ``O_EXCL``; of
  two concurrent runs into one folder exactly one gets the claim, the other gets
  :class:`~manip_id.errors.ReportBusyError`.
- **Never half-written**: the report is built in a temporary sibling folder
  (``.<name>.tmp-*``, registered for removal on signals) and renamed into place at the end.
- **Only our own folders are replaced**: every report folder holds a manifest,
  ``.manip-id-report.json``, listing the files manip_id wrote. An existing non-empty
  folder is replaced only with ``force=True``, and only when it has a manifest and holds
  nothing the manifest does not list; anything else is refused, never deleted.
"""

from __future__ import annotations

import html as html_lib
import os
import shutil
import tempfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from .. import __name__ as _package
from .._io import (
    atomic_write_text,
    check_output_dir,
    json_text,
    register_temporary,
    unregister_temporary,
)
from ..errors import InputError, OutputError, ReportBusyError

INDEX, RESULT, SCENE = "index.html", "result.json", "scene.html"
#: The manifest that marks a folder written by manip_id, and the claim of a run in progress.
MANIFEST, CLAIM = ".manip-id-report.json", ".manip-id-claim"


class ReportExistsError(InputError):
    """The report folder exists and is not empty, and ``force`` was not given."""


def _manifest_files(path: Path) -> set[str] | None:
    """The files a report folder's manifest lists, or None without a (readable) manifest."""
    import json

    try:
        data = json.loads((path / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("written_by") != _package:
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
        raise ReportExistsError(
            f"report folder {path} exists and is not empty (use --force / force=True to replace it)"
        )
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
        import psutil

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

    def write(self, **content) -> Path:
        """Build the report in a temporary sibling folder (arguments of :func:`write_report`)."""
        if self._tmp is not None:
            raise InputError(f"report {self.path} was already written")
        self._tmp = _build(self.path, **content)
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
        raise ReportExistsError(
            f"report folder {path} exists and is not empty (use --force / force=True to replace it)"
        )
    listed = _manifest_files(path)
    if listed is None or any(e not in listed and e != MANIFEST for e in entries):
        raise OutputError(
            f"report folder {path} was not written by manip-id or holds other files; "
            "--force only replaces folders manip-id wrote"
        )


def _cell(value) -> str:
    if isinstance(value, float | np.floating):
        return "n/a" if not np.isfinite(value) else f"{float(value):.6g}"
    if value is None:
        return "n/a"
    return html_lib.escape(str(value))


def _table(rows: Sequence[Mapping], empty: str = "(no parameters)") -> str:
    """An HTML table; keys starting with ``_`` are not columns: ``_class`` is the row's
    CSS class (``"bad"`` rows are highlighted)."""
    if not rows:
        return f"<p>{html_lib.escape(empty)}</p>"
    cols: list[str] = []
    for row in rows:
        cols += [c for c in row if c not in cols and not str(c).startswith("_")]
    head = "".join(f"<th>{html_lib.escape(str(c))}</th>" for c in cols)
    body = "\n".join(
        (f'<tr class="{html_lib.escape(str(row["_class"]))}">' if row.get("_class") else "<tr>")
        + "".join(f"<td>{_cell(row.get(c))}</td>" for c in cols)
        + "</tr>"
        for row in rows
    )
    return f"<table>\n<tr>{head}</tr>\n{body}\n</table>"


def _summary(summary: Mapping) -> str:
    items = "\n".join(
        f"<tr><th>{html_lib.escape(str(k))}</th><td>{_cell(v)}</td></tr>"
        for k, v in summary.items()
    )
    return f'<table class="summary">\n{items}\n</table>'


def _index(
    title: str, summary: Mapping, rows, figures: list[str], scene: bool, notes, tables=None
) -> str:
    figs = "\n".join(
        f'<figure><img src="{html_lib.escape(f)}" alt="{html_lib.escape(Path(f).stem)}">'
        f"<figcaption>{html_lib.escape(Path(f).stem.replace('_', ' '))}</figcaption></figure>"
        for f in figures
    )
    scene_html = (
        f'<h2>Robot</h2>\n<p><a href="{SCENE}">open the scene on its own</a> '
        "(Animations panel: play, pause, time slider)</p>\n"
        f'<iframe src="{SCENE}" title="robot scene"></iframe>'
        if scene
        else ""
    )
    note_html = "".join(f"<li>{html_lib.escape(str(n))}</li>" for n in notes)
    extra = "\n".join(
        f"<h2>{html_lib.escape(str(name))}</h2>\n{_table(t, '(none)')}"
        for name, t in (tables or {}).items()
    )
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>{html_lib.escape(title)}</title>
<style>
body {{ font-family: sans-serif; margin: 1.5em; max-width: 1200px; }}
table {{ border-collapse: collapse; font-size: 0.85em; margin-bottom: 1em; }}
th, td {{ border: 1px solid #ccc; padding: 2px 6px; text-align: left; }}
table.summary th {{ background: #f3f3f3; }}
figure {{ margin: 0 0 1.5em 0; }} img {{ max-width: 100%; border: 1px solid #ddd; }}
iframe {{ width: 100%; height: 600px; border: 1px solid #ddd; }}
tr.bad td {{ background: #fde2dd; }} tr.warn td {{ background: #fff4cc; }}
td {{ white-space: nowrap; }} td:last-child {{ white-space: normal; }}
</style></head>
<body>
<h1>{html_lib.escape(title)}</h1>
<h2>Summary</h2>
{_summary(summary)}
{f"<ul>{note_html}</ul>" if note_html else ""}
{scene_html}
<h2>Figures</h2>
{figs or "<p>(no figures)</p>"}
<h2>Parameters</h2>
{_table(rows)}
{extra}
<p><a href="{RESULT}">{RESULT}</a>: the full result.</p>
</body></html>
"""


def write_report(
    directory,
    *,
    title: str,
    summary: Mapping,
    parameter_table: Sequence[Mapping],
    figures: Mapping[str, Callable[[Path], object] | str | os.PathLike],
    scene=None,
    json_result=None,
    notes: Sequence[str] = (),
    force: bool = False,
    inputs: Sequence = (),
    tables: Mapping[str, Sequence[Mapping]] | None = None,
) -> Path:
    """Write a report folder and return its path.

    directory: the report folder (created; see the module docstring for overwriting).
    title: page title; summary: name -> value pairs shown first;
    parameter_table: rows (dicts, same keys) of the parameter table;
    figures: name -> a callable that writes a PNG to the path it is given, or
        the path of an existing PNG (copied); saved as ``<name>.png``;
    scene: a :class:`~manip_id.viz.meshcat_scene.RobotScene` or its HTML as a string;
    json_result: written to result.json (default: ``{"summary", "parameters"}``);
    notes: lines shown under the summary;
    tables: more sections after the parameters, title -> rows (as ``parameter_table``;
        a row's ``_class`` key, e.g. ``"bad"``, highlights it);
    inputs: paths the report must not replace or contain (see :func:`check_report_target`).

    ``directory`` may also be a :class:`ReportFolder` from :func:`claim_report`: the
    report is then built but left for its :meth:`ReportFolder.publish` (with the other
    outputs of a command).
    """
    _check_content(title, summary, parameter_table, figures, notes)
    content = dict(
        title=title,
        summary=summary,
        parameter_table=parameter_table,
        figures=figures,
        scene=scene,
        json_result=json_result,
        notes=notes,
        tables=tables,
    )
    if isinstance(directory, ReportFolder):
        return directory.write(**content)
    claim = claim_report(directory, force=force, inputs=inputs)
    try:
        claim.write(**content)
        claim.publish()
    except BaseException:
        claim.discard()
        raise
    return claim.path


def _check_content(title, summary, parameter_table, figures, notes) -> None:
    """Types of :func:`write_report`'s arguments, as :class:`InputError` (before any work)."""
    if not isinstance(title, str):
        raise InputError(f"title must be a str, got {type(title).__name__}")
    if not isinstance(summary, Mapping):
        raise InputError(f"summary must be a mapping name -> value, got {type(summary).__name__}")
    if not isinstance(figures, Mapping):
        raise InputError(
            f"figures must be a mapping name -> callable or PNG path, got {type(figures).__name__}"
        )
    if isinstance(parameter_table, str | bytes) or not isinstance(parameter_table, Sequence):
        raise InputError(
            f"parameter_table must be a sequence of mappings, got {type(parameter_table).__name__}"
        )
    for i, row in enumerate(parameter_table):
        if not isinstance(row, Mapping):
            raise InputError(f"parameter_table[{i}] must be a mapping, got {type(row).__name__}")
    if isinstance(notes, str | bytes) or not isinstance(notes, Sequence):
        raise InputError(f"notes must be a sequence of lines, got {type(notes).__name__}")


def _build(
    target: Path,
    *,
    title: str,
    summary: Mapping,
    parameter_table: Sequence[Mapping],
    figures: Mapping[str, Callable[[Path], object] | str | os.PathLike],
    scene=None,
    json_result=None,
    notes: Sequence[str] = (),
    tables=None,
) -> Path:
    """The complete report in a temporary sibling folder of ``target``; returns that folder."""
    for name in figures:
        if not name or "/" in name or name.startswith(".") or name in ("index", "scene"):
            raise InputError(f"figure names must be plain file stems, got {name!r}")
    if scene is not None and not (isinstance(scene, str) or hasattr(scene, "html")):
        raise InputError(
            f"scene must be a RobotScene or an HTML string, got {type(scene).__name__}"
        )
    try:
        tmp = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.tmp-"))
    except OSError as exc:
        raise OutputError(f"cannot create a folder beside {target}: {exc.strerror}") from exc
    register_temporary(tmp)
    try:
        os.chmod(tmp, 0o755)
        payload = (
            json_result
            if json_result is not None
            else {"title": title, "summary": dict(summary), "parameters": list(parameter_table)}
        )
        atomic_write_text(tmp / RESULT, json_text(payload))
        written = []
        for name, fig in figures.items():
            out = tmp / f"{name}.png"
            if callable(fig):
                fig(out)
            else:
                src = Path(fig)
                if not src.is_file():
                    raise InputError(f"figure {name!r}: no file at {src}")
                shutil.copyfile(src, out)
            if not out.is_file():
                raise InputError(f"figure {name!r} wrote nothing to {out}")
            written.append(out.name)
        if scene is not None:
            text = scene if isinstance(scene, str) else scene.html()
            atomic_write_text(tmp / SCENE, text)
            assets: dict = {} if isinstance(scene, str) else getattr(scene, "asset_files", dict)()
            for name, asset in assets.items():  # a scene's external assets, written once
                atomic_write_text(tmp / name, asset)
        atomic_write_text(
            tmp / INDEX,
            _index(title, summary, parameter_table, written, scene is not None, notes, tables),
        )
        files = sorted(p.name for p in tmp.iterdir())
        manifest = {"written_by": _package, "files": files}
        atomic_write_text(tmp / MANIFEST, json_text(manifest))
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        unregister_temporary(tmp)
        raise
    return tmp


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
