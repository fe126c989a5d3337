"""The hardening catalogue (issue 14): bad inputs and situations, each with its expected outcome.

Every CLI case asserts the exit status (2 for bad input, 0 where the command must
work), exactly one stderr line for an error, no traceback, every input file
byte-identical afterwards and no output (nor temporary) left behind. Signal cases
run in subprocesses; the viewer's listening addresses are read with psutil; API
cases assert the exception type.

The data are made here with numpy alone: the mass-spring-damper ``msd``
(``m ddq + c dq + k q = tau``, m = 2 kg, c = 0.8 N s/m, k = 5 N/m) and a
two-link arm URDF written by the test.
"""

from __future__ import annotations

import json
import os
import re
import signal
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest
from _catalogue import (
    Case,
    arm_urdf,
    check_case,
    error_lines,
    msd_arrays,
    snapshot,
    working_folder,
    write_npz,
)

from manip_id.cli import main
from manip_id.errors import ManipIdError
from manip_id.simulation import MeasurementNoise

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}


# ----------------------------------------------------------------- fixtures
@pytest.fixture
def work(tmp_path, monkeypatch):
    """A working folder (the current directory) holding the inputs."""
    return working_folder(tmp_path, monkeypatch)


def _symlink_to_log(w: Path) -> None:
    os.symlink("log.npz", w / "link.npz")


def _hardlink_to_log(w: Path) -> None:
    os.link(w / "log.npz", w / "hard.npz")


def _panda_log_folder(w: Path) -> None:
    """A log folder in the Panda format: one value per line in four files."""
    folder = w / "pandalog"
    folder.mkdir()
    n = 50
    (folder / "rbt_log_time.txt").write_text("".join(f"{k * 1e-3}\n" for k in range(n)))
    for name in ("positions", "velocity", "torques"):
        (folder / f"rbt_log_{name}.txt").write_text("0.1\n" * (7 * n))


def _foreign_report(w: Path) -> None:
    (w / "rep").mkdir()
    (w / "rep" / "thesis.tex").write_text("years of work\n")


def _own_report_plus_user_file(w: Path) -> None:
    assert main(["rank", "msd", "--report", "rep", "--samples", "30"]) == 0
    (w / "rep" / "mine.txt").write_text("added by the user\n")


def _own_report(w: Path) -> None:
    assert main(["rank", "msd", "--report", "rep", "--samples", "30"]) == 0


def _busy_report(w: Path) -> None:
    (w / "rep").mkdir()
    (w / "rep" / ".manip-id-claim").write_text(f"{os.getpid()}\n")  # a live process


def _stale_claim(w: Path) -> None:
    (w / "rep").mkdir()
    (w / "rep" / ".manip-id-claim").write_text("99999999\n")  # above any pid_max: dead


def _weird_names(w: Path) -> None:
    write_npz(w / "we$ird_$x^{2}$.npz")
    write_npz(w / "<script>alert(1)<i>.npz")


def _bad_urdfs(w: Path) -> None:
    arm_urdf(w / "negmass.urdf", m1="-2.0")
    arm_urdf(w / "nonpd.urdf", ixx="-0.5")
    arm_urdf(w / "dollar.urdf", j1="j$1<b>&amp;", l1="l$1")
    (w / "notxml.urdf").write_text("this is not XML at all\n")
    (w / "binary.urdf").write_bytes(bytes(range(256)) * 4)
    (w / "empty.urdf").write_bytes(b"")
    arm_urdf(w / "nomass.urdf", m1="")  # urdfdom skips the inertial: a massless body


def _bad_data(w: Path) -> None:
    a = msd_arrays()
    (w / "binary.csv").write_bytes(b"\x00\xff\xfe\x89PNG\r\n\x1a\n" + bytes(range(256)) * 8)
    (w / "empty.csv").write_bytes(b"")
    (w / "words.csv").write_text("hello,world\nthis,is\nnot,numbers\n")
    (w / "random.npz").write_bytes(np.random.default_rng(0).bytes(4096))
    (w / "fake.npz").write_text("PK but not really a zip file")
    write_npz(w / "complex.npz", tau=a["tau"] * (1 + 1j))
    write_npz(w / "huge.npz", tau=a["tau"] * 1e300)
    write_npz(w / "tiny.npz", tau=a["tau"] * 1e-300)
    write_npz(w / "nan.npz", q=np.where(np.arange(400)[:, None] == 7, np.nan, a["q"]))
    write_npz(w / "inf_dq.npz", dq=np.where(np.arange(400)[:, None] == 9, np.inf, a["dq"]))
    write_npz(w / "backwards.npz", t=a["t"][::-1].copy())
    write_npz(w / "notau.npz", tau=None)
    write_npz(w / "short.npz", tau=a["tau"][:100])
    write_npz(w / "twojoints.npz", q=np.hstack([a["q"], a["q"]]), joint_names=None)
    write_npz(
        w / "beyond.npz", q=a["q"] * 10.0, dq=a["dq"] * 10, ddq=a["ddq"] * 10, tau=a["tau"] * 10
    )
    write_npz(w / "strings.npz", tau=np.array([["x"]] * 400))
    with open(w / "pickled.npz", "wb") as fh:
        np.savez(fh, **{**msd_arrays(), "tau": np.array([object()] * 400, dtype=object)})
    (w / "notalog").mkdir()
    (w / "notalog" / "readme.txt").write_text("no data here\n")


def _special(w: Path) -> None:
    os.mkfifo(w / "fifo.npz")
    os.mkfifo(w / "fifo.urdf")
    os.symlink("data", w / "datalink")
    write_npz(w / os.fsdecode(b"\xff\xfe-latin.npz"))  # not UTF-8: a surrogate-escaped name


def _all(w: Path) -> None:
    _bad_urdfs(w)
    _bad_data(w)
    _weird_names(w)
    _special(w)


def _escaped_report(w: Path) -> None:
    page = (w / "rep" / "index.html").read_text()
    assert "<script>alert(1)" not in page
    assert "&lt;script&gt;" in page


def _escaped_scene(w: Path) -> None:
    page = (w / "scene.html").read_text()
    assert "j$1<b>" not in page  # the names travel base64-encoded in the scene commands


def _escaped_names_report(w: Path) -> None:
    page = (w / "rep" / "index.html").read_text()
    assert "j$1<b>" not in page
    assert "j$1&lt;b&gt;&amp;" in page  # the parameter table names the joint, escaped


SIM = ["--simulate", "--duration", "2", "--rate", "100"]
CASES = [
    # --- rule 1: outputs checked before any work (data loss and late failures)
    Case(
        "json-onto-its-input",
        ["identify", "msd", "--data", "log.npz", "--json", "log.npz"],
        match="is one of the inputs",
    ),
    Case(
        "json-onto-symlink-of-input",
        ["identify", "msd", "--data", "log.npz", "--json", "link.npz"],
        match="one of the inputs",
        setup=_symlink_to_log,
    ),
    Case(
        "json-onto-hardlink-of-input",
        ["identify", "msd", "--data", "log.npz", "--json", "hard.npz"],
        match="one of the inputs",
        setup=_hardlink_to_log,
    ),
    Case(
        "json-onto-windowed-input",
        ["identify", "msd", "--data", "log.npz@0:2", "--json", "log.npz"],
        match="one of the inputs",
    ),
    Case(
        "export-urdf-onto-the-urdf",
        ["identify", "arm.urdf", *SIM, "--consistent", "--export-urdf", "arm.urdf", "--force"],
        match="one of the inputs",
    ),
    Case(
        "json-onto-validation-input",
        ["identify", "msd", "--data", "log.npz", "--validate", "valid.npz", "--json", "valid.npz"],
        match="one of the inputs",
    ),
    Case(
        "json-onto-a-file-of-an-input-folder",
        ["identify", "panda", "--data", "pandalog", "--json", "pandalog/rbt_log_time.txt"],
        match="inside the input folder",
        setup=_panda_log_folder,
    ),
    Case(
        "json-onto-input-by-other-spelling",
        ["identify", "msd", "--data", "log.npz", "--json", "./data/../log.npz"],
        match="one of the inputs",
    ),
    Case(
        "html-onto-its-data",
        ["view", "msd", "--data", "log.npz", "--html", "log.npz"],
        match="one of the inputs",
    ),
    Case(
        "json-onto-the-urdf",
        ["rank", "arm.urdf", "--samples", "30", "--json", "arm.urdf"],
        match="one of the inputs",
    ),
    Case("json-is-a-folder", ["identify", "msd", *SIM, "--json", "data"], match="is a folder"),
    Case(
        "json-in-proc",
        ["identify", "msd", *SIM, "--json", "/proc/manip-id-test.json"],
        match="cannot create a file|not a regular file",
    ),
    Case(
        "json-proc-special-file",
        ["identify", "msd", *SIM, "--json", "/proc/self/status"],
        match="cannot create a file|not a regular file",
    ),
    Case("json-dev-null", ["rank", "msd", "--json", "/dev/null"], match="not a regular file"),
    Case(
        "json-under-a-regular-file",
        ["identify", "msd", *SIM, "--json", "a_file.txt/out.json"],
        match="not a folder",
    ),
    Case(
        "json-in-missing-folder",
        ["identify", "msd", *SIM, "--json", "nowhere/out.json"],
        match="does not exist",
    ),
    Case("json-empty-path", ["rank", "msd", "--json", ""], match="non-empty path"),
    Case("report-is-cwd", ["identify", "msd", *SIM, "--report", "."], match="current directory"),
    Case(
        "report-is-cwd-forced",
        ["identify", "msd", *SIM, "--report", ".", "--force"],
        match="current directory",
    ),
    Case(
        "report-is-parent-of-cwd",
        ["rank", "msd", "--report", "..", "--force"],
        match="current directory or one of its ancestors",
    ),
    Case(
        "report-holds-the-input-forced",
        ["identify", "msd", "--data", "data/inner.npz", "--report", "data", "--force"],
        match="holds the input",
    ),
    Case("report-holds-the-urdf", ["rank", "arm.urdf", "--report", "."], match="current directory"),
    Case(
        "report-is-an-existing-file",
        ["rank", "msd", "--report", "a_file.txt"],
        match="not a folder",
    ),
    Case(
        "report-under-a-file", ["rank", "msd", "--report", "a_file.txt/rep"], match="not a folder"
    ),
    Case(
        "report-in-missing-folder",
        ["rank", "msd", "--report", "no/such/rep"],
        match="does not exist",
    ),
    Case("report-not-empty-no-force", ["rank", "msd", "--report", "data"], match="not empty"),
    Case(
        "report-force-on-foreign-folder",
        ["rank", "msd", "--report", "rep", "--force"],
        match="not written by manip-id",
        setup=_foreign_report,
    ),
    Case(
        "report-force-on-own-folder-with-user-file",
        ["rank", "msd", "--report", "rep", "--force", "--samples", "30"],
        match="did not write",
        setup=_own_report_plus_user_file,
    ),
    Case(
        "report-force-replaces-own-report",
        ["rank", "msd", "--report", "rep", "--force", "--samples", "30"],
        status=0,
        setup=_own_report,
        outputs=("rep/index.html",),
    ),
    Case(
        "report-claimed-by-another-run",
        ["rank", "msd", "--report", "rep"],
        match="another manip-id run",
        setup=_busy_report,
    ),
    Case(
        "report-claim-of-a-killed-run",
        ["rank", "msd", "--report", "rep"],
        match="no longer running",
        setup=_stale_claim,
    ),
    Case(
        "json-inside-report",
        ["rank", "msd", "--report", "rep", "--json", "rep/x.json"],
        match="collides with another output",
    ),
    Case(
        "view-html-named-json",
        ["view", "msd", "--html", "out.json", "--no-inertia"],
        status=0,
        outputs=("out.json",),
    ),
    Case(
        "adapt-json-is-folder",
        ["adapt", "msd", "--duration", "0.2", "--json", "data"],
        match="is a folder",
    ),
    Case(
        "adapt-report-is-cwd",
        ["adapt", "msd", "--duration", "0.2", "--report", "."],
        match="current directory",
    ),
    Case("view-html-is-folder", ["view", "msd", "--html", "data"], match="is a folder"),
    # --- bad options: one line, exit 2
    Case("negative-seed-identify", ["identify", "msd", *SIM, "--seed", "-1"], match="--seed"),
    Case("negative-seed-rank", ["rank", "msd", "--seed", "-3"], match="--seed"),
    Case(
        "negative-seed-view",
        ["view", "msd", "--simulate", "--seed", "-5", "--html", "o.html"],
        match="--seed",
    ),
    Case(
        "negative-seed-adapt", ["adapt", "msd", "--seed", "-1", "--duration", "0.2"], match="--seed"
    ),
    Case("huge-seed", ["rank", "msd", "--seed", str(2**70)], match="--seed"),
    Case("workers-zero", ["identify", "msd", *SIM, "--workers", "0"], match="--workers"),
    Case(
        "workers-capped",
        ["identify", "msd", *SIM, "--workers", "1000", "--json", "o.json"],
        status=0,
        outputs=("o.json",),
        warnings=1,
    ),
    Case(
        "unknown-option", ["identify", "msd", *SIM, "--frobnicate"], match="unrecognized arguments"
    ),
    Case("missing-command", [], match="required"),
    Case(
        "non-numeric-duration",
        ["identify", "msd", "--simulate", "--duration", "ten"],
        match="invalid float",
    ),
    Case(
        "nan-duration", ["identify", "msd", "--simulate", "--duration", "nan"], match="--duration"
    ),
    Case(
        "split-out-of-range",
        ["identify", "msd", "--data", "log.npz", "--split", "1.5"],
        match="--split",
    ),
    Case("unknown-robot", ["rank", "no_such_robot_xyz"], match="no_such_robot_xyz"),
    Case(
        "host-without-serve",
        ["view", "msd", "--html", "o.html", "--host", "0.0.0.0"],
        match="--host applies to --serve",
    ),
    # --- rule 4: inputs validated as data
    Case("binary-file-named-csv", ["identify", "msd", "--data", "binary.csv"]),
    Case("empty-csv", ["identify", "msd", "--data", "empty.csv"]),
    Case("csv-of-words", ["identify", "msd", "--data", "words.csv"]),
    Case("random-bytes-npz", ["identify", "msd", "--data", "random.npz"]),
    Case("text-named-npz", ["rank", "msd", "--data", "fake.npz"]),
    Case("complex-torques", ["identify", "msd", "--data", "complex.npz"], match="complex"),
    Case("torques-1e300", ["identify", "msd", "--data", "huge.npz"], match=r"tau.*sample 0"),
    Case("torques-1e-300", ["identify", "msd", "--data", "tiny.npz"], match="tau"),
    Case("nan-in-positions", ["identify", "msd", "--data", "nan.npz"], match=r"q.*sample 7"),
    Case("inf-in-velocities", ["identify", "msd", "--data", "inf_dq.npz"], match=r"dq.*sample 9"),
    Case("time-backwards", ["identify", "msd", "--data", "backwards.npz"], match="time"),
    Case("npz-without-tau", ["identify", "msd", "--data", "notau.npz"], match="tau"),
    Case("npz-mismatched-rows", ["identify", "msd", "--data", "short.npz"]),
    Case("npz-wrong-joint-count", ["identify", "msd", "--data", "twojoints.npz"]),
    Case("npz-strings", ["identify", "msd", "--data", "strings.npz"]),
    Case("npz-object-array", ["identify", "msd", "--data", "pickled.npz"]),
    Case("positions-beyond-limits", ["identify", "msd", "--data", "beyond.npz"], match="limit"),
    Case(
        "view-positions-beyond-limits",
        ["view", "msd", "--data", "beyond.npz", "--html", "o.html"],
        match="limit",
    ),
    Case("data-missing", ["identify", "msd", "--data", "missing.npz"], match="missing.npz"),
    Case("data-folder-not-a-log", ["identify", "msd", "--data", "notalog"]),
    Case("validate-binary", ["identify", "msd", "--data", "log.npz", "--validate", "binary.csv"]),
    Case("rank-data-binary", ["rank", "msd", "--data", "binary.csv"]),
    # --- robots: physically consistent, urdfdom captured
    Case("urdf-not-xml", ["rank", "notxml.urdf"], match="notxml.urdf"),
    Case("urdf-binary", ["rank", "binary.urdf"], match="binary.urdf"),
    Case("urdf-empty", ["rank", "empty.urdf"], match="empty.urdf"),
    Case("urdf-missing", ["rank", "missing.urdf"], match="missing.urdf"),
    Case("urdf-unparsable-mass", ["rank", "nomass.urdf"], match="mass .* is not a float"),
    Case("simulate-negative-mass", ["identify", "negmass.urdf", *SIM], match=r"l1|j1"),
    Case("simulate-non-pd-inertia", ["identify", "nonpd.urdf", *SIM], match=r"j1|l1"),
    Case(  # view needs no inertias (issue 24): the kinematics only, no refusal
        "view-simulate-negative-mass",
        ["view", "negmass.urdf", "--simulate", "--html", "o.html"],
        status=0,
        outputs=("o.html",),
    ),
    Case(
        "adapt-negative-mass",
        ["adapt", "negmass.urdf", "--duration", "0.2"],
        match=r"j1.*mass|mass.*j1|physically",
    ),
    # --- rule 8: memory estimated up front
    Case(
        "simulation-too-large",
        ["identify", "msd", "--simulate", "--duration", "1e9", "--rate", "1e6"],
        match="GiB",
    ),
    Case(
        "view-simulation-too-large",
        ["view", "msd", "--simulate", "--duration", "1e12", "--html", "o.html"],
        match="GiB",
    ),
    # --- rule 9: escaping; these must work
    Case(
        "dollar-in-data-file-name",
        ["identify", "msd", "--data", "we$ird_$x^{2}$.npz", "--report", "rep"],
        status=0,
        outputs=("rep/index.html", "rep/torque_fit.png"),
    ),
    Case(
        "script-in-data-file-name",
        ["identify", "msd", "--data", "<script>alert(1)<i>.npz", "--report", "rep"],
        status=0,
        outputs=("rep/index.html",),
        check=_escaped_report,
    ),
    Case(
        "dollar-and-tags-in-joint-name",
        ["view", "dollar.urdf", "--html", "scene.html"],
        status=0,
        outputs=("scene.html",),
        check=_escaped_scene,
    ),
    Case(
        "dollar-in-joint-name-report",
        ["rank", "dollar.urdf", "--report", "rep", "--samples", "40"],
        status=0,
        outputs=("rep/index.html", "rep/singular_values.png"),
        check=_escaped_names_report,
    ),
    # --- special files and names
    Case("data-is-a-fifo", ["identify", "msd", "--data", "fifo.npz"], match="regular file"),
    Case(
        "view-data-is-a-fifo",
        ["view", "msd", "--data", "fifo.npz", "--html", "o.html"],
        match="regular file",
    ),
    Case("urdf-is-a-fifo", ["rank", "fifo.urdf"], match="fifo.urdf"),
    Case("data-is-dev-zero", ["identify", "msd", "--data", "/dev/zero"]),
    Case("json-name-too-long", ["rank", "msd", "--json", "a" * 300], match="too long"),
    Case("report-name-too-long", ["rank", "msd", "--report", "a" * 300], match="too long"),
    Case(
        "report-symlink-to-input-folder",
        ["identify", "msd", "--data", "data/inner.npz", "--report", "datalink", "--force"],
        match="holds the input",
    ),
    Case(
        "json-onto-input-through-folder-link",
        ["identify", "msd", "--data", "data/inner.npz", "--json", "datalink/inner.npz"],
        match="one of the inputs",
    ),
    Case(
        "non-utf8-data-name",
        [
            "identify",
            "msd",
            "--data",
            os.fsdecode(b"\xff\xfe-latin.npz"),
            "--report",
            "rep",
            "--json",
            "o.json",
        ],
        status=0,
        outputs=("rep/index.html", "o.json"),
    ),
    # --- the commands still work
    Case(
        "identify-npz-json",
        ["identify", "msd", "--data", "log.npz", "--json", "o.json"],
        status=0,
        outputs=("o.json",),
    ),
    Case(
        "identify-csv-json-and-report",
        ["identify", "msd", "--data", "log.csv", "--json", "o.json", "--report", "rep"],
        status=0,
        outputs=("o.json", "rep/index.html"),
    ),
    Case(
        "report-into-empty-folder",
        ["rank", "msd", "--report", "empty", "--samples", "30"],
        status=0,
        setup=lambda w: (w / "empty").mkdir(),
        outputs=("empty/index.html",),
    ),
]


def _params(cases):
    return [pytest.param(c, id=c.id, marks=c.marks) for c in cases]


@pytest.mark.parametrize("case", _params(CASES))
def test_cli_case(case: Case, work: Path, capfd):
    _all(work)
    if case.setup is not None:
        case.setup(work)
    check_case(case, work, capfd)


# ------------------------------------------------------ partial output, bugs
def test_json_not_published_when_the_report_fails(work, capfd, monkeypatch):
    from manip_id.viz import figures

    def broken(*args, **kwargs):
        raise ManipIdError("the residual figure failed")

    monkeypatch.setattr(figures, "residuals", broken)
    before = snapshot(work)
    status = main(["identify", "msd", "--data", "log.npz", "--json", "o.json", "--report", "rep"])
    err = capfd.readouterr().err
    errors = [line for line in error_lines(err) if not line.startswith("manip-id: warning:")]
    assert status == 2 and errors == ["manip-id: error: the residual figure failed"]
    assert snapshot(work) == before  # neither o.json nor rep, nor any temporary


@pytest.mark.parametrize(
    "exc, status, text",
    [
        (RuntimeError("boom"), 1, "internal error (a bug): RuntimeError: boom"),
        (TypeError("unhashable"), 1, "internal error (a bug): TypeError"),
        (KeyboardInterrupt(), 130, "interrupted"),
        (ManipIdError("bad\ninput on two lines"), 2, "error: bad; input on two lines"),
    ],
    ids=["runtime-error", "type-error", "keyboard-interrupt", "multiline-error"],
)
def test_the_one_exception_boundary(exc, status, text, work, capfd, monkeypatch):
    from manip_id.cli import _robots as robots  # the command's run function

    def fail(args):
        args.outputs.file("o.json", "--json")  # a reserved output must vanish too
        raise exc

    monkeypatch.setattr(robots, "run", fail)
    before = snapshot(work)
    assert main(["robots"]) == status
    err = capfd.readouterr().err
    assert "Traceback" not in err
    assert len(error_lines(err)) == 1 and text in err, err
    if status == 1:
        assert "rerun with --debug" in err
    assert snapshot(work) == before
    assert main(["robots", "--debug"]) == status  # the traceback only with --debug
    err = capfd.readouterr().err
    if status in (1, 2):
        assert "Traceback" in err


def test_library_warnings_become_one_line_each(work, capfd, monkeypatch):
    from manip_id.cli import _robots as robots  # the command's run function

    def noisy(args):
        for _ in range(3):
            np.float64(1.0) / np.float64(0.0)  # numpy RuntimeWarning, three times
            np.log(np.zeros(2))
        return 0

    monkeypatch.setattr(robots, "run", noisy)
    with np.errstate(all="warn"):
        assert main(["robots"]) == 0
    lines = error_lines(capfd.readouterr().err)
    assert lines == [
        "manip-id: warning: divide by zero encountered in scalar divide",
        "manip-id: warning: divide by zero encountered in log",
    ]
    assert not any("np.float64" in line or "np.log" in line for line in lines)  # no source


def test_urdfdom_stderr_is_captured(work, capfd):
    (work / "notxml.urdf").write_text("not xml")
    assert main(["rank", "notxml.urdf"]) == 2
    captured = capfd.readouterr()
    assert error_lines(captured.err) == [
        line for line in error_lines(captured.err) if line.startswith("manip-id: error:")
    ]
    assert "XML_ERROR" not in captured.err and "model.cpp" not in captured.err
    assert len(error_lines(captured.err)) == 1


# ------------------------------------------------------------- concurrency
def test_two_concurrent_runs_into_one_new_report(work):
    cmd = [sys.executable, "-m", "manip_id", "rank", "msd", "--samples", "30", "--report", "rep"]
    procs = [
        subprocess.Popen(cmd, cwd=work, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        for _ in range(2)
    ]
    results = [(p.wait(120), p.stderr.read().decode()) for p in procs]
    for p in procs:
        p.stdout.close()
        p.stderr.close()
    statuses = sorted(s for s, _ in results)
    assert statuses == [0, 2], results
    loser = next(err for s, err in results if s == 2)
    assert "another manip-id run" in loser or "not empty" in loser, loser
    assert len(error_lines(loser)) == 1
    assert (work / "rep" / "index.html").is_file()
    assert not (work / "rep" / ".manip-id-claim").exists()
    assert [p.name for p in work.iterdir() if p.name.startswith(".")] == []


def test_claims_race_in_process(tmp_path):
    from manip_id.errors import ReportBusyError
    from manip_id.viz.report import claim_report

    first = claim_report(tmp_path / "rep")
    with pytest.raises(ReportBusyError):
        claim_report(tmp_path / "rep")
    first.discard()
    assert not (tmp_path / "rep").exists()
    claim_report(tmp_path / "rep").discard()


# ----------------------------------------------------------------- signals
def _wait_for(predicate, timeout: float, proc=None) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        if proc is not None and proc.poll() is not None:
            return False
        time.sleep(0.05)
    return False


def _interactive_signals() -> None:
    """In the child: SIGINT handled as in a terminal, even when pytest itself runs in the
    background (a non-interactive shell starts background jobs with SIGINT ignored, and an
    ignored signal stays ignored across exec)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize(
    "sig, status", [(signal.SIGTERM, 143), (signal.SIGINT, 130)], ids=["sigterm", "sigint"]
)
def test_signal_while_the_report_is_built(work, sig, status):
    before = snapshot(work)
    cmd = [
        sys.executable,
        "-m",
        "manip_id",
        "identify",
        "msd",
        "--simulate",
        "--duration",
        "60",
        "--json",
        "o.json",
        "--report",
        "rep",
    ]
    proc = subprocess.Popen(
        cmd,
        cwd=work,
        env=ENV,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        preexec_fn=_interactive_signals,
    )
    try:
        building = _wait_for(lambda: any(work.glob(".rep.tmp-*")), 120, proc)
        assert building, "the report's temporary folder never appeared"
        proc.send_signal(sig)
        assert proc.wait(60) == status
        err = proc.stderr.read().decode()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stderr.close()
    assert "Traceback" not in err
    assert snapshot(work) == before, "temporaries or outputs left behind"


def test_sigterm_stops_the_worker_processes(work):
    import psutil

    cmd = [
        sys.executable,
        "-m",
        "manip_id",
        "identify",
        "ur5",
        "--simulate",
        "--duration",
        "400",
        "--workers",
        "2",
        "--json",
        "o.json",
    ]
    proc = subprocess.Popen(
        cmd, cwd=work, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    parent = psutil.Process(proc.pid)
    children: list = []
    try:

        def forked():
            children[:] = parent.children(recursive=True)
            return len(children) >= 2

        assert _wait_for(forked, 240, proc), "no worker processes appeared"
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(60) == 143
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stderr.close()
    gone, alive = psutil.wait_procs(children, timeout=10)
    assert alive == []
    assert not (work / "o.json").exists()
    assert [p.name for p in work.iterdir() if p.name.startswith(".")] == []


def _listening(pids) -> list[tuple[int, str]]:
    import psutil

    out = []
    for conn in psutil.net_connections(kind="inet"):
        if conn.status == psutil.CONN_LISTEN and conn.pid in pids:
            out.append((conn.pid, conn.laddr.ip))
    return out


@pytest.mark.parametrize(
    "sig, status", [(signal.SIGTERM, 143), (signal.SIGINT, 0)], ids=["sigterm", "sigint"]
)
def test_view_serve_binds_loopback_and_stops_its_server(work, sig, status):
    import psutil

    cmd = [sys.executable, "-m", "manip_id", "view", "msd", "--serve", "--no-inertia"]
    proc = subprocess.Popen(
        cmd,
        cwd=work,
        env=ENV,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        preexec_fn=_interactive_signals,
    )
    parent = psutil.Process(proc.pid)
    family: list = []
    try:
        line = proc.stdout.readline().decode()
        assert "meshcat viewer at http://127.0.0.1:" in line, line
        family = parent.children(recursive=True)
        pids = {proc.pid, *(c.pid for c in family)}
        addresses = _listening(pids)
        assert len(addresses) >= 2, addresses  # the web server and the ZeroMQ socket
        assert {ip for _, ip in addresses} == {"127.0.0.1"}, addresses
        proc.send_signal(sig)
        assert proc.wait(30) == status
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        err = proc.stderr.read().decode()
        proc.stdout.close()
        proc.stderr.close()
        for child in family:
            if child.is_running():
                child.kill()
    assert "Traceback" not in err
    gone, alive = psutil.wait_procs(family, timeout=10)
    assert alive == [], "the meshcat server outlived the command"


def test_meshcat_server_dies_with_a_killed_parent(work):
    """SIGKILL cannot be handled: the server itself ends when its parent is gone."""
    import psutil

    cmd = [sys.executable, "-m", "manip_id", "view", "msd", "--serve", "--no-inertia"]
    proc = subprocess.Popen(
        cmd, cwd=work, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL
    )
    family: list = []
    try:
        assert "meshcat viewer" in proc.stdout.readline().decode()
        family = psutil.Process(proc.pid).children(recursive=True)
        assert family
        proc.kill()
        proc.wait(10)
        gone, alive = psutil.wait_procs(family, timeout=10)
        assert alive == []
    finally:
        proc.stdout.close()
        for child in family:
            if child.is_running():
                child.kill()


def test_host_rules():
    from manip_id.errors import InputError
    from manip_id.viz.meshcat_server import check_host, is_loopback

    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.4")
    for bad in ("", "no such host.invalid", "a b"):
        with pytest.raises(InputError):
            check_host(bad)


def test_non_loopback_host_warns(work, capfd, monkeypatch):
    """--host 0.0.0.0 warns once; the server is not started here (start_server is replaced)."""
    from manip_id.viz import meshcat_scene

    def no_server(self, open_browser=False, host="127.0.0.1"):
        raise ManipIdError(f"would serve on {host}")

    monkeypatch.setattr(meshcat_scene.RobotScene, "serve", no_server)
    assert main(["view", "msd", "--serve", "--host", "0.0.0.0", "--no-inertia"]) == 2
    lines = error_lines(capfd.readouterr().err)
    assert lines[0].startswith("manip-id: warning: --host 0.0.0.0: the viewer is reachable")
    assert lines[1] == "manip-id: error: would serve on 0.0.0.0"


# --------------------------------------------------------------- NPZ bomb
def _npy_header(shape) -> bytes:
    import io

    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buf, {"descr": "<f8", "fortran_order": False, "shape": tuple(shape)}
    )
    return buf.getvalue()


def _bomb(path: Path, n: int = 40_000_000, width: int = 6) -> None:
    """A real NPZ of zeros (t, q, dq, tau) whose inflated size is n * (1 + 3 width) * 8 bytes.

    Written by hand: each member is deflated once per 16 MiB block of zeros (blocks
    separated by full flushes repeat exactly), so making it costs seconds, not the
    gigabytes it declares.
    """
    block = bytes(16 << 20)
    entries, offset = [], 0
    with open(path, "wb") as fh:
        for name, shape in (
            ("t", (n,)),
            ("q", (n, width)),
            ("dq", (n, width)),
            ("tau", (n, width)),
        ):
            header = _npy_header(shape)
            size = 8 * int(np.prod(shape))
            comp = zlib.compressobj(9, zlib.DEFLATED, -15)
            head = comp.compress(header) + comp.flush(zlib.Z_FULL_FLUSH)
            one = comp.compress(block) + comp.flush(zlib.Z_FULL_FLUSH)
            full, rest = divmod(size, len(block))
            tail = comp.compress(bytes(rest)) + comp.flush()
            crc = zlib.crc32(header)
            for _ in range(full):
                crc = zlib.crc32(block, crc)
            crc = zlib.crc32(bytes(rest), crc)
            csize = len(head) + full * len(one) + len(tail)
            usize = len(header) + size
            fname = f"{name}.npy".encode()
            local = struct.pack(
                "<IHHHHHIIIHH",
                0x04034B50,
                20,
                0,
                8,
                0,
                0x21,
                crc & 0xFFFFFFFF,
                csize,
                usize,
                len(fname),
                0,
            )
            fh.write(local + fname + head)
            for _ in range(full):
                fh.write(one)
            fh.write(tail)
            entries.append((fname, crc & 0xFFFFFFFF, csize, usize, offset))
            offset += len(local) + len(fname) + csize
        cd_start = offset
        for fname, crc, csize, usize, off in entries:
            rec = struct.pack(
                "<IHHHHHHIIIHHHHHII",
                0x02014B50,
                20,
                20,
                0,
                8,
                0,
                0x21,
                crc,
                csize,
                usize,
                len(fname),
                0,
                0,
                0,
                0,
                0,
                off,
            )
            fh.write(rec + fname)
            offset += len(rec) + len(fname)
        fh.write(
            struct.pack(
                "<IHHHHIIH",
                0x06054B50,
                0,
                0,
                len(entries),
                len(entries),
                offset - cd_start,
                cd_start,
                0,
            )
        )


@pytest.fixture(scope="module")
def bomb(tmp_path_factory):
    path = tmp_path_factory.mktemp("bomb") / "bomb.npz"
    _bomb(path)
    return path


def test_the_bomb_is_what_it_claims(bomb):
    import zipfile

    assert bomb.stat().st_size < 8 * 2**20  # a few MB on disk
    with zipfile.ZipFile(bomb) as zf:
        assert sorted(zf.namelist()) == ["dq.npy", "q.npy", "t.npy", "tau.npy"]
        assert zf.getinfo("tau.npy").file_size > 1.9e9
        with zf.open("tau.npy") as fh:  # a valid array header, then zeros
            assert np.lib.format.read_magic(fh) == (1, 0)
            shape, _, _ = np.lib.format.read_array_header_1_0(fh)
            assert shape == (40_000_000, 6)
            assert fh.read(4096) == bytes(4096)


@pytest.mark.parametrize("command", ["identify", "rank", "view"])
def test_npz_bomb_refused_before_inflating(bomb, tmp_path, command):
    """Run under a 3 GiB address-space limit: inflating the bomb (6 GB) would fail loudly."""
    argv = [command, "ur5", "--data", str(bomb)]
    if command == "view":
        argv += ["--html", str(tmp_path / "o.html")]
    code = (
        "import resource, sys; resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30)); "
        "from manip_id.cli import main; sys.exit(main(sys.argv[1:]))"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code, *argv], cwd=tmp_path, env=ENV, capture_output=True, timeout=120
    )
    err = proc.stderr.decode()
    assert "Traceback" not in err
    assert proc.returncode == 2, err
    assert len(error_lines(err)) == 1, err
    if command == "identify":  # streamed in bounded memory: the zeros of t are refused
        assert re.search(r"budget|memory|GiB|MiB|time must increase", err), err
    else:  # a whole-file read: refused for its size, from the headers (the budget
        # respects the 3 GiB address-space limit), not by a failed allocation
        assert "more than the budget" in err and "allocate" not in err, err
    assert list(tmp_path.iterdir()) == []


# -------------------------------------------------------------- API cases
def _api_cases():
    from manip_id.errors import DataError, InputError, OutputError, RobotError

    def robot(name="msd"):
        from manip_id.robot.model import load_robot

        return load_robot(name)

    def load(path):
        from manip_id.datasets import load_dataset

        return load_dataset(path)

    def dataset(**over):
        from manip_id.datasets import Dataset

        a = {k: v for k, v in msd_arrays().items() if k != "joint_names"}
        a.update(over)
        return Dataset(**a)

    def sim(**kw):
        from manip_id.simulation import simulate
        from manip_id.trajectories import random_trajectory

        r = robot()
        args = dict(duration=1.0, rate=50.0)
        args.update(kw)
        return simulate(r, random_trajectory(r, harmonics=3, seed=0), **args)

    def simulate_urdf(w, **arm):
        from manip_id.robot.model import load_robot
        from manip_id.simulation import simulate
        from manip_id.trajectories import random_trajectory

        r = load_robot(str(arm_urdf(w / "x.urdf", **arm)))
        return simulate(r, random_trajectory(r, harmonics=3, seed=0), duration=1.0, rate=50.0)

    def identify(**kw):
        from manip_id.identification import identify as ident

        a = msd_arrays()
        args = dict(q=a["q"], dq=a["dq"], ddq=a["ddq"], tau=a["tau"])
        args.update(kw)
        return ident(robot(), (args["q"], args["dq"], args["ddq"], args["tau"]))

    def report(w, *, force=False, **kw):
        from manip_id.viz.report import ReportContent, write_report

        args = dict(title="t", summary={}, parameter_table=[], figures={})
        args.update(kw)
        return write_report(w / "rep", ReportContent(**args), force=force)

    def foreign(w):
        (w / "rep").mkdir()
        (w / "rep" / "keep.txt").write_text("keep")
        return report(w, force=True)

    def atomic(w):
        from manip_id._io import atomic_write_text

        (w / "d").mkdir()
        return atomic_write_text(w / "d", "x")

    def save(w):
        from manip_id.datasets import save_dataset

        return save_dataset(dataset(), w / "a_file.txt" / "x.npz")

    return [
        ("load-binary-csv", lambda w: load(w / "binary.csv"), DataError),
        ("load-missing-file", lambda w: load(w / "missing.npz"), DataError),
        ("load-int-path", lambda w: load(123), ManipIdError),
        ("load-none-path", lambda w: load(None), ManipIdError),
        ("load-random-npz", lambda w: load(w / "random.npz"), DataError),
        ("load-folder-not-a-log", lambda w: load(w / "notalog"), DataError),
        ("load-empty-csv", lambda w: load(w / "empty.csv"), DataError),
        ("load-object-npz", lambda w: load(w / "pickled.npz"), DataError),
        ("load-complex-npz", lambda w: load(w / "complex.npz"), DataError),
        ("load-huge-npz", lambda w: load(w / "huge.npz"), DataError),
        ("load-tiny-npz", lambda w: load(w / "tiny.npz"), DataError),
        ("dataset-complex-tau", lambda w: dataset(tau=msd_arrays()["tau"] * 1j), DataError),
        ("dataset-tau-1e300", lambda w: dataset(tau=msd_arrays()["tau"] * 1e300), DataError),
        ("dataset-tau-1e-300", lambda w: dataset(tau=msd_arrays()["tau"] * 1e-300), DataError),
        ("dataset-string-q", lambda w: dataset(q="abc"), DataError),
        ("dataset-dict-t", lambda w: dataset(t={"a": 1}), DataError),
        ("robot-int-name", lambda w: robot(123), RobotError),
        ("robot-missing-urdf", lambda w: robot(str(w / "missing.urdf")), RobotError),
        ("robot-binary-urdf", lambda w: robot(str(w / "binary.urdf")), RobotError),
        ("simulate-negative-mass", lambda w: simulate_urdf(w, m1="-1"), ManipIdError),
        ("simulate-non-pd-inertia", lambda w: simulate_urdf(w, ixx="-0.5"), ManipIdError),
        ("simulate-duration-text", lambda w: sim(duration="abc"), InputError),
        ("simulate-too-large", lambda w: sim(duration=1e9, rate=1e6), InputError),
        ("simulate-negative-seed", lambda w: sim(seed=-1), InputError),
        ("identify-wrong-shape", lambda w: identify(q=np.zeros((5, 3))), InputError),
        ("identify-complex-tau", lambda w: identify(tau=msd_arrays()["tau"] * 1j), InputError),
        ("identify-tau-1e300", lambda w: identify(tau=msd_arrays()["tau"] * 1e300), InputError),
        ("identify-tau-1e-300", lambda w: identify(tau=msd_arrays()["tau"] * 1e-300), InputError),
        ("report-force-foreign-folder", foreign, OutputError),
        ("report-parent-missing", lambda w: report(w / "no" / "where"), OutputError),
        ("atomic-write-onto-folder", atomic, OutputError),
        ("save-under-a-file", save, ManipIdError),
        ("robot-friction-int", lambda w: _load_robot_kw(friction=3), InputError),
        ("trajectory-seed-negative", lambda w: _traj(seed=-1), InputError),
        ("trajectory-seed-text", lambda w: _traj(seed="a"), InputError),
        ("trajectory-harmonics-text", lambda w: _traj(harmonics="x"), InputError),
        ("trajectory-harmonics-zero", lambda w: _traj(harmonics=0), InputError),
        ("perturb-rel-text", lambda w: _perturb("x"), InputError),
        ("perturb-seed-negative", lambda w: _perturb(0.1, seed=-1), InputError),
        ("simulate-noise-text", lambda w: sim(noise=MeasurementNoise(tau="x")), InputError),
        ("identify-workers-text", lambda w: _identify_kw(run={"workers": "x"}), InputError),
        ("identify-chunk-zero", lambda w: _identify_kw(run={"chunk": 0}), InputError),
        ("structural-seed-negative", lambda w: _structural(seed=-1), InputError),
        ("structural-tolerance-text", lambda w: _structural(tolerance="x"), InputError),
        ("structural-samples-text", lambda w: _structural(n_samples="x"), InputError),
        ("scene-label-int", lambda w: _scene_label(5), InputError),
        ("scene-label-slash", lambda w: _scene_label("a/b"), InputError),
        ("report-figures-text", lambda w: report(w, figures="x"), InputError),
        ("report-table-of-ints", lambda w: report(w, parameter_table=[1, 2]), InputError),
        ("report-summary-list", lambda w: report(w, summary=[1]), InputError),
        ("dataset-split-text", lambda w: dataset().split("a"), DataError),
        ("dataset-split-out-of-range", lambda w: dataset().split(1.5), DataError),
        ("dataset-slice-text", lambda w: dataset().slice("a", 3), InputError),
        ("reference-seed-negative", lambda w: _reference(seed=-1), InputError),
    ]


def _load_robot_kw(**kw):
    from manip_id.robot.model import load_robot

    return load_robot("msd", **kw)


def _traj(**kw):
    from manip_id.trajectories import random_trajectory

    return random_trajectory(_load_robot_kw(), **kw)


def _perturb(rel, **kw):
    from manip_id.simulation import perturb_parameters

    return perturb_parameters(_load_robot_kw(), rel, **kw)


def _identify_kw(**kw):
    from manip_id.identification import identify

    a = msd_arrays()
    return identify(_load_robot_kw(), (a["q"], a["dq"], a["ddq"], a["tau"]), **kw)


def _structural(**kw):
    from manip_id.identifiability import structural_analysis

    return structural_analysis(_load_robot_kw(), **kw)


def _scene_label(label):
    from manip_id.viz.meshcat_scene import RobotScene

    robot = _load_robot_kw()
    return RobotScene(robot).add_inertia(robot.nominal_parameters, label=label)


def _reference(**kw):
    from manip_id.control.closed_loop import default_reference

    return default_reference(_load_robot_kw(), **kw)


API_CASES = _api_cases()


@pytest.mark.parametrize("name, call, expected", API_CASES, ids=[c[0] for c in API_CASES])
def test_api_case(name, call, expected, work):
    _all(work)
    before = snapshot(work)
    with pytest.raises(ManipIdError) as info:
        call(work)
    assert isinstance(info.value, expected), (type(info.value), info.value)
    after = snapshot(work)
    assert {k: v for k, v in after.items() if k in before} == before
    made_by_the_case = ("x.urdf", "rep", "rep/keep.txt", "d")  # inputs the call itself writes
    assert [k for k in after if k not in before and k not in made_by_the_case] == []


def test_add_inertia_label_is_escaped(tmp_path):
    from manip_id.robot.model import load_robot
    from manip_id.viz.meshcat_scene import RobotScene

    robot = load_robot("msd")
    scene = RobotScene(robot, title="<b>title</b> & $x$")
    scene.add_inertia(robot.nominal_parameters, label='<img src=x onerror="alert(1)">')
    page = scene.html()
    assert "<img src=x" not in page and "&lt;img src=x" in page
    assert "<b>title</b>" not in page


def test_matplotlib_shows_dollars_literally(tmp_path):
    from manip_id.viz import figures

    t = np.linspace(0, 1, 50)
    tau = np.column_stack([np.sin(t), np.cos(t)])
    labels = figures.FigureOptions(title="file we$ird_$x$.npz $", joint_names=["j$1", "$x^{"])
    fig = figures.torque_fit(tmp_path / "f.png", t, tau, tau, options=labels)
    assert (tmp_path / "f.png").is_file()
    texts = [fig.axes[0].get_title(), *(ax.get_ylabel() for ax in fig.axes)]
    assert any("j$1" in s for s in texts) or any("$" in s for s in texts)
    assert all(not t.get_parse_math() for ax in fig.axes for t in (ax.title, ax.yaxis.label))


def test_report_manifest_and_json(tmp_path):
    from manip_id.viz.report import MANIFEST, ReportContent, write_report

    content = ReportContent(title="t", summary={"a": 1}, parameter_table=[], figures={})
    out = write_report(tmp_path / "rep", content)
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["written_by"] == "manip_id"
    assert sorted(manifest["files"]) == sorted(p.name for p in out.iterdir() if p.name != MANIFEST)
