"""What a report folder shows: result.json, PNG figures, scene.html and an index.html.

This module only renders. The folder itself (claimed before the work, built in a
temporary sibling, published with the other outputs, replaced only when manip_id wrote
it) is :mod:`manip_id._io.report_folder`'s: :func:`write_report` fills a
:class:`~manip_id._io.ReportFolder`.
"""

from __future__ import annotations

import html as html_lib
import os
import shutil
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from .._io import (
    CLAIM,
    MANIFEST,
    ReportFolder,
    atomic_write_text,
    check_report_target,
    claim_report,
    json_text,
)
from ..errors import InputError, ReportExistsError
from ..identifiability.qr import REGROUPED_NOTE, has_regrouped

INDEX, RESULT, SCENE = "index.html", "result.json", "scene.html"


@dataclass(frozen=True)
class ReportContent:
    """What a report page shows (see :func:`write_report`)."""

    title: str
    summary: Mapping
    parameter_table: Sequence[Mapping]
    figures: Mapping[str, Callable[[Path], object] | str | os.PathLike]
    scene: Any = None  # a RobotScene (html(), asset_files()) or its HTML
    json_result: Any = None
    notes: Sequence[str] = ()
    tables: Mapping[str, Sequence[Mapping]] | None = None
    questions: Sequence[tuple[str, str]] = ()


#: Re-exported for the imports of earlier releases (they live in manip_id._io / errors).
__all__ = [
    "CLAIM",
    "INDEX",
    "MANIFEST",
    "RESULT",
    "SCENE",
    "ReportContent",
    "ReportExistsError",
    "ReportFolder",
    "check_report_target",
    "claim_report",
    "write_report",
]


def html_cell(value) -> str:
    """A table cell's text, escaped; floats with 6 significant digits, None as n/a."""
    if isinstance(value, float | np.floating):
        return "n/a" if not np.isfinite(value) else f"{float(value):.6g}"
    if value is None:
        return "n/a"
    return html_lib.escape(str(value))


def html_table(rows: Sequence[Mapping], empty: str = "(no parameters)") -> str:
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
        + "".join(f"<td>{html_cell(row.get(c))}</td>" for c in cols)
        + "</tr>"
        for row in rows
    )
    return f"<table>\n<tr>{head}</tr>\n{body}\n</table>"


def _summary(summary: Mapping) -> str:
    items = "\n".join(
        f"<tr><th>{html_lib.escape(str(k))}</th><td>{html_cell(v)}</td></tr>"
        for k, v in summary.items()
    )
    return f'<table class="summary">\n{items}\n</table>'


def _index(c: ReportContent, figures: list[str]) -> str:
    """The page: title, the answers, summary, notes, scene, figures, parameters, tables."""
    title, summary, rows, notes, tables = c.title, c.summary, c.parameter_table, c.notes, c.tables
    scene = c.scene is not None
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
    answers = "\n".join(
        f'<section class="answer"><h2>{html_lib.escape(str(q))}</h2>\n{a}</section>'
        for q, a in c.questions
    )
    regrouped = ""  # the R suffix explained under the table that shows it
    if has_regrouped(r.get("name", "") for r in rows or []):
        note = html_lib.escape(REGROUPED_NOTE[0].upper() + REGROUPED_NOTE[1:])
        regrouped = f'<p class="regrouped">{note}.</p>\n'

    note_html = "".join(f"<li>{html_lib.escape(str(n))}</li>" for n in notes)
    extra = "\n".join(
        f"<h2>{html_lib.escape(str(name))}</h2>\n{html_table(t, '(none)')}"
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
section.answer {{ border-left: 4px solid #1f77b4; padding: 0 0 0 0.8em; margin: 0 0 1em 0; }}
section.answer h2 {{ margin: 0.3em 0; font-size: 1.15em; }}
p.verdict {{ font-size: 1.1em; margin: 0.3em 0 1em 0; }}
.yes {{ color: #1a7f37; font-weight: bold; }} .no {{ color: #b42318; font-weight: bold; }}
</style></head>
<body>
<h1>{html_lib.escape(title)}</h1>
{answers}
<h2>Summary</h2>
{_summary(summary)}
{f"<ul>{note_html}</ul>" if note_html else ""}
{scene_html}
<h2>Figures</h2>
{figs or "<p>(no figures)</p>"}
<h2>Parameters</h2>
{regrouped}{html_table(rows)}
{extra}
<p><a href="{RESULT}">{RESULT}</a>: the full result.</p>
</body></html>
"""


def write_report(
    directory, content: ReportContent, *, force: bool = False, inputs: Sequence = ()
) -> Path:
    """Write a report folder and return its path.

    directory: the report folder (created; see the module docstring for overwriting).
    content: what the page shows, a :class:`ReportContent`:

    - title: page title; summary: name -> value pairs shown first;
    - parameter_table: rows (dicts, same keys) of the parameter table;
    - figures: name -> a callable that writes a PNG to the path it is given, or
      the path of an existing PNG (copied); saved as ``<name>.png``;
    - scene: a :class:`~manip_id.viz.meshcat_scene.RobotScene` or its HTML as a string;
    - json_result: written to result.json (default: ``{"summary", "parameters"}``);
    - notes: lines shown under the summary;
    - tables: more sections after the parameters, title -> rows (as ``parameter_table``;
      a row's ``_class`` key, e.g. ``"bad"``, highlights it);
    - questions: sections shown first, ``(question, answer HTML)`` pairs (the answer is
      markup built by the caller, escaped there), e.g. "How good is the model?".

    force: replace a report folder manip_id wrote;
    inputs: paths the report must not replace or contain (see :func:`check_report_target`).

    ``directory`` may also be a :class:`ReportFolder` from :func:`claim_report`: the
    report is then built but left for its :meth:`ReportFolder.publish` (with the other
    outputs of a command).
    """
    if not isinstance(content, ReportContent):
        raise InputError(f"content must be a ReportContent, got {type(content).__name__}")
    c = content
    _check_content(c.title, c.summary, c.parameter_table, c.figures, c.notes)
    content = replace(c, questions=tuple(c.questions))
    _check_names(c.figures, c.scene)

    def fill(tmp: Path) -> None:
        _fill(tmp, content)

    if isinstance(directory, ReportFolder):
        return directory.build(fill)
    claim = claim_report(directory, force=force, inputs=inputs)
    try:
        claim.build(fill)
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


def _fill(tmp: Path, c: ReportContent) -> None:
    """Write the report's files into the (temporary) folder ``tmp``."""
    title, summary, parameter_table, scene = c.title, c.summary, c.parameter_table, c.scene
    json_result = c.json_result
    payload = (
        json_result
        if json_result is not None
        else {"title": title, "summary": dict(summary), "parameters": list(parameter_table)}
    )
    atomic_write_text(tmp / RESULT, json_text(payload))
    written = []
    for name, fig in c.figures.items():
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
        _index(c, written),
    )


def _check_names(figures: Mapping, scene) -> None:
    """Figure names are plain file stems; a scene is a RobotScene or HTML (before any work)."""
    for name in figures:
        if not name or "/" in name or name.startswith(".") or name in ("index", "scene"):
            raise InputError(f"figure names must be plain file stems, got {name!r}")
    if scene is not None and not (isinstance(scene, str) or hasattr(scene, "html")):
        raise InputError(
            f"scene must be a RobotScene or an HTML string, got {type(scene).__name__}"
        )
