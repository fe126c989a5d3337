"""Dataset validation, NPZ/CSV round trips, column maps, the Panda log loader."""

from __future__ import annotations

import os
import warnings

import numpy as np
import pytest
from conftest import get_robot

from manip_id.datasets import (
    Dataset,
    check_robot,
    load_dataset,
    load_panda_gaz2019,
    save_dataset,
)
from manip_id.datasets.quality import encoder_resolution
from manip_id.errors import DataError, ManipIdError

NAMES = ("j1", "j2", "j3")


def _dataset(n=50, nv=3, ddq=True, seed=0, names=NAMES) -> Dataset:
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.5e-3, 1.5e-3, n))
    return Dataset(
        t=t,
        q=rng.uniform(-2, 2, (n, nv)),
        dq=rng.normal(size=(n, nv)),
        tau=rng.normal(size=(n, nv)) * 10,
        ddq=rng.normal(size=(n, nv)) if ddq else None,
        joint_names=names,
    )


def _same(a: Dataset, b: Dataset):
    for name in ("t", "q", "dq", "tau"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    if a.ddq is None:
        assert b.ddq is None
    else:
        np.testing.assert_array_equal(a.ddq, b.ddq)
    assert a.joint_names == b.joint_names


# ------------------------------------------------------------------- validation
def test_time_going_backwards():
    ds = _dataset()
    t = ds.t.copy()
    t[7] = t[5]
    with pytest.raises(DataError, match=r"time must increase strictly: t\[7\]=.* after t\[6\]"):
        Dataset(t=t, q=ds.q, dq=ds.dq, tau=ds.tau)


def test_nan_is_reported_with_sample_and_joint():
    ds = _dataset()
    tau = ds.tau.copy()
    tau[12, 1] = np.nan
    with pytest.raises(DataError, match="tau holds nan at sample 12, j2"):
        Dataset(t=ds.t, q=ds.q, dq=ds.dq, tau=tau, joint_names=NAMES)


def test_shape_mismatch_and_degrees_warning():
    ds = _dataset()
    with pytest.raises(DataError, match="tau.shape"):
        Dataset(t=ds.t, q=ds.q, dq=ds.dq, tau=ds.tau[:, :2])
    with pytest.warns(UserWarning, match="degrees"):
        Dataset(t=ds.t, q=np.degrees(ds.q) * 20, dq=ds.dq, tau=ds.tau)


# -------------------------------------------------------------------- round trips
@pytest.mark.parametrize("suffix", [".npz", ".csv"])
@pytest.mark.parametrize("ddq", [True, False])
def test_round_trip(tmp_path, suffix, ddq):
    ds = _dataset(ddq=ddq)
    path = save_dataset(ds, tmp_path / f"sub/data{suffix}")
    assert path.is_file()
    assert [p.name for p in path.parent.iterdir()] == [path.name]  # no temp file left behind
    _same(ds, load_dataset(path))


def test_npz_written_by_another_tool(tmp_path):
    """The interchange format: plain arrays t, q, dq, tau (+ ddq, joint_names)."""
    ds = _dataset()
    np.savez(
        tmp_path / "other.npz", t=ds.t, q=ds.q, dq=ds.dq, tau=ds.tau, joint_names=np.array(NAMES)
    )
    loaded = load_dataset(tmp_path / "other.npz")
    _same(Dataset(t=ds.t, q=ds.q, dq=ds.dq, tau=ds.tau, joint_names=NAMES), loaded)


@pytest.mark.parametrize(
    ("arrays", "match"),
    [({"t", "q", "dq"}, "lacks array"), ({"t", "q", "dq", "tau", "extra"}, "unexpected array")],
)
def test_npz_with_wrong_arrays(tmp_path, arrays, match):
    ds = _dataset()
    values = {"t": ds.t, "q": ds.q, "dq": ds.dq, "tau": ds.tau, "extra": ds.t}
    np.savez(tmp_path / "x.npz", **{k: values[k] for k in arrays})
    with pytest.raises(DataError, match=match):
        load_dataset(tmp_path / "x.npz")


def test_csv_header_layout(tmp_path):
    ds = _dataset(ddq=False)
    path = save_dataset(ds, tmp_path / "d.csv")
    header = path.read_text().splitlines()[0]
    assert header == "t,q_j1,q_j2,q_j3,dq_j1,dq_j2,dq_j3,tau_j1,tau_j2,tau_j3"


def test_csv_with_a_column_map(tmp_path):
    ds = _dataset(ddq=False)
    # another layout: time in ms last, interleaved per joint, other names
    cols, header = [], []
    for j in range(3):
        cols += [ds.tau[:, j], ds.q[:, j], ds.dq[:, j]]
        header += [f"effort{j}", f"pos{j}", f"vel{j}"]
    cols.append(ds.t)
    header.append("stamp")
    (tmp_path / "o.csv").write_text(
        ",".join(header)
        + "\n"
        + "\n".join(",".join(repr(float(v)) for v in row) for row in np.column_stack(cols))
        + "\n"
    )
    loaded = load_dataset(
        tmp_path / "o.csv",
        columns={
            "t": "stamp",
            "q": "pos*",
            "dq": ["vel0", "vel1", "vel2"],
            "tau": "effort*",
            "joint_names": list(NAMES),
        },
    )
    _same(Dataset(t=ds.t, q=ds.q, dq=ds.dq, tau=ds.tau, joint_names=NAMES), loaded)


def test_csv_without_header_by_index(tmp_path):
    ds = _dataset(ddq=False, names=None)
    np.savetxt(
        tmp_path / "n.csv", np.column_stack([ds.t, ds.q, ds.dq, ds.tau]), delimiter=",", fmt="%.17g"
    )
    loaded = load_dataset(
        tmp_path / "n.csv", columns={"t": 0, "q": [1, 2, 3], "dq": [4, 5, 6], "tau": [7, 8, 9]}
    )
    _same(ds, loaded)


def test_csv_without_velocities_differentiates_q(tmp_path):
    t = np.arange(400) / 200.0
    q = np.column_stack([np.sin(t), t**2])
    text = "t,q_a,q_b,tau_a,tau_b\n" + "\n".join(
        f"{a:.17g},{b:.17g},{c:.17g},0,0" for a, b, c in zip(t, q[:, 0], q[:, 1], strict=True)
    )
    (tmp_path / "nov.csv").write_text(text + "\n")
    loaded = load_dataset(tmp_path / "nov.csv")
    assert loaded.joint_names == ("a", "b")
    np.testing.assert_allclose(loaded.dq[:, 1], 2 * t, atol=1e-9)
    np.testing.assert_allclose(loaded.dq[:, 0], np.cos(t), atol=1e-5)


@pytest.mark.parametrize(
    ("columns", "match"),
    [
        ({"t": "time"}, "column 'time' of 't' is not in"),
        ({"q": "pos*"}, "pattern 'pos\\*' of 'q' matches no column"),
        ({"q": [1, 2, 99]}, "refers to column 99"),
        ({"torque": "x"}, "unknown field"),
    ],
)
def test_column_map_that_does_not_fit(tmp_path, columns, match):
    path = save_dataset(_dataset(ddq=False), tmp_path / "d.csv")
    with pytest.raises(DataError, match=match):
        load_dataset(path, columns=columns)


@pytest.mark.parametrize(
    ("name", "fmt", "match"),
    [
        ("missing.npz", None, "no such data file"),
        ("d.h5", None, "unknown data format"),
        ("d.csv", "parquet", "unknown data format 'parquet'"),
    ],
)
def test_bad_paths_and_formats(tmp_path, name, fmt, match):
    (tmp_path / "d.h5").write_text("x")
    (tmp_path / "d.csv").write_text("t,q_a,dq_a,tau_a\n0,0,0,0\n1,0,0,0\n")
    with pytest.raises(DataError, match=match):
        load_dataset(tmp_path / name, format=fmt)


def test_csv_time_going_backwards_names_the_file(tmp_path):
    (tmp_path / "b.csv").write_text("t,q_a,dq_a,tau_a\n0,0,0,0\n1,0,0,0\n0.5,0,0,0\n")
    with pytest.raises(DataError, match=r"b.csv: time must increase strictly: t\[2\]=0.5"):
        load_dataset(tmp_path / "b.csv")


def test_save_never_leaves_a_partial_file(tmp_path, monkeypatch):
    path = tmp_path / "d.npz"
    save_dataset(_dataset(seed=1), path)
    before = path.read_bytes()

    def boom(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises((OSError, ManipIdError), match="disk full"):  # OutputError in newer _io
        save_dataset(_dataset(seed=2), path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.npz"]


# ------------------------------------------------------------------------ robot
def test_check_robot():
    robot = get_robot("panda")
    n = 10
    ok = Dataset(
        t=np.arange(n) * 1e-3,
        q=np.tile((robot.lower + robot.upper) / 2, (n, 1)),  # within the position limits
        dq=np.zeros((n, 7)),
        tau=np.zeros((n, 7)),
        joint_names=tuple(robot.dof_names),
    )
    check_robot(ok, robot)
    with pytest.raises(DataError, match=r"the data have 3 joints .* robot 'panda' has nq=7, nv=7"):
        check_robot(_dataset(), robot)
    swapped = tuple(reversed(robot.dof_names))
    with pytest.raises(DataError, match="in the order"):
        check_robot(Dataset(t=ok.t, q=ok.q, dq=ok.dq, tau=ok.tau, joint_names=swapped), robot)


# ------------------------------------------------------------------ the real log
def test_panda_log_loads(panda_log):
    ds = load_dataset(panda_log)
    assert ds.n_samples == 20544
    assert ds.joint_names == tuple(f"panda_joint{i}" for i in range(1, 8))
    assert ds.t[0] == 0.0 and ds.duration == pytest.approx(21.0, abs=0.01)
    first = np.loadtxt(panda_log / "rbt_log_positions.txt", max_rows=14)
    np.testing.assert_array_equal(ds.q[:2].ravel(), first)  # sample-major, one value per line
    check_robot(ds, get_robot("panda"))


def test_panda_log_with_missing_file(tmp_path):
    (tmp_path / "rbt_log_time.txt").write_text("0\n0.001\n")
    with pytest.raises(DataError, match="lacks rbt_log_positions.txt"):
        load_panda_gaz2019(tmp_path)
    with pytest.raises(DataError, match="neither a Panda log"):
        load_dataset(tmp_path)


def test_panda_log_with_wrong_count(tmp_path):
    for f, k in (("time", 3), ("positions", 21), ("velocity", 21), ("torques", 20)):
        (tmp_path / f"rbt_log_{f}.txt").write_text(
            "\n".join(str(i * 1e-3) for i in range(k)) + "\n"
        )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(DataError, match="has 20 values but 7 x 3 time stamps = 21"):
            load_dataset(tmp_path)


@pytest.mark.parametrize("n", [0, 1, 2, 5, 65536, 65537, 65538, 140001])
def test_encoder_resolution_in_blocks_is_the_smallest_step_of_the_whole(n):
    """Evaluated in blocks of rows (no (N, nq) temporaries), the smallest non-zero step
    per column equals numpy's on the whole array, across block edges; a joint that never
    moves has inf."""
    rng = np.random.default_rng(n)
    q = np.round(rng.standard_normal((n, 3)).cumsum(axis=0) * 1e3) / 1e3  # [rad], 1 mrad steps
    if n:
        q[:, 2] = 0.25
        q[min(n - 1, 65536), 0] += 1e-7  # one tiny step, at a block edge for the long ones
    steps = np.abs(np.diff(q, axis=0))
    steps[steps == 0] = np.inf
    want = steps.min(axis=0) if steps.shape[0] else np.full(3, np.inf)
    assert np.array_equal(encoder_resolution(q), want)
