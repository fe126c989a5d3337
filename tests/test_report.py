"""write_report: the folder's contents, never overwritten without force, never half-written."""

from __future__ import annotations

import hashlib
import json
from html.parser import HTMLParser

import numpy as np
import pytest

from manip_id.errors import InputError, ManipIdError
from manip_id.viz import figures
from manip_id.viz.report import ReportContent, ReportExistsError, check_report_target, write_report

T = np.linspace(0, 1, 50)


class _Links(HTMLParser):
    """Every src/href of a page, and the text of its table cells (an independent HTML parse)."""

    def __init__(self):
        super().__init__()
        self.refs, self.cells, self._in_cell = [], [], False

    def handle_starttag(self, tag, attrs):
        self.refs += [v for k, v in attrs if k in ("src", "href")]
        self._in_cell = tag == "td"

    def handle_endtag(self, tag):
        self._in_cell = False

    def handle_data(self, data):
        if self._in_cell:
            self.cells.append(data)


def _parse(path):
    p = _Links()
    p.feed(path.read_text())
    return p


def _fig(path):
    figures.residuals(path, T, np.sin(T)[:, None], title="sine")


def _report(directory, *, force=False, inputs=(), **kw):
    args = dict(
        title="test report",
        summary={"robot": "x", "error": 0.0123},
        parameter_table=[{"name": "a.m", "value": 1.5}, {"name": "a.mcx", "value": -2.25}],
        figures={"residuals": _fig},
        scene="<html><body>scene</body></html>",
        json_result={"answer": 42, "array": np.arange(3)},
    )
    args.update(kw)
    return write_report(directory, ReportContent(**args), force=force, inputs=inputs)


def test_report_folder_contents(tmp_path):
    existing = tmp_path / "given.png"
    _fig(existing)
    out = _report(tmp_path / "rep", figures={"residuals": _fig, "copied": existing})
    assert out == tmp_path / "rep"
    names = sorted(p.name for p in out.iterdir())
    assert names == [
        ".manip-id-report.json",  # the manifest that lets --force replace the folder later
        "copied.png",
        "index.html",
        "residuals.png",
        "result.json",
        "scene.html",
    ]
    manifest = json.loads((out / ".manip-id-report.json").read_text())
    assert sorted(manifest["files"]) == names[1:]
    for name, entry in manifest["files"].items():  # size and SHA-256, checked by --force
        data = (out / name).read_bytes()
        assert entry == {"size": len(data), "sha256": hashlib.sha256(data).hexdigest()}
    assert json.loads((out / "result.json").read_text()) == {"answer": 42, "array": [0, 1, 2]}
    assert (out / "copied.png").read_bytes() == existing.read_bytes()
    assert (out / "scene.html").read_text() == "<html><body>scene</body></html>"
    page = _parse(out / "index.html")
    for ref in ("residuals.png", "copied.png", "scene.html", "result.json"):
        assert ref in page.refs
        assert (out / ref).is_file()
    assert {"a.m", "1.5", "a.mcx", "-2.25", "0.0123"} <= set(page.cells)
    # nothing left beside the report
    assert sorted(p.name for p in tmp_path.iterdir()) == ["given.png", "rep"]


def test_default_json_and_no_scene(tmp_path):
    out = _report(tmp_path / "rep", scene=None, json_result=None, figures={})
    data = json.loads((out / "result.json").read_text())
    assert data["summary"] == {"robot": "x", "error": 0.0123}
    assert data["parameters"][1] == {"name": "a.mcx", "value": -2.25}
    assert not (out / "scene.html").exists()
    assert "scene.html" not in _parse(out / "index.html").refs


def test_empty_existing_folder_is_used(tmp_path):
    (tmp_path / "rep").mkdir()
    _report(tmp_path / "rep")
    assert (tmp_path / "rep" / "index.html").is_file()


def test_non_empty_folder_needs_force(tmp_path):
    rep = tmp_path / "rep"
    rep.mkdir()
    (rep / "mine.txt").write_text("keep me")
    with pytest.raises(ReportExistsError, match="exists and is not empty") as info:
        _report(rep)
    assert isinstance(info.value, ManipIdError)
    assert sorted(p.name for p in rep.iterdir()) == ["mine.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rep"]
    # --force never removes a folder manip_id did not write (no manifest)
    with pytest.raises(InputError, match="not written by manip-id"):
        _report(rep, force=True)
    assert (rep / "mine.txt").read_text() == "keep me"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rep"]


def test_force_replaces_only_our_own_report(tmp_path):
    rep = tmp_path / "rep"
    _report(rep)
    first = (rep / "result.json").read_bytes()
    _report(rep, force=True, json_result={"second": True})
    assert (rep / "result.json").read_bytes() != first
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rep"]
    (rep / "notes.txt").write_text("the user's own file")
    with pytest.raises(InputError, match="did not write"):
        _report(rep, force=True)
    assert (rep / "notes.txt").read_text() == "the user's own file"


def test_a_file_in_the_way_is_an_error(tmp_path):
    (tmp_path / "rep").write_text("x")
    with pytest.raises(InputError, match="not a folder"):
        check_report_target(tmp_path / "rep", force=True)


@pytest.mark.parametrize("force", [False, True])
def test_failure_leaves_no_half_written_report(tmp_path, force):
    rep = tmp_path / "rep"
    if force:
        _report(rep, json_result={"previous": True})
    before = sorted(p.name for p in rep.iterdir()) if force else None

    def broken(path):
        raise InputError("figure failed")

    with pytest.raises(InputError, match="figure failed"):
        _report(rep, figures={"ok": _fig, "broken": broken}, force=force)
    if force:  # the old report is intact
        assert sorted(p.name for p in rep.iterdir()) == before
        assert json.loads((rep / "result.json").read_text()) == {"previous": True}
        assert sorted(p.name for p in tmp_path.iterdir()) == ["rep"]
    else:
        assert not rep.exists()
        assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", ["", "a/b", ".hidden", "index"])
def test_bad_figure_names(tmp_path, name):
    with pytest.raises(InputError, match="figure names"):
        _report(tmp_path / "rep", figures={name: _fig})
    assert not (tmp_path / "rep").exists()


def test_missing_figure_file(tmp_path):
    with pytest.raises(InputError, match="no file at"):
        _report(tmp_path / "rep", figures={"f": tmp_path / "missing.png"})
    assert list(tmp_path.iterdir()) == []
