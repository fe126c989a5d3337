"""The hardening catalogue, third round (issue 29, rules 3, 4 and 6): each case a CLI run.

- Rule 3: resources estimated before allocation (samples, durations x rates, harmonics,
  chain size, perturbation size) and Dask scheduler specs parsed strictly (ports 1..65535,
  ``local:N`` capped at the cores, a short connection timeout).
- Rule 4: ``--force`` replaces a report folder only when every entry is a regular file its
  manifest lists with the same size and SHA-256; a report path that is a symbolic link is
  refused; no input may live inside the report folder.
- Rule 6: nothing of Dask's logging reaches stderr: a failing task on a local cluster
  gives one ``manip-id: error:`` line.

Every case asserts the exit status, one stderr line for an error, no traceback, every
input byte-identical and nothing left behind (:func:`_catalogue.check_case`).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import pytest
from _catalogue import Case, check_case, error_lines, working_folder, write_npz

from manip_id.cli import main

MANIFEST = ".manip-id-report.json"
RANK = ["rank", "msd", "--report", "rep", "--force", "--samples", "30"]
SIM = ["--simulate", "--duration", "2", "--rate", "100"]
TWO_LOGS = ["--data", "log.npz", "valid.npz"]


@pytest.fixture
def work(tmp_path, monkeypatch):
    """A working folder (the current directory) holding the inputs."""
    return working_folder(tmp_path, monkeypatch)


# ------------------------------------------------------------------- set-ups
def _own(w: Path) -> None:
    assert main(["rank", "msd", "--report", "rep", "--samples", "30"]) == 0


def _manifest(w: Path) -> dict:
    return json.loads((w / "rep" / MANIFEST).read_text())


def _write_manifest(w: Path, doc: dict) -> None:
    (w / "rep" / MANIFEST).write_text(json.dumps(doc))


def _entry(path: Path) -> dict:
    data = path.read_bytes()
    return {"size": len(data), "sha256": hashlib.sha256(data).hexdigest()}


def _lists_user_file_wrong_hash(w: Path) -> None:
    _own(w)
    (w / "rep" / "thesis.tex").write_text("years of work\n")
    doc = _manifest(w)
    doc["files"]["thesis.tex"] = {"size": 14, "sha256": "0" * 64}
    _write_manifest(w, doc)


def _lists_a_folder(w: Path) -> None:
    _own(w)
    (w / "rep" / "sub").mkdir()
    (w / "rep" / "sub" / "paper.tex").write_text("more work\n")
    doc = _manifest(w)
    doc["files"]["sub"] = {"size": 4096, "sha256": "0" * 64}
    _write_manifest(w, doc)


def _edited_index(w: Path) -> None:
    _own(w)
    page = w / "rep" / "index.html"
    page.write_text(page.read_text() + "<!-- my notes -->")


def _same_size_edit(w: Path) -> None:
    _own(w)
    page = w / "rep" / "index.html"
    text = page.read_text()
    page.write_text(text[:-1] + ("X" if text[-1] != "X" else "Y"))  # same size, other bytes


def _edited_result(w: Path) -> None:
    _own(w)
    doc = json.loads((w / "rep" / "result.json").read_text())
    doc["note"] = "mine"
    (w / "rep" / "result.json").write_text(json.dumps(doc))


def _old_manifest(w: Path) -> None:
    _own(w)
    doc = _manifest(w)
    doc["files"] = sorted(doc["files"])  # the names-only manifest of earlier releases
    _write_manifest(w, doc)


def _malformed_manifest(w: Path) -> None:
    _own(w)
    doc = _manifest(w)
    doc["files"]["index.html"] = {"size": "big", "sha256": 42}
    _write_manifest(w, doc)


def _foreign_manifest(w: Path) -> None:
    _own(w)
    doc = _manifest(w)
    doc["written_by"] = "someone_else"
    _write_manifest(w, doc)


def _manifest_is_a_folder(w: Path) -> None:
    (w / "rep").mkdir()
    (w / "rep" / MANIFEST).mkdir()
    (w / "rep" / "index.html").write_text("<html></html>")


def _listed_name_is_a_link(w: Path) -> None:
    _own(w)
    page = w / "rep" / "index.html"
    page.unlink()
    os.symlink(w / "a_file.txt", page)  # listed name, now a link to the user's file


def _listed_file_removed(w: Path) -> None:
    _own(w)
    (w / "rep" / "index.html").unlink()


def _link_to_empty(w: Path) -> None:
    (w / "target").mkdir()
    os.symlink("target", w / "rep")


def _link_to_own(w: Path) -> None:
    assert main(["rank", "msd", "--report", "target", "--samples", "30"]) == 0
    os.symlink("target", w / "rep")


def _dangling_link(w: Path) -> None:
    os.symlink("nowhere", w / "rep")


def _input_in_own_report(w: Path) -> None:
    _own(w)
    write_npz(w / "rep" / "log.npz")
    doc = _manifest(w)
    doc["files"]["log.npz"] = _entry(w / "rep" / "log.npz")  # listed and unchanged
    _write_manifest(w, doc)


def _validation_in_own_report(w: Path) -> None:
    _own(w)
    write_npz(w / "rep" / "valid.npz")
    doc = _manifest(w)
    doc["files"]["valid.npz"] = _entry(w / "rep" / "valid.npz")
    _write_manifest(w, doc)


def _chain(w: Path, n: int = 300) -> None:
    body = ['<?xml version="1.0"?>', '<robot name="chain">', '<link name="l0"/>']
    for k in range(1, n + 1):
        body.append(
            f'<link name="l{k}"><inertial><origin xyz="0.05 0 0"/><mass value="1"/>'
            '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>'
        )
        body.append(
            f'<joint name="j{k}" type="revolute"><parent link="l{k - 1}"/><child link="l{k}"/>'
            '<origin xyz="0.1 0 0"/><axis xyz="0 0 1"/>'
            '<limit lower="-3" upper="3" velocity="5" effort="50"/></joint>'
        )
    body.append("</robot>")
    (w / "chain.urdf").write_text("\n".join(body))


def _big_harmonics(w: Path) -> None:
    (w / "big.toml").write_text(
        "[model]\nspring = true\n\n[excitation]\nharmonics = 1000000000000\n"
    )


def _bad_npz(w: Path) -> None:
    (w / "bad.npz").write_text("PK but not really a zip file")


def _unchanged(w: Path) -> None:
    page = (w / "rep" / "index.html").read_text()
    assert "<html" in page.lower()


CASES = [
    # --- rule 4: --force removes only what it wrote, unchanged
    Case("force-manifest-lists-user-file", RANK, match="thesis.tex was changed",
         setup=_lists_user_file_wrong_hash),
    Case("force-manifest-lists-a-folder", RANK, match="sub is not a regular file",
         setup=_lists_a_folder),
    Case("force-edited-index", RANK, match="index.html was changed", setup=_edited_index),
    Case("force-same-size-edit", RANK, match="index.html was changed", setup=_same_size_edit),
    Case("force-edited-result-json", ["identify", "msd", *SIM, "--report", "rep", "--force"],
         match="result.json was changed", setup=_edited_result),
    Case("force-old-manifest-without-hashes", RANK, match="older manip-id.*delete",
         setup=_old_manifest),
    Case("force-malformed-manifest", RANK, match="malformed", setup=_malformed_manifest),
    Case("force-foreign-manifest", RANK, match="not written by manip-id",
         setup=_foreign_manifest),
    Case("force-manifest-is-a-folder", RANK, match="not written by manip-id",
         setup=_manifest_is_a_folder),
    Case("force-listed-name-is-a-link", RANK, match="index.html is not a regular file",
         setup=_listed_name_is_a_link),
    Case("force-unchanged-own-report", RANK, status=0, setup=_own,
         outputs=("rep/index.html",), check=_unchanged),
    Case("force-own-report-file-removed", RANK, status=0, setup=_listed_file_removed,
         outputs=("rep/index.html",)),
    Case("report-is-link-to-empty-folder", ["rank", "msd", "--report", "rep", "--samples", "30"],
         match="symbolic link", setup=_link_to_empty),
    Case("report-is-link-to-own-report-forced", RANK, match="symbolic link", setup=_link_to_own),
    Case("report-is-dangling-link", RANK, match="symbolic link", setup=_dangling_link),
    Case("report-slash-is-link", ["rank", "msd", "--report", "rep/", "--force"],
         match="symbolic link", setup=_link_to_empty),
    Case("input-listed-in-own-report", ["identify", "msd", "--data", "rep/log.npz",
         "--report", "rep", "--force"], match="holds the input", setup=_input_in_own_report),
    Case("validation-data-listed-in-own-report", ["identify", "msd", "--data", "log.npz",
         "--validate", "rep/valid.npz", "--report", "rep", "--force"], match="holds the input",
         setup=_validation_in_own_report),
    # --- rule 3: resources estimated before allocation
    Case("rank-samples-1e9", ["rank", "msd", "--samples", "1000000000"],
         match=r"random states .* GiB.* available"),
    Case("rank-arm-samples-3e8", ["rank", "arm.urdf", "--samples", "300000000"],
         match=r"GiB, more than 50%"),
    Case("adapt-duration-1e9", ["adapt", "msd", "--duration", "1e9"],
         match=r"integration steps \(duration x rate x substeps\) .* limit"),
    Case("adapt-rate-1e10", ["adapt", "msd", "--duration", "100", "--rate", "1e10"],
         match=r"GiB|rate"),
    Case("adapt-perturb-1e6", ["adapt", "msd", "--perturb", "1e6"], match="limit of 5"),
    Case("adapt-perturb-6", ["adapt", "msd", "--perturb", "6"], match="limit of 5"),
    Case("identify-simulate-duration-1e9", ["identify", "msd", "--simulate", "--duration", "1e9"],
         match=r"GiB, more than 50%"),
    Case("identify-simulate-rate-1e10", ["identify", "msd", "--simulate", "--duration", "10",
         "--rate", "1e10"], match=r"GiB|rate"),
    Case("profile-harmonics-1e12", ["identify", "msd", "--profile", "big.toml", *SIM],
         match="excitation.harmonics must be a positive integer <= 1000", setup=_big_harmonics),
    Case("rank-300-joint-chain", ["rank", "chain.urdf"], match="300 joints .* limit",
         setup=_chain),
    Case("identify-300-joint-chain", ["identify", "chain.urdf", *SIM], match="300 joints",
         setup=_chain),
    # --- rule 3: Dask scheduler specs
    Case("scheduler-port-99999", ["identify", "msd", *TWO_LOGS, "--scheduler",
         "tcp://127.0.0.1:99999"], match="1..65535"),
    Case("scheduler-port-0", ["identify", "msd", *TWO_LOGS, "--scheduler", "tcp://127.0.0.1:0"],
         match="1..65535"),
    Case("scheduler-no-host", ["identify", "msd", *TWO_LOGS, "--scheduler", "tcp://:8786"],
         match="tcp://HOST:PORT"),
    Case("scheduler-path-in-host", ["identify", "msd", *TWO_LOGS, "--scheduler",
         "tcp://a/b:8786"], match="tcp://HOST:PORT"),
    Case("scheduler-http", ["identify", "msd", *TWO_LOGS, "--scheduler", "http://x:8786"],
         match="tcp://HOST:PORT"),
    Case("scheduler-file-garbage", ["identify", "msd", *TWO_LOGS, "--scheduler", "s.json"],
         match="scheduler file", setup=lambda w: (w / "s.json").write_bytes(b"\x00{not json")),
    Case("scheduler-file-no-address", ["identify", "msd", *TWO_LOGS, "--scheduler", "s.json"],
         match='must be a JSON object with an "address"',
         setup=lambda w: (w / "s.json").write_text('{"id": "Scheduler-1"}')),
    Case("scheduler-file-bad-port", ["identify", "msd", *TWO_LOGS, "--scheduler", "s.json"],
         match="1..65535",
         setup=lambda w: (w / "s.json").write_text('{"address": "tcp://127.0.0.1:70000"}')),
    Case("scheduler-file-is-fifo", ["identify", "msd", *TWO_LOGS, "--scheduler", "s.json"],
         match="FIFO|fifo|named pipe", setup=lambda w: os.mkfifo(w / "s.json")),
    # --- rule 6: a failing task on a local cluster: one line, no worker log
    Case("local-cluster-failing-task", ["identify", "msd", "--data", "log.npz", "bad.npz",
         "--scheduler", "local:2", "--per-file"], match="bad.npz", setup=_bad_npz),
]  # fmt: skip


@pytest.mark.parametrize("case", [pytest.param(c, id=c.id, marks=c.marks) for c in CASES])
def test_cli_case(case: Case, work: Path, capfd):
    if case.setup is not None:
        case.setup(work)
    check_case(case, work, capfd)


def test_catalogue_size():
    assert len(CASES) >= 30


def test_local_workers_capped_and_quiet(work, capfd):
    """``local:8`` on fewer cores runs on as many workers as cores, with one warning."""
    cores = len(os.sched_getaffinity(0))
    argv = ["identify", "msd", *TWO_LOGS, "--scheduler", "local:8", "--per-file"]
    assert main([*argv, "--json", "o.json"]) == 0
    lines = error_lines(capfd.readouterr().err)
    assert all(line.startswith("manip-id: warning: ") for line in lines), lines
    capped = [line for line in lines if "local:8 capped" in line]
    assert len(capped) == (1 if cores < 8 else 0), lines
    assert json.loads((work / "o.json").read_text())["source"]["scheduler"] == (
        f"local:{min(cores, 8)}"
    )


@pytest.mark.parametrize(
    ("value", "match"), [("1", "cannot reach .* within 1.0 s"), ("abc", "MANIP_ID_DASK_TIMEOUT")]
)
def test_scheduler_timeout(value, match, work, capfd, monkeypatch):
    """A scheduler nobody runs: refused after the (overridable) wait, in one line."""
    import re

    monkeypatch.setenv("MANIP_ID_DASK_TIMEOUT", value)
    before = sorted(p.name for p in work.iterdir())
    status = main(["identify", "msd", *TWO_LOGS, "--scheduler", "tcp://127.0.0.1:1"])
    lines = error_lines(capfd.readouterr().err)
    assert status == 2
    assert len(lines) == 1 and re.search(match, lines[0]), lines
    assert sorted(p.name for p in work.iterdir()) == before


def test_symlinked_report_leaves_nothing_in_its_target(work, capfd):
    """The refused link and its target are as they were: no claim, no ``.rep.old-*``."""
    _link_to_own(work)
    before = sorted(p.name for p in (work / "target").iterdir())
    assert main(RANK) == 2
    assert sorted(p.name for p in (work / "target").iterdir()) == before
    assert os.readlink(work / "rep") == "target"
    assert not [p for p in os.listdir(work) if ".old-" in p or ".tmp" in p]


def test_resource_tracker_note_silenced(monkeypatch, capfd):
    """multiprocessing's "resource_tracker: process died unexpectedly" (seen when a local
    cluster's tracker was stopped with it) is not one of ours: no line without --debug,
    while a warning of the package itself is still printed."""
    import warnings

    import manip_id.cli._robots as robots_run

    def noisy(args):
        warnings.warn("resource_tracker: process died unexpectedly, relaunching.", stacklevel=1)
        warnings.warn("a warning of the package", stacklevel=1)
        return 0

    monkeypatch.setattr(robots_run, "run", noisy)
    capfd.readouterr()
    assert main(["robots"]) == 0
    assert error_lines(capfd.readouterr().err) == ["manip-id: warning: a warning of the package"]
    assert main(["robots", "--debug"]) == 0
    assert any("resource_tracker" in line for line in error_lines(capfd.readouterr().err))
