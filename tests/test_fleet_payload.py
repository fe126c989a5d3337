"""Payload and drive-gain identification on Dask give the local result, and fail cleanly.

The runs are made here with ``pinocchio.rnea`` of the unloaded model and of the model
whose tool link carries the payload (:mod:`test_payload`), plus Gaussian noise, and saved
with ``numpy.savez``. The reference is the same call without a scheduler (this process);
:mod:`test_payload` checks that one against the true payload.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from dataclasses import dataclass

import numpy as np
import pytest
from conftest import get_robot
from test_payload import make_payload, make_runs

from manip_id.cli import main
from manip_id.errors import DataError
from manip_id.payload import identify_drive_gains, identify_payload
from manip_id.robot import compiled_regressor as cr

RTOL = 1e-9


@pytest.fixture(autouse=True, scope="module")
def _long_lived_process():
    """``auto`` regressor mode in a process that has evaluated many samples before (as a
    long-lived one has) and fresh workers: each call announces its runs' size, which alone
    decides the regressor path on every process of it, so both give the same round-off
    (which the payload solve amplifies on its smallest quantities)."""
    mp = pytest.MonkeyPatch()
    mp.setenv(cr.ENV, "auto")
    mp.setattr(cr, "_seen", 10 * cr.AUTO_SAMPLES)
    yield
    mp.undo()


GAINS = np.array([0.45, 0.8, 1.1, 1.4, 1.7, 2.3])  # [N m / A]
N_RUNS, N = 3, 400  # runs of each kind, samples per run


def _close(a, b, rtol=RTOL):
    """Equal to ``rtol`` relative to the largest magnitude of ``b`` (NaN where ``b`` is NaN)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    assert np.array_equal(np.isnan(a), np.isnan(b))
    a, b = a[~np.isnan(b)], b[~np.isnan(b)]
    scale = np.abs(b).max()
    assert np.abs(a - b).max() <= rtol * scale, np.abs(a - b).max() / scale


def _same_payload(res, ref):
    p, q = res.payload, ref.payload
    assert p.mass > 0.1  # a payload, not a zero
    _close(p.mass, q.mass)
    _close(p.com, q.com)
    _close(p.inertia, q.inertia)
    _close(p.std, q.std)
    _close(res.base_estimate, ref.base_estimate)
    _close(res.base_std, ref.base_std)
    _close(res.sigma2, ref.sigma2)
    assert res.n_samples == ref.n_samples
    np.testing.assert_array_equal(res.rows_left_out, ref.rows_left_out)


@dataclass(frozen=True)
class NpzRun:
    """One run read from an NPZ file with numpy, in two blocks. Picklable (a worker reads
    the file); its ``label`` names the file in errors, ``n_samples`` (when given) its size
    before it is read."""

    path: str
    start: int = 0
    stop: int | None = None
    n_samples: int | None = None

    @property
    def label(self) -> str:
        return self.path

    def __call__(self):
        with np.load(self.path) as z:
            arrays = [z[k][self.start : self.stop] for k in ("q", "dq", "ddq", "tau")]
        half = arrays[0].shape[0] // 2
        yield tuple(a[:half] for a in arrays)
        yield tuple(a[half:] for a in arrays)


def _save(path, block, robot) -> str:
    q, dq, ddq, tau = block
    t = 0.01 * np.arange(q.shape[0])  # [s]
    np.savez(path, t=t, q=q, dq=dq, ddq=ddq, tau=tau, joint_names=np.array(robot.dof_names))
    return str(path)


@pytest.fixture(scope="module")
def ur5():
    return get_robot("ur5")


@pytest.fixture(scope="module")
def runs(ur5, tmp_path_factory):
    """Unloaded and loaded ur5 runs (torques [N m] and currents [A]) as arrays and files."""
    d = tmp_path_factory.mktemp("fleet_payload")
    payload = make_payload()
    out: dict = {"u": [], "l": [], "cu": [], "cl": [], "files": {"u": [], "l": []}}
    for k in range(N_RUNS):
        u, ld = make_runs(ur5, "tool0", payload, n=N, seed=k, noise=0.02)
        cu, cl = make_runs(ur5, "tool0", payload, n=N, seed=10 + k, noise=0.01, gains=GAINS)
        out["u"].append(u)
        out["l"].append(ld)
        out["cu"].append(cu)
        out["cl"].append(cl)
        out["files"]["u"].append(_save(d / f"u{k}.npz", u, ur5))
        out["files"]["l"].append(_save(d / f"l{k}.npz", ld, ur5))
    return out


@pytest.fixture(scope="module")
def local_client():
    """A LocalCluster of two worker processes on 127.0.0.1, closed at the end."""
    from distributed import Client, LocalCluster

    cluster = LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        host="127.0.0.1",
        scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
        env={"OPENBLAS_NUM_THREADS": "1"},
    )
    client = Client(cluster)
    yield client
    client.close()
    cluster.close()


def _children() -> set[int]:
    """Processes below this one, but multiprocessing's resource tracker (started with the
    first spawned process, it lives as long as this interpreter, and stops with it)."""
    import psutil

    out = set()
    for p in psutil.Process().children(recursive=True):
        try:
            if "multiprocessing.resource_tracker" in " ".join(p.cmdline()):
                continue
        except psutil.Error:  # gone meanwhile
            continue
        out.add(p.pid)
    return out


def _wait_gone(before: set[int]) -> set[int]:
    deadline = time.monotonic() + 30
    left = _children() - before
    while left and time.monotonic() < deadline:
        time.sleep(0.2)
        left = _children() - before
    return left


# --------------------------------------------------------------------- API
@pytest.mark.parametrize("method", ["wls", "ols"])
def test_local_cluster_payload_equals_the_local_one(ur5, runs, local_client, method):
    ref = identify_payload(ur5, runs["u"], runs["l"], "tool0", method=method)
    res = identify_payload(
        ur5, runs["u"], runs["l"], "tool0", method=method, scheduler=local_client
    )
    _same_payload(res, ref)
    assert res.payload_test["dof"] == ref.payload_test["dof"]
    _close(res.payload_test["statistic"], ref.payload_test["statistic"])
    for key in ("unloaded", "loaded"):
        _close(res.relative_error_per_joint[key], ref.relative_error_per_joint[key])


def test_runs_read_on_the_workers(ur5, runs, local_client):
    """Runs given as picklable functions reading files (window, two blocks each): read on
    the workers, the local answer; and the answer of the arrays in one block up to the
    round-off of the other partition into chunks."""
    fu, fl = runs["files"]["u"], runs["files"]["l"]
    unloaded = [NpzRun(p, n_samples=N) for p in fu]
    loaded = [NpzRun(p, 0, 300, n_samples=300) for p in fl]
    ref = identify_payload(ur5, unloaded, loaded, "tool0", velocity_deadband=0.05)
    res = identify_payload(
        ur5, unloaded, loaded, "tool0", velocity_deadband=0.05, scheduler=local_client
    )
    assert ref.rows_left_out.sum() > 0  # the deadband took rows out
    _same_payload(res, ref)
    assert res.n_samples == {"unloaded": N_RUNS * N, "loaded": N_RUNS * 300}
    arrays_l = [tuple(a[:300] for a in r) for r in runs["l"]]
    whole = identify_payload(ur5, runs["u"], arrays_l, "tool0", velocity_deadband=0.05)
    _close(res.payload.mass, whole.payload.mass, 1e-9)
    _close(res.payload.std, whole.payload.std, 1e-7)  # sqrt of an inverse: round-off grows
    np.testing.assert_array_equal(res.rows_left_out, whole.rows_left_out)


def test_local_cluster_known_base_and_consistent(ur5, runs, local_client):
    from manip_id.identification import identify

    q, dq, ddq, tau = (np.concatenate([r[i] for r in runs["u"]]) for i in range(4))
    known = identify(ur5, (q, dq, ddq, tau), method="wls")
    ref = identify_payload(ur5, None, runs["l"], "tool0", known_base=known, consistent=True)
    res = identify_payload(
        ur5, None, runs["l"], "tool0", known_base=known, consistent=True, scheduler=local_client
    )
    assert res.known_base and res.consistent
    _same_payload(res, ref)


@pytest.mark.parametrize("method", ["ml", "ols"])
def test_local_cluster_drive_gains_equal_the_local_ones(ur5, runs, local_client, method):
    payload = make_payload()
    kw = dict(payload_com=payload.lever, method=method)
    ref = identify_drive_gains(ur5, runs["cu"], runs["cl"], "tool0", payload.mass, **kw)
    res = identify_drive_gains(
        ur5, runs["cu"], runs["cl"], "tool0", payload.mass, scheduler=local_client, **kw
    )
    assert np.nanmax(np.abs(ref.gains - GAINS) / GAINS) < 0.05  # it identifies the gains
    _close(res.gains, ref.gains)
    _close(res.gains_std, ref.gains_std)
    np.testing.assert_array_equal(res.determined, ref.determined)
    _close(res.payload.inertia, ref.payload.inertia)
    _close(res.payload.std, ref.payload.std)
    _close(res.base_estimate, ref.base_estimate)


def test_a_bad_run_file_is_named_and_gives_no_result(ur5, runs, local_client, tmp_path):
    bad = tmp_path / "broken.npz"
    bad.write_bytes(b"\x00" * 64)
    loaded = [NpzRun(p) for p in runs["files"]["l"]]
    loaded.insert(1, NpzRun(str(bad)))
    with pytest.raises(DataError, match=r"loaded run 1 \(.*broken\.npz\)"):
        identify_payload(ur5, runs["u"], loaded, "tool0", scheduler=local_client)
    # the failed call's other tasks are cancelled: nothing is left running or held
    deadline = time.monotonic() + 30
    while any(local_client.processing().values()) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(local_client.processing().values())


def test_a_local_spec_starts_and_stops_its_cluster(ur5, runs):
    before = _children()
    ref = identify_payload(ur5, runs["u"], runs["l"], "tool0")
    res = identify_payload(ur5, runs["u"], runs["l"], "tool0", scheduler="local:2")
    _same_payload(res, ref)
    left = _wait_gone(before)
    assert not left, f"processes left running: {left}"


# --------------------------------------------------------------------- CLI
def _cli(argv, capsys):
    status = main(argv)
    return status, capsys.readouterr()


def _payload_argv(runs, out, *extra):
    return [
        "payload",
        "ur5",
        "--unloaded",
        *runs["files"]["u"],
        "--loaded",
        *runs["files"]["l"],
        "--frame",
        "tool0",
        "--json",
        str(out),
        *extra,
    ]


def test_cli_scheduler_gives_the_local_json(runs, tmp_path, capsys):
    before = _children()
    status, cap = _cli(_payload_argv(runs, tmp_path / "local.json"), capsys)
    assert status == 0, cap.err
    status, cap_d = _cli(
        _payload_argv(runs, tmp_path / "dask.json", "--scheduler", "local:2"), capsys
    )
    assert status == 0, cap_d.err
    assert not _wait_gone(before), "the local cluster was not stopped"
    ref = json.loads((tmp_path / "local.json").read_text())
    doc = json.loads((tmp_path / "dask.json").read_text())
    p, q = doc["payload"], ref["payload"]
    assert p["mass"] > 0.1
    for key in ("mass", "mass_std", "com", "com_std", "inertia", "inertia_std"):
        _close(p[key], q[key])
    _close(_values(doc["base_parameters"]), _values(ref["base_parameters"]))
    assert doc["data_quality"] == ref["data_quality"]  # scanned on the workers, the same
    assert doc["preprocess"] == ref["preprocess"]
    assert doc["source"]["scheduler"] == "local:2"
    assert ref["source"]["scheduler"] == "this process"
    # the data quality is in the JSON either way (above); printed only with --verbose
    assert "standstill (" not in cap_d.out


def _values(node) -> list[float]:
    """Every number of a JSON tree, in order (the payload's values and stds)."""
    if isinstance(node, dict):
        return [v for k in sorted(node) for v in _values(node[k])]
    if isinstance(node, list):
        return [v for x in node for v in _values(x)]
    if isinstance(node, bool) or node is None or isinstance(node, str):
        return []
    return [float(node)]


def test_cli_bad_file_on_the_cluster_names_it_and_writes_nothing(runs, tmp_path, capsys):
    bad = tmp_path / "broken.npz"
    bad.write_bytes(b"\x00" * 64)
    out = tmp_path / "p.json"
    argv = _payload_argv(runs, out, "--scheduler", "local:1")
    argv.insert(argv.index("--frame"), str(bad))
    before = _children()
    status, cap = _cli(argv, capsys)
    assert status == 2
    assert "broken.npz" in cap.err and "Traceback" not in cap.err
    assert len(cap.err.strip().splitlines()) == 1
    assert not out.exists() and not list(tmp_path.glob("*.tmp*"))
    assert not _wait_gone(before)


@pytest.mark.parametrize("spec", ["local:0", "tcp://nowhere", "nofile.json", "foo"])
def test_cli_bad_scheduler_is_refused_before_the_work(runs, tmp_path, capsys, spec):
    out = tmp_path / "p.json"
    status, cap = _cli(_payload_argv(runs, out, "--scheduler", spec), capsys)
    assert status == 2 and "scheduler" in cap.err
    assert "quality" not in cap.out and not out.exists()


def test_no_dask_without_a_scheduler(runs):
    """The local path (API and command) runs the same tasks without importing Dask."""
    fu, fl = runs["files"]["u"], runs["files"]["l"]
    code = (
        "import sys; from manip_id.cli import main;"
        f"assert main(['payload', 'ur5', '--unloaded', *{fu!r}, '--loaded', *{fl!r}, "
        "'--frame', 'tool0']) == 0;"
        "bad = [m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')];"
        "print(bad); sys.exit(1 if bad else 0)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
