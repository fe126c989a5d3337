"""Rows parsed once per run (manip_id.datasets.replay): a recorded request read back
equals the parse it replaces, block for block, and ``manip-id identify`` parses a CSV once."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _logs import log, save_npz
from conftest import get_robot

import manip_id.datasets.csv as csv_module
from manip_id.cli import main
from manip_id.datasets import FileSpec, RowCache, RowCounts, Window, iter_rows, open_source
from manip_id.datasets.stream import READ_CHUNK
from manip_id.errors import DataError

ROBOT = "ur5"
RATE = 200.0


@pytest.fixture(scope="module")
def robot():
    return get_robot(ROBOT, friction="viscous,coulomb")


def _write_csv(path, robot, t, q, dq, tau, bad_lines=()):
    """The log as CSV text written with numpy alone (17 digits: read back exactly);
    ``bad_lines``: data rows replaced by a line that is not numbers."""
    names = list(robot.dof_names)
    head = ",".join(["t", *(f"{p}_{n}" for p in ("q", "dq", "tau") for n in names)])
    rows = np.column_stack([t, q, dq, tau])
    lines = [",".join(f"{v:.17g}" for v in row) for row in rows]
    for k in bad_lines:
        lines[k] = "oops," + lines[k].split(",", 1)[1]
    path.write_text(head + "\n" + "\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def bad_csv(robot, tmp_path_factory):
    t, q, dq, _, tau = log(robot, n=1000, rate=RATE, seed=5)
    dq = dq.copy()
    dq[123, 2] = np.nan
    return _write_csv(tmp_path_factory.mktemp("replay") / "bad.csv", robot, t, q, dq, tau, [400])


def _pass(source, window, drop: bool):
    counts = RowCounts()
    blocks = list(iter_rows(source, window, drop_bad_rows=drop, chunk=64, counts=counts))
    return blocks, counts


@pytest.mark.parametrize(
    "window", [None, Window(0.5, 3.0, "s"), Window(1.0, None, "s"), Window(100, 900, "index")]
)
def test_a_replayed_pass_equals_a_parsed_one(robot, bad_csv, window):
    spec = FileSpec(bad_csv)
    want, want_counts = _pass(open_source(spec), window, True)
    assert want_counts.n_dropped == 2 and len(want) > 3
    with RowCache() as cache:
        for k in range(2):  # recorded, then read back
            got, counts = _pass(open_source(spec, cache=cache), window, True)
            assert counts == want_counts
            assert len(got) == len(want)
            for a, b in zip(got, want, strict=True):
                assert np.array_equal(a, b)
            if k == 0:
                parsed = cache.n_parsed
        assert cache.n_parsed == parsed and cache.n_replayed >= len(want)


@pytest.mark.parametrize(
    ("window", "where"), [(None, "sample 123"), (Window(200, 1000, "index"), "line 402")]
)
def test_a_replayed_pass_refuses_the_same_row(robot, bad_csv, window, where):
    spec = FileSpec(bad_csv)
    with pytest.raises(DataError) as direct:
        _pass(open_source(spec), window, False)
    assert where in str(direct.value)
    with RowCache() as cache:
        for _ in range(2):
            with pytest.raises(DataError) as replayed:
                _pass(open_source(spec, cache=cache), window, False)
            assert str(replayed.value) == str(direct.value)


def test_a_pass_stopped_early_is_resumed_not_parsed_again(robot, bad_csv):
    spec = FileSpec(bad_csv)
    whole, whole_counts = _pass(open_source(spec), None, True)
    with RowCache() as cache:
        src = open_source(spec, cache=cache)
        head = next(iter(src.chunks(64, 0, None)))  # the first block only
        assert np.array_equal(head[:, 0], whole[0][:, 0])
        short, _ = _pass(src, Window(None, 1.2, "s"), True)  # stops at 1.2 s
        assert 1 < len(short) < len(whole)
        got, counts = _pass(open_source(spec, cache=cache), None, True)
        assert counts == whole_counts
        for a, b in zip(got, whole, strict=True):
            assert np.array_equal(a, b)
        assert cache.n_parsed == -(-1000 // 64)  # each block of the file parsed once
    assert not list(cache._recordings)  # closed: the recordings removed


def test_a_fast_format_is_not_recorded(robot, tmp_path):
    t, q, dq, ddq, tau = log(robot, n=300, rate=RATE)
    path = save_npz(tmp_path / "l.npz", robot, t, q, dq, ddq, tau)
    with RowCache() as cache:
        src = open_source(FileSpec(path), cache=cache)
        assert src.format == "npz" and not hasattr(src, "cache")


@pytest.fixture(scope="module")
def logs(robot, tmp_path_factory):
    """One log without accelerations, 1.5 s at rest at its start, as NPZ and as CSV."""
    t, q, dq, ddq, tau = log(robot, n=3000, rate=RATE, seed=2)
    rest = 300
    q_a = np.repeat(q[:1], rest, axis=0)
    z = np.zeros((rest, robot.nv))
    model, data = robot.model, robot.model.createData()
    import pinocchio as pin

    g = np.array([pin.computeGeneralizedGravity(model, data, x) for x in q_a])
    t = np.arange(t.size + rest) / RATE
    q, dq, tau = np.vstack([q_a, q]), np.vstack([z, dq]), np.vstack([g, tau])
    folder = tmp_path_factory.mktemp("logs")
    npz = save_npz(folder / "log.npz", robot, t, q, dq, None, tau, with_ddq=False)
    return npz, _write_csv(folder / "log.csv", robot, t, q, dq, tau), t.size


def _identify(path, tmp_path, *extra, window=""):
    out = tmp_path / f"{path.suffix[1:]}.json"
    args = ["identify", ROBOT, "--friction", "viscous,coulomb", "--data", f"{path}{window}"]
    assert main([*args, *extra, "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    return doc, np.array([p["value"] for p in doc["base_parameters"]])


@pytest.mark.parametrize("compiled", [False, True])
@pytest.mark.parametrize(
    ("extra", "window"),
    [((), ""), (("--trim-standstill",), ""), (("--split", "0.7"), ""), ((), "@#100:#3000")],
)
def test_identify_parses_a_csv_once_and_equals_its_npz(
    logs, tmp_path, monkeypatch, extra, window, compiled
):
    npz, csv, n = logs
    if compiled:  # the compiled reader whatever the file's size (numba installed)
        pytest.importorskip("numba")
        monkeypatch.setattr(csv_module, "COMPILED_BYTES", 0)
    else:
        monkeypatch.setattr(csv_module, "_reader_of", lambda path, delimiter: "numpy")
    rows = []
    tables = csv_module.CsvSource._tables

    def counted(self, chunk, reader=None):
        for first, table in tables(self, chunk, reader):
            rows.append(table.shape[0])
            yield first, table

    monkeypatch.setattr(csv_module.CsvSource, "_tables", counted)
    doc_csv, est_csv = _identify(csv, tmp_path, *extra, window=window)
    # every data line parsed once, by the audit's pass (a row window: the tables of
    # READ_CHUNK lines up to its end)
    assert sum(rows) == (n if not window else min(n, -(-3000 // READ_CHUNK) * READ_CHUNK))
    doc_npz, est_npz = _identify(npz, tmp_path, *extra, window=window)
    assert doc_csv["n_samples"] == doc_npz["n_samples"]
    assert doc_csv["files"][0]["window"] == doc_npz["files"][0]["window"]
    if extra == ("--trim-standstill",):
        assert doc_csv["files"][0]["window"] is not None
        assert doc_csv["n_samples"] < n
    np.testing.assert_allclose(est_csv, est_npz, rtol=1e-12, atol=0)
