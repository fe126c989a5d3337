"""The audit's one pass over a file (manip_id.audit.reading) against the whole array.

The reference reads the same rows into one array (``collect`` of ``iter_rows``, the
audit's former reader) and computes each figure with numpy on all rows; the file has a
time gap, dropped bad rows, rest at both edges, a flipped sign and a delay, and is read
in blocks much shorter than the central window, so that blocks are let go on the way.
"""

from __future__ import annotations

import numpy as np
import pytest
from _logs import log, save_npz
from conftest import get_robot

import manip_id.audit.reading as reading
from manip_id.audit import AuditOptions, audit_file
from manip_id.audit.reading import read_pass
from manip_id.datasets import iter_rows, open_source
from manip_id.datasets.quality import STANDSTILL
from manip_id.datasets.stream import collect

RATE, LAG, REST, WINDOW = 200.0, 5, 400, 700


@pytest.fixture(scope="module")
def robot():
    return get_robot("ur5", friction="viscous,coulomb")


@pytest.fixture(scope="module")
def path(robot, tmp_path_factory):
    t, q, dq, ddq, tau = log(robot, n=3000 + LAG, rate=RATE, seed=5)
    t, q, dq, ddq, tau = t[LAG:], q[LAG:], dq[LAG:], ddq[LAG:], tau[:-LAG].copy()  # delay
    tau[:, 2] *= -1  # flipped sign
    nv = robot.nv
    zeros = np.zeros((REST, nv))
    q = np.vstack([np.repeat(q[:1], REST, 0), q, np.repeat(q[-1:], REST, 0)])
    dq, ddq = np.vstack([zeros, dq, zeros]), np.vstack([zeros, ddq, zeros])
    tau = np.vstack([np.repeat(tau[:1], REST, 0), tau, np.repeat(tau[-1:], REST, 0)])
    t = np.arange(q.shape[0]) / RATE
    keep = np.ones(t.size, bool)
    keep[1500:1530] = False  # a gap of 30 rows
    rng = np.random.default_rng(1)
    bad = rng.choice(np.flatnonzero(keep), 40, replace=False)
    tau[bad, rng.integers(0, nv, 40)] = 1e184  # dropped with drop_bad_rows
    out = tmp_path_factory.mktemp("stream") / "log.npz"
    return save_npz(out, robot, t[keep], q[keep], dq[keep], ddq[keep], tau[keep])


def _rows(robot, path, chunk):
    src = open_source(path, joint_names=list(robot.dof_names))
    return src, iter_rows(src, drop_bad_rows=True, chunk=chunk)


@pytest.mark.parametrize("capacity", [None, "rows", 1000])
@pytest.mark.parametrize("chunk", [64, 333, 100_000])
def test_one_pass_equals_the_whole_array(robot, path, chunk, capacity, monkeypatch):
    """Also with the positions filled in place: for the file's row count (an upper bound:
    bad rows are dropped) and for a count too small (the rows so far become blocks)."""
    monkeypatch.setattr(reading, "FIT_ROWS", WINDOW)
    src, rows = _rows(robot, path, chunk)
    cap = src.n_rows if capacity == "rows" else capacity
    got = read_pass(rows, src.layout, src.joint_names, STANDSTILL, cap)
    src, rows = _rows(robot, path, 100_000)
    ds = collect(rows, src.layout, src.joint_names)
    n = ds.n_samples
    assert got.n_samples == n and n > WINDOW
    np.testing.assert_array_equal(got.t, ds.t)
    np.testing.assert_array_equal(got.q, ds.q)
    still = np.abs(ds.dq) < STANDSTILL
    np.testing.assert_array_equal(got.still, still.mean(axis=0))
    moving = np.flatnonzero(~still.all(axis=1))
    assert got.moving == (moving[0], moving[-1])
    assert 0 < moving[0] and moving[-1] < n - 1  # rest at both edges
    np.testing.assert_allclose(got.tau_mean, ds.tau.mean(axis=0), rtol=1e-12)
    start = (n - WINDOW) // 2
    for name in ("t", "q", "dq", "tau", "ddq"):
        np.testing.assert_array_equal(
            getattr(got.central, name), getattr(ds, name)[start : start + WINDOW]
        )


def test_audit_findings_do_not_depend_on_the_blocks(robot, path, monkeypatch):
    monkeypatch.setattr(reading, "FIT_ROWS", 2000)
    whole = audit_file(robot, path, AuditOptions(drop_bad_rows=True, read_chunk=100_000))
    small = audit_file(robot, path, AuditOptions(drop_bad_rows=True, read_chunk=97))
    assert small.to_dict() == whole.to_dict()
    text = " ".join(whole.findings)
    assert "40 bad rows dropped" in text and "sign flipped on joint elbow_joint" in text
    assert "--trim-standstill keeps" in text and "lags the motion stream" in text
    assert whole.rest == pytest.approx((REST / RATE, REST / RATE), abs=2 / RATE)
