"""Property tests: random bytes and random arrays into every loader; only ManipIdError comes out.

Each loader gets (a) arbitrary bytes under each file name it accepts, (b) NPZ and
CSV files built from random arrays (any shape, dtype and value, NaN, Inf, complex,
huge and tiny numbers), and (c) near-valid files with one random corruption. The
only acceptable outcomes are a result or a :class:`~manip_id.errors.ManipIdError`;
any other exception (TypeError, ValueError, UnicodeDecodeError, zipfile.BadZipFile,
MemoryError, ...) fails the test. The input file is never modified.
"""

from __future__ import annotations

import hashlib
import io
import os
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from manip_id.errors import ManipIdError, ManipIdWarning

#: Examples per property (MANIP_ID_FUZZ_EXAMPLES=500 for a longer hunt).
SETTINGS = settings(
    max_examples=int(os.environ.get("MANIP_ID_FUZZ_EXAMPLES", "40")),
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
FIELDS = ("t", "q", "dq", "ddq", "tau")


def _digest(path: Path) -> str:
    if path.is_dir():
        return "|".join(_digest(p) for p in sorted(path.iterdir()))
    return hashlib.sha256(path.read_bytes()).hexdigest()


def only_ours(call, path: Path | None = None):
    """Run ``call()``; any exception but a ManipIdError fails; the input stays unchanged."""
    before = _digest(path) if path is not None and path.exists() else None
    try:
        with warnings.catch_warnings():
            # the package's own warnings are allowed here (a dropped truncated last line,
            # "degrees?"); any other warning stays under the suite's filters
            warnings.simplefilter("ignore", ManipIdWarning)
            return call()
    except ManipIdError as exc:
        assert str(exc), "an error without a message"
        return exc
    finally:
        if before is not None:
            assert _digest(path) == before, f"{path} was modified"


def _load(path: Path):
    from manip_id.datasets import load_dataset

    return load_dataset(path)


def _stream(path: Path):
    from manip_id.datasets import FileSpec, iter_rows, open_source

    source = open_source(FileSpec(path))
    for _ in iter_rows(source, chunk=64):
        pass
    return source


def _robot(path: Path):
    from manip_id.robot.model import load_robot

    return load_robot(str(path) if isinstance(path, Path) else path)


def _profile(path: Path):
    from manip_id.robot.profiles import load_profile

    return load_profile(path)


# ------------------------------------------------------------- random bytes
NAMES = ["x.npz", "x.csv", "x.mcap", "x.urdf", "x.toml"]


@SETTINGS
@given(data=st.binary(min_size=0, max_size=4096), name=st.sampled_from(NAMES))
def test_random_bytes_into_every_loader(tmp_path_factory, data, name):
    path = tmp_path_factory.mktemp("bytes") / name
    path.write_bytes(data)
    if name.endswith(".urdf"):
        only_ours(lambda: _robot(path), path)
    elif name.endswith(".toml"):
        only_ours(lambda: _profile(path), path)
    else:
        only_ours(lambda: _load(path), path)
        only_ours(lambda: _stream(path), path)


@SETTINGS
@given(
    data=st.binary(min_size=1, max_size=2048),
    prefix=st.sampled_from(
        [b"PK\x03\x04", b"\x93NUMPY", b"t,q,dq,tau\n", b"<?xml version='1.0'?><robot name='r'>"]
    ),
)
def test_random_bytes_behind_a_plausible_magic(tmp_path_factory, data, prefix):
    folder = tmp_path_factory.mktemp("magic")
    suffix = {b"PK": ".npz", b"\x93N": ".npz", b"t,": ".csv", b"<?": ".urdf"}[prefix[:2]]
    path = folder / f"f{suffix}"
    path.write_bytes(prefix + data)
    if suffix == ".urdf":
        only_ours(lambda: _robot(path), path)
    else:
        only_ours(lambda: _load(path), path)


@SETTINGS
@given(
    files=st.dictionaries(
        st.sampled_from(
            [
                "rbt_log_positions.txt",
                "rbt_log_velocities.txt",
                "rbt_log_torques.txt",
                "rbt_log_time.txt",
                "other.txt",
            ]
        ),
        st.binary(max_size=512),
        max_size=5,
    )
)
def test_random_files_in_a_log_folder(tmp_path_factory, files):
    folder = tmp_path_factory.mktemp("log")
    for name, content in files.items():
        (folder / name).write_bytes(content)
    only_ours(lambda: _load(folder), folder)


# ------------------------------------------------------------ random arrays
_dtypes = st.one_of(
    hnp.floating_dtypes(),
    hnp.integer_dtypes(),
    hnp.complex_number_dtypes(),
    hnp.boolean_dtypes(),
    st.just(np.dtype("U3")),
)
_arrays = _dtypes.flatmap(
    lambda dt: hnp.arrays(dt, hnp.array_shapes(min_dims=0, max_dims=3, max_side=6))
)


def _plausible(n: int, nv: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    return {
        "t": np.arange(n) * 0.01,
        "q": rng.uniform(-1, 1, (n, nv)),
        "dq": rng.uniform(-1, 1, (n, nv)),
        "ddq": rng.uniform(-1, 1, (n, nv)),
        "tau": rng.uniform(-5, 5, (n, nv)),
    }


@SETTINGS
@given(arrays=st.dictionaries(st.sampled_from([*FIELDS, "joint_names", "junk"]), _arrays))
def test_random_arrays_in_an_npz(tmp_path_factory, arrays):
    path = tmp_path_factory.mktemp("npz") / "a.npz"
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)
    only_ours(lambda: _load(path), path)
    only_ours(lambda: _stream(path), path)


@SETTINGS
@given(
    field=st.sampled_from(FIELDS),
    value=st.sampled_from([np.nan, np.inf, -np.inf, 1e300, -1e300, 1e-300, 1e308, 0.0, 1e7]),
    n=st.integers(2, 30),
    nv=st.integers(1, 3),
    row=st.integers(0, 29),
    seed=st.integers(0, 2**16),
)
def test_one_bad_value_in_plausible_data(tmp_path_factory, field, value, n, nv, row, seed):
    a = _plausible(n, nv, np.random.default_rng(seed))
    a[field] = a[field].copy()
    a[field].reshape(n, -1)[row % n, 0] = value
    folder = tmp_path_factory.mktemp("one")
    path = folder / "a.npz"
    with open(path, "wb") as fh:
        np.savez(fh, **a)
    out = only_ours(lambda: _load(path), path)
    if not isinstance(out, ManipIdError):  # accepted: then every value is finite and sane
        for name in FIELDS:
            arr = getattr(out, name)
            assert arr is None or (np.isfinite(arr).all() and np.abs(arr).max() <= 1e9)
    from manip_id.datasets import Dataset

    only_ours(lambda: Dataset(**a))


@SETTINGS
@given(cells=st.lists(st.lists(st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=4),
    st.complex_numbers(max_magnitude=1e3),
    st.integers(-10**30, 10**30)), min_size=1, max_size=5), min_size=0, max_size=12),
    header=st.booleans())  # fmt: skip
def test_random_csv_tables(tmp_path_factory, cells, header):
    lines = ["t,q_a,dq_a,tau_a"] if header else []
    lines += [",".join(str(c) for c in row) for row in cells]
    path = tmp_path_factory.mktemp("csv") / "a.csv"
    path.write_text("\n".join(lines), encoding="utf-8")
    only_ours(lambda: _load(path), path)
    only_ours(lambda: _stream(path), path)


@SETTINGS
@given(t=_arrays, q=_arrays, dq=_arrays, tau=_arrays, ddq=st.one_of(st.none(), _arrays))
def test_random_arrays_into_dataset(t, q, dq, tau, ddq):
    from manip_id.datasets import Dataset

    only_ours(lambda: Dataset(t=t, q=q, dq=dq, tau=tau, ddq=ddq))


@SETTINGS
@given(
    value=_arrays,
    name=st.sampled_from(FIELDS),
    ndim=st.integers(1, 2),
)
def test_random_arrays_into_check_values(value, name, ndim):
    from manip_id.datasets import check_values

    only_ours(lambda: check_values(name, value, ndim))


# ----------------------------------------------------- corrupted valid files
def _valid_npz_bytes() -> bytes:
    rng = np.random.default_rng(0)
    buf = io.BytesIO()
    np.savez_compressed(buf, **_plausible(50, 2, rng))
    return buf.getvalue()


VALID_NPZ = _valid_npz_bytes()


@SETTINGS
@given(
    where=st.integers(0, len(VALID_NPZ) - 1),
    byte=st.integers(0, 255),
    cut=st.one_of(st.none(), st.integers(0, len(VALID_NPZ))),
)
def test_corrupted_npz(tmp_path_factory, where, byte, cut):
    data = bytearray(VALID_NPZ)
    data[where] = byte
    if cut is not None:
        data = data[:cut]
    path = tmp_path_factory.mktemp("corrupt") / "a.npz"
    path.write_bytes(bytes(data))
    only_ours(lambda: _load(path), path)
    only_ours(lambda: _stream(path), path)


@SETTINGS
@given(
    shapes=st.dictionaries(
        st.sampled_from(FIELDS),
        st.tuples(st.integers(0, 10**12), st.integers(0, 10**6)),
        min_size=1,
    )
)
def test_npz_headers_declaring_any_shape(tmp_path_factory, shapes):
    """Members whose headers declare huge or inconsistent shapes (data absent): refused."""
    path = tmp_path_factory.mktemp("hdr") / "a.npz"
    with zipfile.ZipFile(path, "w") as zf:
        for name, shape in shapes.items():
            buf = io.BytesIO()
            np.lib.format.write_array_header_1_0(
                buf, {"descr": "<f8", "fortran_order": False, "shape": shape}
            )
            zf.writestr(f"{name}.npy", buf.getvalue() + bytes(64))
    only_ours(lambda: _load(path), path)
    only_ours(lambda: _stream(path), path)


URDF = """<?xml version="1.0"?>
<robot name="r"><link name="base"/>
<link name="a"><inertial><mass value="{m}"/><origin xyz="{x} 0 0"/>
<inertia ixx="{i}" ixy="{ixy}" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
<joint name="{j}" type="{kind}"><parent link="base"/><child link="a"/><axis xyz="{ax}"/>
<limit lower="{lo}" upper="{hi}" velocity="{v}" effort="10"/></joint></robot>
"""
_num = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["", "abc", "1e999", "-0", "0x10", "1,5"]),
)


@SETTINGS
@given(
    m=_num, x=_num, i=_num, ixy=_num, lo=_num, hi=_num, v=_num,
    j=st.text(min_size=0, max_size=6).filter(lambda s: "\x00" not in s),
    kind=st.sampled_from(["revolute", "prismatic", "continuous", "fixed", "floating", "weird"]),
    ax=st.sampled_from(["1 0 0", "0 0 0", "nan 0 1", "1 2", "a b c"]),
)  # fmt: skip
def test_random_urdf_fields(tmp_path_factory, m, x, i, ixy, lo, hi, v, j, kind, ax):
    from xml.sax.saxutils import escape, quoteattr

    text = URDF.format(
        m=escape(m), x=escape(x), i=escape(i), ixy=escape(ixy), lo=escape(lo), hi=escape(hi),
        v=escape(v), j=quoteattr(j)[1:-1], kind=kind, ax=ax,
    )  # fmt: skip
    path = tmp_path_factory.mktemp("urdf") / "r.urdf"
    path.write_text(text, encoding="utf-8")
    robot = only_ours(lambda: _robot(path), path)
    if isinstance(robot, ManipIdError):
        return
    from manip_id.simulation import require_physical

    only_ours(lambda: require_physical(robot, robot.nominal_parameters))


@pytest.mark.parametrize("value", [None, 3, 2.5, b"bytes", ["a"], {"a": 1}, object()])
def test_wrong_types_into_loaders(value):
    only_ours(lambda: _load(value))
    only_ours(lambda: _robot(value))
