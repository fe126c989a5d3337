"""A report folder: result.json, PNG figures, scene.html and an index.html that shows them.

Never half-written: the report is built in a temporary sibling folder
(``.<name>.tmp-*``) and renamed into place at the end. An existing non-empty
folder is only replaced with ``force=True``, and then only after the new
report is complete (the old folder is first renamed aside, then removed).
"""

from __future__ import annotations

import html as html_lib
import os
import shutil
import tempfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from .._io import atomic_write_text, json_text
from ..errors import InputError

INDEX, RESULT, SCENE = "index.html", "result.json", "scene.html"


class ReportExistsError(InputError):
    """The report folder exists and is not empty, and ``force`` was not given."""


def check_report_target(directory, force: bool = False) -> Path:
    """Raise :class:`ReportExistsError` if ``directory`` would be overwritten without ``force``.

    Also refuses a path that is an existing file. Call it before the long work.
    """
    path = Path(directory)
    if path.exists() and not path.is_dir():
        raise InputError(f"report folder {path} exists and is not a folder")
    if path.is_dir() and any(path.iterdir()) and not force:
        raise ReportExistsError(
            f"report folder {path} exists and is not empty (use --force / force=True to replace it)"
        )
    return path


def _cell(value) -> str:
    if isinstance(value, float | np.floating):
        return "n/a" if not np.isfinite(value) else f"{float(value):.6g}"
    if value is None:
        return "n/a"
    return html_lib.escape(str(value))


def _table(rows: Sequence[Mapping]) -> str:
    if not rows:
        return "<p>(no parameters)</p>"
    cols: list[str] = []
    for row in rows:
        cols += [c for c in row if c not in cols]
    head = "".join(f"<th>{html_lib.escape(str(c))}</th>" for c in cols)
    body = "\n".join(
        "<tr>" + "".join(f"<td>{_cell(row.get(c))}</td>" for c in cols) + "</tr>" for row in rows
    )
    return f"<table>\n<tr>{head}</tr>\n{body}\n</table>"


def _summary(summary: Mapping) -> str:
    items = "\n".join(
        f"<tr><th>{html_lib.escape(str(k))}</th><td>{_cell(v)}</td></tr>"
        for k, v in summary.items()
    )
    return f'<table class="summary">\n{items}\n</table>'


def _index(title: str, summary: Mapping, rows, figures: list[str], scene: bool, notes) -> str:
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
) -> Path:
    """Write a report folder and return its path.

    directory: the report folder (created; see the module docstring for overwriting).
    title: page title; summary: name -> value pairs shown first;
    parameter_table: rows (dicts, same keys) of the parameter table;
    figures: name -> a callable that writes a PNG to the path it is given, or
        the path of an existing PNG (copied); saved as ``<name>.png``;
    scene: a :class:`~manip_id.viz.meshcat_scene.RobotScene` or its HTML as a string;
    json_result: written to result.json (default: ``{"summary", "parameters"}``);
    notes: lines shown under the summary.
    """
    target = check_report_target(directory, force)
    for name in figures:
        if not name or "/" in name or name.startswith(".") or name in ("index", "scene"):
            raise InputError(f"figure names must be plain file stems, got {name!r}")
    if scene is not None and not (isinstance(scene, str) or hasattr(scene, "html")):
        raise InputError(
            f"scene must be a RobotScene or an HTML string, got {type(scene).__name__}"
        )
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.tmp-"))
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
        atomic_write_text(
            tmp / INDEX, _index(title, summary, parameter_table, written, scene is not None, notes)
        )
        _swap(tmp, target)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return target


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
