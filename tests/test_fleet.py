"""Fleet identification: many files on Dask give the local result, robustly.

The data are made here with Pinocchio's ``rnea`` plus friction written in numpy
and saved with ``numpy.savez``; the reference is :func:`identify` on the
concatenated arrays (and on each file's arrays alone for ``per_file``).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id.datasets import parse_file_spec
from manip_id.errors import DataError, InputError
from manip_id.identification import (
    FileOptions,
    ModelOptions,
    PartitionOptions,
    PreprocessOptions,
    RunOptions,
    identify,
)
from manip_id.identification.fleet import parse_scheduler, portable_robot

VENV_BIN = Path(sys.executable).parent
N_FILES, N_SAMPLES = 6, 1500
NOISE = np.array([0.02, 0.08, 0.05, 0.2, 0.01, 0.03])  # [N m] per joint
FV, FC = 0.3, 0.5  # viscous [N m s/rad], Coulomb [N m]


def _close(a, b, rtol=1e-9):
    a, b = np.asarray(a, float), np.asarray(b, float)
    scale = np.abs(b).max()
    assert np.abs(a - b).max() <= rtol * scale, np.abs(a - b).max() / scale


def _make_file(robot, path: Path, seed: int, n: int = N_SAMPLES, ddq: bool = True):
    q, dq, ddq_ = robot.random_states(n, seed=seed)
    tau = np.array([pin.rnea(robot.model, robot.data, q[k], dq[k], ddq_[k]) for k in range(n)])
    tau += FV * dq + FC * np.sign(dq)  # [N m]
    tau += NOISE * np.random.default_rng(100 + seed).standard_normal(tau.shape)
    arrays = dict(t=np.arange(n) * 1e-3, q=q, dq=dq, tau=tau)
    if ddq:
        arrays["ddq"] = ddq_
    np.savez(path, **arrays)
    return q, dq, ddq_, tau


@pytest.fixture(scope="module")
def robot():
    return get_robot("ur10", friction=("viscous", "coulomb"))


@pytest.fixture(scope="module")
def fleet(robot, tmp_path_factory):
    folder = tmp_path_factory.mktemp("fleet")
    paths, arrays = [], []
    for f in range(N_FILES):
        path = folder / f"arm{f}.npz"
        arrays.append(_make_file(robot, path, seed=f))
        paths.append(str(path))
    concat = [np.concatenate([a[i] for a in arrays]) for i in range(4)]
    return paths, arrays, concat


@pytest.fixture(scope="module")
def reference(robot, fleet):
    _, _, (q, dq, ddq, tau) = fleet
    return {m: identify(robot, (q, dq, ddq, tau), method=m) for m in ("ols", "wls")}


@pytest.fixture(scope="module")
def files_reference(robot, fleet):
    """The files in this process, one task each: the reference of the honest std, whose
    blocks end at each file's end (the concatenated arrays' blocks run across them)."""
    return {
        m: identify(robot, fleet[0], method=m, files=FileOptions(audit=False))
        for m in ("ols", "wls")
    }


def _same(res, ref, method="ols", std_rtol=None, honest=None):
    """Estimate, white-noise std and noise variances as ``ref``; the honest std as
    ``honest`` (a result of the same files) when given."""
    _close(res.estimate, ref.estimate)
    if std_rtol is None:
        std_rtol = 1e-8 if method == "wls" else 1e-9
    _close(res.std_white, ref.std_white, rtol=std_rtol)
    if honest is not None:
        assert res.uncertainty["method"] == honest.uncertainty["method"]
        _close(res.std, honest.std, rtol=100 * std_rtol)
    _close(res.noise_variance, ref.noise_variance, rtol=1e-6)
    assert res.n_samples == ref.n_samples


# ------------------------------------------------------------------- serial
@pytest.mark.parametrize("method", ["ols", "wls"])
@pytest.mark.parametrize("block,split_every", [(None, 8), (400, 2), (1, 3), (10**6, 8)])
def test_serial_any_partition_gives_the_concatenated_result(
    robot, fleet, reference, files_reference, method, block, split_every
):
    paths = fleet[0]
    if block == 1:  # one task per sample: only on a short file pair, against its own reference
        paths = paths[:1]
        q, dq, ddq, tau = (a[:300] for a in fleet[1][0])
        np.savez(
            Path(paths[0]).with_name("short.npz"),
            t=np.arange(300) * 1e-3,
            q=q,
            dq=dq,
            ddq=ddq,
            tau=tau,
        )
        paths = [str(Path(paths[0]).with_name("short.npz"))]
        ref = identify(robot, (q, dq, ddq, tau), method=method)
        honest = ref  # one file: its blocks are the arrays'
    else:
        ref, honest = reference[method], files_reference[method]
    res = identify(
        robot,
        paths,
        method=method,
        files=FileOptions(
            audit=False, partition=PartitionOptions(block=block, split_every=split_every)
        ),
    )
    _same(res, ref, method, honest=honest)


def test_wls_noise_variances_are_the_per_file_residual_sums(robot, fleet, reference):
    """The WLS variances equal the residuals summed file by file, computed sample by sample."""
    paths, arrays, _ = fleet
    res = identify(robot, paths, method="wls", files=FileOptions(audit=False))
    rss = np.zeros(robot.nv)
    for q, dq, ddq, tau in arrays:
        err = tau - res.predict(robot, q, dq, ddq)  # [N m]
        rss += (err**2).sum(axis=0)
    n, r = res.n_samples, len(res.estimate)
    np.testing.assert_allclose(res.noise_variance, rss / (n - r / robot.nv), rtol=1e-6)
    # and they found the noise that was put in
    np.testing.assert_allclose(np.sqrt(res.noise_variance), NOISE, rtol=0.1)


def test_per_file_estimates_are_each_files_own_identification(robot, fleet):
    paths, arrays, _ = fleet
    res = identify(
        robot,
        paths,
        files=FileOptions(audit=False, partition=PartitionOptions(block=500, per_file=True)),
    )
    assert [f.path for f in res.per_file] == paths
    for fe, (q, dq, ddq, tau) in zip(res.per_file, arrays, strict=True):
        own = identify(robot, (q, dq, ddq, tau), base=res.base)
        assert fe.error is None and fe.n_samples == N_SAMPLES and fe.n_tasks == 3
        _close(fe.result.estimate, own.estimate)
        _close(fe.result.std, own.std)
    d = res.to_dict()
    json.dumps(d)
    assert len(d["per_file"]) == N_FILES
    assert d["per_file"][2]["file"] == paths[2]
    names = [p["name"] for p in d["per_file"][2]["parameters"]]
    assert names == res.names


def test_a_file_that_excites_too_little_is_reported_not_fatal(robot, fleet, tmp_path):
    paths, arrays, _ = fleet
    short = tmp_path / "short.npz"
    q, dq, ddq, tau = (a[:5] for a in arrays[0])  # 30 equations for 48+ parameters
    np.savez(short, t=np.arange(5) * 1e-3, q=q, dq=dq, ddq=ddq, tau=tau)
    res = identify(
        robot,
        [*paths[:2], str(short)],
        files=FileOptions(audit=False, partition=PartitionOptions(per_file=True)),
    )
    assert res.per_file[0].result is not None
    bad = res.per_file[2]
    assert bad.result is None and bad.n_samples == 5 and bad.error
    assert res.n_samples == 2 * N_SAMPLES + 5


def test_validation_files_pooled_and_per_file(robot, fleet, tmp_path):
    paths, arrays, _ = fleet
    vpaths, varrays = [], []
    for f in range(2):
        path = tmp_path / f"val{f}.npz"
        varrays.append(_make_file(robot, path, seed=50 + f, n=700))
        vpaths.append(str(path))
    res = identify(robot, paths, validation=vpaths, files=FileOptions(audit=False))
    vcat = [np.concatenate([a[i] for a in varrays]) for i in range(4)]
    tcat = [np.concatenate([a[i] for a in arrays]) for i in range(4)]
    ref = identify(robot, tuple(tcat), validation=tuple(vcat))
    re, rr = res.relative_error, ref.relative_error
    # from each file's sums (zz - 2 b.theta + theta.A.theta), which carry about 1e-8 of
    # the torque energy as round-off, against residuals sample by sample
    assert re.validation == pytest.approx(rr.validation, rel=1e-6)
    np.testing.assert_allclose(re.validation_per_joint, rr.validation_per_joint, rtol=1e-6)
    for entry, (q, dq, ddq, tau) in zip(re.validation_per_file, varrays, strict=True):
        err = res.predict(robot, q, dq, ddq) - tau
        assert entry["n_samples"] == 700
        assert entry["error"] == pytest.approx(np.linalg.norm(err) / np.linalg.norm(tau), 1e-6)
    d = res.to_dict()["relative_error"]
    assert [e["file"] for e in d["validation_per_file"]] == vpaths


def _smooth_file(robot, path: Path, seed: int, n: int = 4001, rate: float = 500.0):
    """A Fourier motion inside the limits, torques from rnea + friction, saved with numpy."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate  # [s]
    lo, hi = robot.lower, robot.upper
    mid, amp = 0.5 * (lo + hi), 0.25 * np.minimum(hi - lo, 2.0)
    w = 2 * np.pi * rng.uniform(0.3, 1.0, (3, robot.nv))  # [rad/s]
    a = rng.uniform(-1, 1, (3, robot.nv)) / 3
    ph = rng.uniform(0, 2 * np.pi, (3, robot.nv))
    arg = w[:, None, :] * t[None, :, None] + ph[:, None, :]
    q = mid + amp * (a[:, None, :] * np.sin(arg)).sum(axis=0)
    dq = amp * (a[:, None, :] * w[:, None, :] * np.cos(arg)).sum(axis=0)
    ddq = -amp * (a[:, None, :] * w[:, None, :] ** 2 * np.sin(arg)).sum(axis=0)
    tau = np.array([pin.rnea(robot.model, robot.data, q[k], dq[k], ddq[k]) for k in range(n)])
    tau += FV * dq + FC * np.sign(dq)  # [N m]
    tau += 0.01 * rng.standard_normal(tau.shape)
    np.savez(path, t=t, q=q, dq=dq, ddq=ddq, tau=tau)
    return q, dq, ddq, tau


@pytest.mark.parametrize("model", ["energy", "momentum"])
def test_acceleration_free_models(robot, tmp_path, model):
    paths, arrays = [], []
    for f in range(3):
        path = tmp_path / f"smooth{f}.npz"
        arrays.append(_smooth_file(robot, path, seed=70 + f))
        paths.append(str(path))
    kw = dict(model=ModelOptions(model, window_length=0.02 if model == "energy" else 0.1))
    # one file: the local acceleration-free run of identify()
    q, dq, ddq, tau = arrays[0]
    own = identify(robot, (q, dq, None, tau), model=replace(kw["model"], dt=1 / 500.0))
    one = identify(robot, paths[:1], files=FileOptions(audit=False), **kw)
    _same(one, own, honest=own)  # the rows' blocks too
    assert own.uncertainty["method"] == "hac"
    assert one.model == model and one.n_samples == q.shape[0]
    # several files: any partition of the energy windows gives the same sums
    whole = identify(
        robot,
        paths,
        files=FileOptions(audit=False, partition=PartitionOptions(per_file=True)),
        **kw,
    )
    if model == "energy":
        for block in (50, 333):
            # the energy fit is nearly exact: sigma^2 comes from RSS = zz - 2 b.theta +
            # theta.A.theta, a difference of sums 1e7 times larger than itself
            _same(
                identify(
                    robot,
                    paths,
                    files=FileOptions(audit=False, partition=PartitionOptions(block=block)),
                    **kw,
                ),
                whole,
                std_rtol=1e-6,
                honest=whole,
            )
    else:
        with pytest.raises(InputError, match="no blocks"):
            identify(
                robot,
                paths,
                files=FileOptions(audit=False, partition=PartitionOptions(block=100)),
                **kw,
            )
    assert whole.n_samples == 3 * 4001
    for fe, (q, dq, _, tau) in zip(whole.per_file, arrays, strict=True):
        _close(
            fe.result.estimate,
            identify(robot, (q, dq, None, tau), model=replace(kw["model"], dt=1 / 500)).estimate,
        )
    # validation: the torque error of the dynamic model, on the validation files' sums
    res = identify(robot, paths[1:], validation=paths[:1], files=FileOptions(audit=False), **kw)
    err = res.predict(robot, q := arrays[0][0], arrays[0][1], arrays[0][2]) - arrays[0][3]
    assert res.relative_error.validation == pytest.approx(
        np.linalg.norm(err) / np.linalg.norm(arrays[0][3]), rel=1e-6
    )
    del q


def test_preprocessed_files_any_partition(robot, tmp_path):
    """Files without ddq are preprocessed each on its own, and blocks cut the result."""
    from manip_id.datasets import load_dataset
    from manip_id.signals import preprocess

    paths = []
    for f in range(2):
        path = tmp_path / f"raw{f}.npz"
        _make_file(robot, path, seed=20 + f, n=1200, ddq=False)
        paths.append(str(path))
    opts = {"cutoff": 50.0, "trim": 0.02}
    blocks = []
    for p in paths:
        ds = preprocess(load_dataset(p), **opts)
        blocks.append((ds.q, ds.dq, ds.ddq, ds.tau))
    ref = identify(robot, tuple(np.concatenate([b[i] for b in blocks]) for i in range(4)))
    for block in (None, 250):
        res = identify(
            robot,
            paths,
            files=FileOptions(
                preprocess=PreprocessOptions(**opts),
                audit=False,
                partition=PartitionOptions(block=block),
            ),
        )
        _same(res, ref)


def test_no_dask_without_a_scheduler(fleet):
    code = (
        "import sys; from manip_id import load_robot; from manip_id import identify;"
        "r = load_robot('ur10', friction='viscous,coulomb');"
        "from manip_id.identification import FileOptions, PreprocessOptions, PartitionOptions;"
        "tasks = FileOptions(audit=False, partition=PartitionOptions(per_file=True, block=700));"
        f"identify(r, {fleet[0][:2]!r}, files=tasks);"
        "from manip_id.cli import main;"
        f"assert main(['identify', 'ur10', '--friction', 'viscous,coulomb', '--data', "
        f"*{fleet[0][:2]!r}, '--per-file']) == 0;"
        "bad = [m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')];"
        "print(bad); sys.exit(1 if bad else 0)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr


@pytest.mark.parametrize("where", ["corrupt", "joints", "missing"])
def test_a_bad_file_is_named_serial(robot, fleet, tmp_path, where):
    paths = list(fleet[0][:3])
    bad = tmp_path / f"bad_{where}.npz"
    if where == "corrupt":
        bad.write_bytes(b"not a zip archive")
    elif where == "joints":
        np.savez(bad, t=np.arange(10.0), q=np.zeros((10, 3)), dq=np.zeros((10, 3)),
                 tau=np.zeros((10, 3)))  # fmt: skip
    paths.insert(1, str(bad))
    with pytest.raises(DataError, match=str(bad).replace(".", r"\.")):
        identify(robot, paths, files=FileOptions(audit=False))


def test_bad_arguments(robot, fleet):
    paths = fleet[0]
    with pytest.raises(InputError, match="twice"):
        identify(robot, [paths[0], paths[0]], files=FileOptions(audit=False))
    with pytest.raises(InputError, match="empty"):
        identify(robot, [], files=FileOptions(audit=False))
    per_file = FileOptions(audit=False, partition=PartitionOptions(per_file=True))
    with pytest.raises(InputError, match="least squares"):  # tasks: sums, not sample order
        identify(robot, paths, method="rls", files=per_file)
    with pytest.raises(InputError, match="block"):
        identify(robot, paths, files=FileOptions(audit=False, partition=PartitionOptions(block=0)))
    for spec in ("local:0", "local:x", "tcp://nowhere", "http//x", "missing.json"):
        with pytest.raises(InputError):
            parse_scheduler(spec)
    assert parse_scheduler("local") == ("local", 2)
    assert parse_scheduler("local:3") == ("local", 3)
    assert parse_scheduler("tcp://127.0.0.1:8786") == ("address", "tcp://127.0.0.1:8786")


def test_portable_robot_pickles_small_and_identifies_the_same(robot, fleet, reference):
    import pickle

    light = portable_robot(robot)
    blob = pickle.dumps(light)
    assert len(blob) < 2_000_000
    res = identify(pickle.loads(blob), tuple(fleet[2]))  # WLS by default
    _close(res.estimate, reference["wls"].estimate)


def test_accumulator_pickles(robot, fleet):
    import pickle

    from manip_id.identification.fleet import FilePart, part_sums

    res = identify(robot, tuple(fleet[1][0]))
    spec = parse_file_spec(fleet[0][0])
    ps = part_sums(portable_robot(robot), FilePart(spec, 0), res.base.independent)
    back = pickle.loads(pickle.dumps(ps))
    np.testing.assert_array_equal(back.acc.A_joint, ps.acc.A_joint)
    np.testing.assert_array_equal(back.acc.b_joint, ps.acc.b_joint)
    assert back.acc.n == ps.acc.n == N_SAMPLES


# -------------------------------------------------------------- LocalCluster
@pytest.fixture(scope="module")
def local_client():
    from distributed import Client, LocalCluster

    cluster = LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        host="127.0.0.1",
        scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
    )
    client = Client(cluster)
    yield client
    client.close()
    cluster.close()


@pytest.mark.parametrize("method", ["ols", "wls"])
def test_local_cluster_gives_the_local_result(
    robot, fleet, reference, files_reference, local_client, method
):
    res = identify(
        robot,
        fleet[0],
        method=method,
        run=RunOptions(scheduler=local_client),
        files=FileOptions(audit=False, partition=PartitionOptions(block=700, per_file=True)),
    )
    _same(res, reference[method], method, honest=files_reference[method])
    serial = identify(
        robot,
        fleet[0],
        method=method,
        files=FileOptions(audit=False, partition=PartitionOptions(per_file=True)),
    )
    for a, b in zip(res.per_file, serial.per_file, strict=True):
        _close(a.result.estimate, b.result.estimate)
    assert res.timings["distributed"] > 0


def _npz_block(path: str, start: int, stop: int):
    """A part of :func:`identify`: one block of an NPZ file, read with numpy."""
    with np.load(path) as z:
        yield tuple(z[k][start:stop] for k in ("q", "dq", "ddq", "tau"))


def test_identify_chunks_parts_as_dask_tasks(robot, fleet, reference, local_client):
    from manip_id.identification import identify

    parts = [(_npz_block, (p, a, a + 500)) for p in fleet[0] for a in range(0, N_SAMPLES, 500)]
    res = identify(robot, parts, method="wls", run=RunOptions(scheduler=local_client))
    _same(res, reference["wls"], "wls")


def test_local_cluster_bad_file_no_result(robot, fleet, local_client, tmp_path):
    bad = tmp_path / "broken.npz"
    bad.write_bytes(b"\x00" * 64)
    with pytest.raises(DataError, match="broken.npz"):
        identify(
            robot,
            [*fleet[0], str(bad)],
            run=RunOptions(scheduler=local_client),
            files=FileOptions(audit=False, partition=PartitionOptions(block=500)),
        )
    # the rest of the failed run is cancelled: nothing of it is left running
    deadline = time.monotonic() + 30
    while any(local_client.processing().values()) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(local_client.processing().values())


def test_local_spec_starts_and_stops_its_cluster(robot, fleet, reference, files_reference):
    import psutil

    before = {p.pid for p in psutil.Process().children(recursive=True)}
    res = identify(
        robot, fleet[0], run=RunOptions(scheduler="local:2"), files=FileOptions(audit=False)
    )  # WLS by default
    _same(res, reference["wls"], "wls", honest=files_reference["wls"])
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        left = {p.pid for p in psutil.Process().children(recursive=True)} - before
        if not left:
            break
        time.sleep(0.2)
    assert not left, f"processes left running: {left}"


# ------------------------------------------- dask scheduler / dask worker CLI
def _start(args, log: Path):
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    fh = open(log, "wb")  # noqa: SIM115 (closed in _stop)
    proc = subprocess.Popen(args, stdout=fh, stderr=subprocess.STDOUT, env=env)
    proc._log = fh  # type: ignore[attr-defined]
    return proc


def _stop(proc) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=20)
    proc._log.close()


def _worker(scheduler_file: Path, name: str, log: Path):
    return _start(
        [
            str(VENV_BIN / "dask"), "worker", "--scheduler-file", str(scheduler_file),
            "--host", "127.0.0.1", "--nthreads", "1", "--no-nanny", "--no-dashboard",
            "--name", name,
        ],
        log,
    )  # fmt: skip


@pytest.fixture(scope="module")
def dask_cli(tmp_path_factory):
    """A scheduler and two workers started with the venv's ``dask`` commands, on 127.0.0.1."""
    from distributed import Client

    folder = tmp_path_factory.mktemp("dask")
    sched_file = folder / "scheduler.json"
    procs = []
    try:
        procs.append(
            _start(
                [
                    str(VENV_BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0",
                    "--no-dashboard", "--scheduler-file", str(sched_file),
                ],
                folder / "scheduler.log",
            )
        )  # fmt: skip
        deadline = time.monotonic() + 60
        while not sched_file.is_file() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert sched_file.is_file(), (folder / "scheduler.log").read_text()
        for i in range(2):
            procs.append(_worker(sched_file, f"w{i}", folder / f"w{i}.log"))
        with Client(scheduler_file=str(sched_file), timeout="30s") as c:
            c.wait_for_workers(2, timeout=60)
        yield {"file": sched_file, "folder": folder, "procs": procs}
    finally:
        for p in reversed(procs):
            _stop(p)


def test_cli_cluster_by_address_and_by_file(robot, fleet, reference, files_reference, dask_cli):
    address = json.loads(dask_cli["file"].read_text())["address"]
    assert address.startswith("tcp://127.0.0.1:")
    res = identify(
        robot,
        fleet[0],
        method="wls",
        run=RunOptions(scheduler=address),
        files=FileOptions(audit=False, partition=PartitionOptions(block=600)),
    )
    _same(res, reference["wls"], "wls", honest=files_reference["wls"])
    res = identify(
        robot,
        fleet[0],
        method="ols",
        run=RunOptions(scheduler=str(dask_cli["file"])),
        files=FileOptions(audit=False),
    )
    _same(res, reference["ols"], honest=files_reference["ols"])


def test_a_worker_killed_mid_run_changes_nothing(
    robot, fleet, reference, files_reference, dask_cli
):
    from distributed import Client

    sched = dask_cli["file"]
    victim = _worker(sched, "victim", dask_cli["folder"] / "victim.log")
    try:
        with Client(scheduler_file=str(sched), timeout="30s") as client:
            client.wait_for_workers(3, timeout=60)
            addr = next(
                a for a, w in client.scheduler_info()["workers"].items() if w["name"] == "victim"
            )
            with ThreadPoolExecutor(1) as pool:
                job = pool.submit(
                    identify,
                    robot,
                    fleet[0],
                    run=RunOptions(scheduler=client),
                    files=FileOptions(audit=False, partition=PartitionOptions(block=60)),
                    method="wls",
                )
                deadline = time.monotonic() + 120
                while time.monotonic() < deadline and not job.done():
                    if client.has_what([addr]).get(addr):  # it holds results: kill it
                        break
                    time.sleep(0.01)
                assert not job.done(), "the run ended before the worker could be killed"
                victim.send_signal(signal.SIGKILL)
                victim.wait(timeout=20)
                res = job.result(timeout=300)
            assert addr not in client.scheduler_info()["workers"]
        _same(res, reference["wls"], "wls", honest=files_reference["wls"])
    finally:
        _stop(victim)


# --------------------------------------------------------------------- figure
def test_per_file_figure(robot, fleet, tmp_path):
    from manip_id.viz.figures import per_file_parameters, png_size

    res = identify(
        robot,
        fleet[0][:3],
        files=FileOptions(audit=False, partition=PartitionOptions(per_file=True)),
    )
    out = tmp_path / "per_file.png"
    est = np.array([f.result.estimate for f in res.per_file])
    std = np.array([f.result.std for f in res.per_file])
    fig = per_file_parameters(
        out, est, std, pooled=res.estimate, names=res.names,
        files=[Path(f.path).name for f in res.per_file], max_parameters=6,
    )  # fmt: skip
    assert png_size(out) == tuple(int(v) for v in fig.get_size_inches() * fig.dpi)
    ax = fig.axes[0]
    assert len(ax.containers) == 3  # one error-bar series per file
    shown = np.argsort(-np.abs(res.estimate), kind="stable")[:6]
    scale = np.abs(res.estimate[shown])
    for f, cont in enumerate(ax.containers):
        np.testing.assert_allclose(cont.lines[0].get_ydata(), est[f, shown] / scale)
    assert [t.get_text() for t in ax.get_xticklabels()] == [res.names[i] for i in shown]
    with pytest.raises(InputError):
        per_file_parameters(out, est, std[:2], pooled=res.estimate, names=res.names, files="abc")


# ------------------------------------------------------------------------ CLI
def _cli(args, tmp_path, capsys):
    from manip_id.cli import main

    out = tmp_path / "out.json"
    status = main(["identify", "ur10", "--friction", "viscous,coulomb", *args, "--json", str(out)])
    captured = capsys.readouterr()
    return status, (json.loads(out.read_text()) if out.exists() else None), captured


def test_cli_per_file_validation_and_report(robot, fleet, tmp_path, capsys):
    paths, arrays, _ = fleet
    report_dir = tmp_path / "report"
    status, rep, cap = _cli(
        ["--data", paths[0], paths[1], "--validate", paths[2], "--per-file", "--block", "400",
         "--report", str(report_dir)],
        tmp_path, capsys,
    )  # fmt: skip
    assert status == 0, cap.err
    train = [np.concatenate([arrays[0][i], arrays[1][i]]) for i in range(4)]
    pooled = identify(robot, tuple(train), validation=tuple(arrays[2]))
    _close([p["value"] for p in rep["base_parameters"]], pooled.estimate)
    assert rep["n_samples"] == 2 * N_SAMPLES
    assert [e["file"] for e in rep["per_file"]] == paths[:2]
    for entry, data in zip(rep["per_file"], arrays[:2], strict=True):
        assert entry["n_tasks"] == 4 and entry["n_samples"] == N_SAMPLES
        own = identify(robot, tuple(data), base=pooled.base)
        _close([p["value"] for p in entry["parameters"]], own.estimate)
    assert rep["relative_error"]["validation"] == pytest.approx(
        pooled.relative_error.validation, rel=1e-6
    )
    (ventry,) = rep["relative_error"]["validation_per_file"]
    assert ventry["file"] == paths[2] and ventry["n_samples"] == N_SAMPLES
    assert rep["n_validation_samples"] == N_SAMPLES
    # the multi-file path's file information, from the tasks
    assert [q["file"] for q in rep["data_quality"]] == paths[:2]
    assert [f["n_samples"] for f in rep["files"]] == [N_SAMPLES, N_SAMPLES]
    assert (report_dir / "per_file_parameters.png").is_file()
    assert (report_dir / "index.html").is_file()
    assert "per file:" in cap.out


def test_cli_matches_the_multi_file_path(robot, fleet, tmp_path, capsys):
    """--per-file (in this process) and the local multi-file path give the same JSON numbers."""
    paths = fleet[0][:3]
    opts = ["--data", *paths, "--method", "wls", "--velocity-deadband", "0.05"]
    status, local, cap = _cli(opts, tmp_path, capsys)
    assert status == 0, cap.err
    status, fleet_rep, cap = _cli([*opts, "--per-file", "--block", "700"], tmp_path, capsys)
    assert status == 0, cap.err
    _close(
        [p["value"] for p in fleet_rep["base_parameters"]],
        [p["value"] for p in local["base_parameters"]],
    )
    assert fleet_rep["velocity_deadband"] == local["velocity_deadband"]
    assert [f["n_samples"] for f in fleet_rep["files"]] == [f["n_samples"] for f in local["files"]]


def test_cli_scheduler_local(robot, fleet, reference, tmp_path, capsys):
    paths, arrays, _ = fleet
    status, rep, cap = _cli(
        ["--data", paths[0], "--scheduler", "local:2", "--block", "500", "--method", "wls"],
        tmp_path, capsys,
    )  # fmt: skip
    assert status == 0, cap.err
    own = identify(robot, tuple(arrays[0]), method="wls")
    _close([p["value"] for p in rep["base_parameters"]], own.estimate)
    assert rep["source"]["scheduler"] == "local:2"


def test_cli_scheduler_file(robot, fleet, dask_cli, tmp_path, capsys):
    paths, arrays, _ = fleet
    status, rep, cap = _cli(
        ["--data", paths[2], "--scheduler", str(dask_cli["file"])], tmp_path, capsys
    )
    assert status == 0, cap.err
    _close([p["value"] for p in rep["base_parameters"]], identify(robot, tuple(arrays[2])).estimate)


@pytest.mark.parametrize(
    "args,match",
    [
        (["--scheduler", "nowhere"], "local"),
        (["--scheduler", "local:0"], "positive"),
        (["--per-file", "--method", "rls"], "ols or wls"),
        (["--per-file", "--split", "0.5"], "--validate"),
        (["--block", "10"], "--block applies"),
        (["--scheduler", "local", "--workers", "2"], "local:N"),
    ],
)
def test_cli_bad_fleet_options(fleet, tmp_path, capsys, args, match):
    status, rep, cap = _cli(["--data", fleet[0][0], *args], tmp_path, capsys)
    assert status == 2 and rep is None
    assert match in cap.err and "Traceback" not in cap.err
    assert len(cap.err.strip().splitlines()) == 1


def test_cli_bad_file_on_the_cluster_names_it_and_writes_nothing(tmp_path, capsys):
    bad = tmp_path / "arm_bad.npz"
    bad.write_bytes(b"garbage")
    status, rep, cap = _cli(["--data", str(bad), "--scheduler", "local:1"], tmp_path, capsys)
    assert status == 2 and rep is None
    assert "arm_bad.npz" in cap.err and "Traceback" not in cap.err


def test_cli_energy_model_matches_the_local_energy_path(robot, tmp_path, capsys):
    path = tmp_path / "smooth.npz"
    _smooth_file(robot, path, seed=90)
    opts = ["--data", str(path), "--model", "energy", "--window-length", "0.02"]
    status, local, cap = _cli(opts, tmp_path, capsys)
    assert status == 0, cap.err
    status, rep, cap = _cli([*opts, "--per-file", "--block", "1000"], tmp_path, capsys)
    assert status == 0, cap.err
    # the local path filters in memory, the tasks in overlapping blocks (equal to round-off)
    _close(
        [p["value"] for p in rep["base_parameters"]],
        [p["value"] for p in local["base_parameters"]],
        rtol=1e-6,
    )
    assert rep["per_file"][0]["n_tasks"] > 1


def test_dask_carries_the_deadband_and_raw_torque_sums(robot, local_client, tmp_path):
    """Filtered files with a deadband: on Dask, in blocks, the same document as serially
    (the moving-rows and raw-torque errors travel with the sums)."""
    from manip_id.identification import PreprocessOptions

    paths = [str(tmp_path / f"raw{k}.npz") for k in range(3)]
    for k, p in enumerate(paths):
        _make_file(robot, Path(p), seed=90 + k, ddq=False)
    opts = PreprocessOptions(cutoff=20.0, velocity_deadband=0.05)
    kw = dict(validation=paths[2:], method="wls")
    serial = identify(
        robot, paths[:2], files=FileOptions(preprocess=opts, audit=False), **kw
    ).to_dict()
    dask = identify(
        robot,
        paths[:2],
        run=RunOptions(scheduler=local_client),
        files=FileOptions(preprocess=opts, audit=False, partition=PartitionOptions(block=500)),
        **kw,
    ).to_dict()
    for key in ("train", "validation", "train_moving", "validation_moving"):
        assert dask["relative_error"][key] == pytest.approx(serial["relative_error"][key], 1e-7)
    for key in ("train", "validation", "nominal_train", "nominal_validation"):
        assert dask["relative_error_raw"][key] == pytest.approx(
            serial["relative_error_raw"][key], 1e-7
        )
    assert serial["relative_error_raw"]["train"] > serial["relative_error"]["train"]


def test_identify_datasets_with_a_scheduler(robot, fleet, local_client):
    from manip_id.identification import identify

    local = identify(
        robot, fleet[0][:3], validation=fleet[0][3:4], method="wls", files=FileOptions(audit=False)
    )
    res = identify(
        robot,
        fleet[0][:3],
        validation=fleet[0][3:4],
        method="wls",
        run=RunOptions(scheduler=local_client),
        files=FileOptions(audit=False),
    )
    _same(res, local, "wls", honest=local)
    assert res.relative_error.validation == pytest.approx(local.relative_error.validation, 1e-9)
    joints = list(robot.dof_names)
    for a, b in zip(res.files["train"], local.files["train"], strict=True):
        assert a.summary(joints) == b.summary(joints)


def test_identify_files_equals_identify_datasets_nominal_errors_included(tmp_path):
    """The fleet path and the local file path give the same document (the fleet once
    rebuilt the validation errors without the nominal model's)."""
    from manip_id.identification import identify

    robot = get_robot("double_pendulum", friction=("viscous", "coulomb"))
    paths, arrays = [], []
    for f in range(3):
        q, dq, ddq = robot.random_states(800, seed=40 + f)
        tau0 = np.array(
            [pin.rnea(robot.model, robot.data, *x) for x in zip(q, dq, ddq, strict=True)]
        )
        tau = tau0 + FV * dq + FC * np.sign(dq)  # [N m]
        tau += 0.05 * np.random.default_rng(f).standard_normal(tau.shape)
        np.savez(tmp_path / f"dp{f}.npz", t=np.arange(800) * 1e-3, q=q, dq=dq, ddq=ddq, tau=tau)
        paths.append(str(tmp_path / f"dp{f}.npz"))
        fv0 = robot.nominal_parameters[
            [robot.parameter_names.index(f"{j}.fv") for j in robot.dof_names]
        ]
        arrays.append((tau0 + fv0 * dq, tau))  # the nominal model: URDF and its fv
    kw = dict(validation=paths[2:], method="wls")
    local = identify(robot, paths[:2], files=FileOptions(audit=False), **kw).to_dict()
    fleet = identify(robot, paths[:2], files=FileOptions(audit=False), **kw).to_dict()
    local.pop("timings"), fleet.pop("timings")
    assert fleet == local
    # the nominal model by rnea and numpy on the validation file's arrays
    tau0, tau = arrays[2]
    nominal = np.linalg.norm(tau - tau0) / np.linalg.norm(tau)
    rel = fleet["relative_error"]
    assert rel["nominal_validation"] == pytest.approx(nominal, rel=1e-6)
    assert rel["validation_per_file"][0]["nominal_error"] == pytest.approx(nominal, rel=1e-6)
    assert rel["nominal_train"] is not None and rel["validation"] < 0.5 * nominal
