"""Streamed readers: NPZ by its .npy headers, CSV in row chunks, file specs and windows."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

from manip_id.datasets import (
    FileSpec,
    Layout,
    Window,
    iter_rows,
    load_dataset,
    open_source,
    parse_file_spec,
    save_dataset,
)
from manip_id.datasets.npz import inspect_npz
from manip_id.errors import DataError, InputError


def _arrays(n=1000, nv=3, seed=0):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.5e-3, 1.5e-3, n))
    return {
        "t": t,
        "q": rng.uniform(-2, 2, (n, nv)),
        "dq": rng.normal(size=(n, nv)),
        "tau": rng.normal(size=(n, nv)) * 10,
        "ddq": rng.normal(size=(n, nv)),
    }


def _rows(path, chunk, **kw):
    src = open_source(FileSpec(path, **kw))
    return src, np.vstack(list(src.chunks(chunk)))


@pytest.mark.parametrize("compressed", [False, True])
@pytest.mark.parametrize("chunk", [1, 7, 1000, 4096])
def test_npz_chunks_equal_the_arrays(tmp_path, compressed, chunk):
    a = _arrays()
    path = tmp_path / "d.npz"
    (np.savez_compressed if compressed else np.savez)(path, **a)
    src, rows = _rows(path, chunk)
    assert src.n_rows == 1000 and src.layout == Layout(3, 3, True)
    np.testing.assert_array_equal(
        rows, np.column_stack([a[k] for k in ("t", "q", "dq", "tau", "ddq")])
    )
    part = np.vstack(list(src.chunks(64, 100, 321)))
    np.testing.assert_array_equal(part, rows[100:321])


def test_npz_other_dtypes_and_fortran_order(tmp_path):
    a = _arrays(n=50)
    path = tmp_path / "f.npz"
    np.savez(
        path,
        t=a["t"].astype(">f8"),
        q=np.asfortranarray(a["q"]),
        dq=a["dq"].astype(np.float32),
        tau=a["tau"].astype(np.int64),
    )
    _, rows = _rows(path, 16)
    np.testing.assert_array_equal(rows[:, 0], a["t"])
    np.testing.assert_array_equal(rows[:, 1:4], a["q"])
    np.testing.assert_array_equal(rows[:, 4:7], a["dq"].astype(np.float32))
    np.testing.assert_array_equal(rows[:, 7:10], a["tau"].astype(np.int64))


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda a: a.update(q=a["q"][:-1]), r"t.shape=\(1000,\) but q.shape=\(999, 3\)"),
        (
            lambda a: a.update(tau=a["tau"][:, :2]),
            r"dq.shape=\(1000, 3\) but tau.shape=\(1000, 2\)",
        ),
        (lambda a: a.update(tau=a["tau"] + 1j), "complex"),
        (lambda a: a.update(t=a["t"][:, None]), "t must have 1 dimension"),
        (lambda a: a.update(q=np.array(["x"] * 1000)), "must be numeric"),
    ],
)
def test_npz_headers_checked_before_reading(tmp_path, mutate, match):
    a = _arrays()
    a.pop("ddq")
    mutate(a)
    path = tmp_path / "bad.npz"
    np.savez(path, **a)
    with pytest.raises(DataError, match=match):
        open_source(FileSpec(path))


def test_npz_truncated_member_and_memory_budget(tmp_path):
    a = _arrays()
    path = tmp_path / "d.npz"
    np.savez(path, **a)
    members, lay = inspect_npz(path)
    assert members["q"].shape == (1000, 3) and lay.width == 13
    with pytest.raises(DataError, match=r"need 0 MiB in memory, more than the budget"):
        inspect_npz(path, max_bytes=1000)
    # a member whose header claims more rows than it holds
    lie = tmp_path / "lie.npz"
    with zipfile.ZipFile(path) as zin, zipfile.ZipFile(lie, "w") as zout:
        for info in zin.infolist():
            data = zin.read(info)
            if info.filename == "q.npy":
                data = data.replace(b"(1000, 3)", b"(9000, 3)")
            zout.writestr(info.filename, data)
    with pytest.raises(
        DataError, match=r"lie.npz: member q.npy declares shape \(9000, 3\).*truncated"
    ):
        open_source(FileSpec(lie))
    (tmp_path / "not.npz").write_bytes(b"plain text")
    with pytest.raises(DataError, match="cannot read .*not.npz as NPZ"):
        load_dataset(tmp_path / "not.npz")


@pytest.mark.parametrize("chunk", [3, 10, 999, 5000])
def test_csv_chunks_equal_the_whole_file(tmp_path, chunk):
    a = _arrays()
    from manip_id.datasets import Dataset

    ds = Dataset(t=a["t"], q=a["q"], dq=a["dq"], tau=a["tau"], joint_names=("a", "b", "c"))
    path = save_dataset(ds, tmp_path / "d.csv")
    whole = np.loadtxt(path, delimiter=",", skiprows=1)  # numpy alone
    _, rows = _rows(path, chunk)
    np.testing.assert_array_equal(rows, whole)


@pytest.mark.parametrize("chunk", [3, 4, 17, 1000])
def test_csv_dq_from_q_across_chunks_equals_numpy_gradient(tmp_path, chunk):
    a = _arrays(n=200)
    text = "t,q_a,q_b,q_c,tau_a,tau_b,tau_c\n" + "\n".join(
        ",".join(f"{v:.17g}" for v in row) for row in np.column_stack([a["t"], a["q"], a["tau"]])
    )
    path = tmp_path / "nodq.csv"
    path.write_text(text + "\n")
    _, rows = _rows(path, chunk)
    want = np.gradient(a["q"], a["t"], axis=0, edge_order=2)
    np.testing.assert_allclose(rows[:, 4:7], want, rtol=1e-12, atol=1e-9)


def test_csv_bad_cells(tmp_path):
    (tmp_path / "e.csv").write_text("t,q_a,dq_a,tau_a\n0,0,0,0\n0.1,,0,0\n0.2,0,0,0\n")
    with pytest.raises(DataError, match=r"e.csv: q holds nan at sample 1"):
        list(iter_rows(open_source(FileSpec(tmp_path / "e.csv"))))
    (tmp_path / "w.csv").write_text("t,q_a,dq_a,tau_a\n0,0,0,0\n0.1,x,0,0\n")
    with pytest.raises(DataError, match="line 3"):
        list(iter_rows(open_source(FileSpec(tmp_path / "w.csv"))))


def test_file_specs_and_windows(tmp_path):
    s = parse_file_spec("run.csv@2.5:30")
    assert s.path.name == "run.csv" and s.window == Window(2.5, 30.0, "s")
    assert parse_file_spec("run.csv@#10:#20").window == Window(10, 20, "index")
    assert parse_file_spec("run.csv@#10:").window == Window(10, None, "index")
    assert parse_file_spec("run.csv@:4").window == Window(None, 4.0, "s")
    assert parse_file_spec("run.csv", window="1:2").window == Window(1.0, 2.0, "s")
    assert parse_file_spec("run.csv@3:4", window="1:2").window == Window(3.0, 4.0, "s")
    odd = tmp_path / "a@1:2.csv"  # an existing path is never split
    odd.write_text("x")
    assert parse_file_spec(str(odd)).window is None
    for bad in ("a.csv@1:x", "a.csv@#1.5:3", "a.csv@-1:3"):
        with pytest.raises(InputError):
            parse_file_spec(bad)
    with pytest.raises(InputError, match="empty"):
        parse_file_spec("a.csv@5:5")
    assert str(Window(10, None, "index")) == "#10:" and str(Window(1.5, 3.0)) == "1.5:3"


def test_npz_stored_members_read_at_their_offsets(tmp_path):
    """Stored members are read by plain reads at their data offset (local headers with
    ZIP64 extra fields, as ``save_dataset`` writes, and archives mixing stored and
    deflated members): the rows equal ``numpy.load``'s arrays."""
    a = _arrays(n=777)
    ref = np.column_stack([a[k] for k in ("t", "q", "dq", "tau", "ddq")])
    written = tmp_path / "w.npz"
    save_dataset(load_dataset(_npz(tmp_path / "src.npz", a)), written)
    with zipfile.ZipFile(written) as zf:  # the writer's local headers carry extra fields
        assert all(i.compress_type == zipfile.ZIP_STORED for i in zf.infolist())
    mixed = tmp_path / "mixed.npz"
    with zipfile.ZipFile(written) as zin, zipfile.ZipFile(mixed, "w") as zout:
        for k, info in enumerate(zin.infolist()):
            kind = zipfile.ZIP_STORED if k % 2 else zipfile.ZIP_DEFLATED
            zout.writestr(info.filename, zin.read(info), compress_type=kind)
    for path in (written, mixed):
        src = open_source(FileSpec(path))
        assert src._offsets  # some members take the plain-read path
        with np.load(path) as z:
            np.testing.assert_array_equal(
                np.column_stack([z[k] for k in ("t", "q", "dq", "tau", "ddq")]), ref
            )
        np.testing.assert_array_equal(np.vstack(list(src.chunks(100))), ref)
        np.testing.assert_array_equal(np.vstack(list(src.chunks(64, 33, 500))), ref[33:500])


def _npz(path, arrays):
    np.savez(path, **arrays)
    return path
