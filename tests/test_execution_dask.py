"""The Dask side of the execution layer: the local cluster it starts, and the regressor
path of a run, which follows the run's announced size on every process of it.

The cluster's workers are asked directly (``Client.run``) what they hold: their Dask
configuration, their BLAS environment, the size a task sees announced.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from manip_id import execution, load_robot
from manip_id.errors import ManipIdWarning
from manip_id.execution import DaskBackend, add_values, connect, header_samples, reduce_tree
from manip_id.robot import compiled_regressor as cr

pytest.importorskip("distributed")


def _worker_settings(dask_worker) -> dict:
    import os

    return {
        "profile": "profile" in dask_worker.periodic_callbacks,
        "blas": os.environ.get("OPENBLAS_NUM_THREADS"),
        "malloc": {k: os.environ.get(k) for k in execution.WORKER_MALLOC},
    }


def test_connect_caps_local_workers_at_the_cores(monkeypatch):
    monkeypatch.setattr(execution, "available_cores", lambda: 1)
    monkeypatch.delenv("MALLOC_MMAP_THRESHOLD_", raising=False)
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "12345")
    with pytest.warns(ManipIdWarning, match=r"local:3 capped at the 1 cores"):
        client, cluster = connect("local:3")
    try:
        settings = client.run(_worker_settings)
        assert len(settings) == 1  # one worker, not three
        # the workers run without the statistical profiler, on one BLAS thread, with the
        # allocator's settings; this process's environment is left as it was
        want = {"profile": False, "blas": "1", "malloc": execution.WORKER_MALLOC}
        assert list(settings.values()) == [want]
        assert "MALLOC_MMAP_THRESHOLD_" not in os.environ
        assert os.environ["MALLOC_TRIM_THRESHOLD_"] == "12345"
    finally:
        client.close()
        cluster.close()


def test_connect_leaves_the_dask_configuration_as_it_was():
    """The profiler is stopped on the workers themselves: the global configuration of
    this process is the same after a local cluster as before it."""
    import copy

    import dask

    before = copy.deepcopy(dask.config.config)
    client, cluster = connect("local:1")
    try:
        assert client.submit(sum, [1, 2]).result() == 3
        assert [s["profile"] for s in client.run(_worker_settings).values()] == [False]
    finally:
        client.close()
        cluster.close()
    assert dask.config.config == before


def test_connect_within_the_cores_does_not_warn(monkeypatch, recwarn):
    monkeypatch.setattr(execution, "available_cores", lambda: 4)
    assert execution.cap_local_workers("local:2") == ("local:2", None)
    assert execution.cap_local_workers("local:9") == ("local:4", 9)
    assert execution.cap_local_workers("tcp://127.0.0.1:8786") == ("tcp://127.0.0.1:8786", None)
    assert not [w for w in recwarn if issubclass(w.category, ManipIdWarning)]


@pytest.fixture(scope="module")
def backend():
    """A DaskBackend on a LocalCluster of two workers (capped at the cores)."""
    with DaskBackend("local:2") as b:
        yield b


def test_tasks_see_the_clients_announced_run(backend):
    n = cr.AUTO_SAMPLES // 2  # small: the kernel is not loaded by the announcement
    with cr.planned_samples(n):
        inside = backend.gather([backend.submit(cr.planned) for _ in range(4)])
    outside = backend.gather([backend.submit(cr.planned)])
    assert inside == [n] * 4
    assert outside == [0]
    # the reduction tasks add values and see nothing else
    with cr.planned_samples(n):
        root = reduce_tree(backend, [backend.submit(int, k) for k in range(5)], 2)
    assert backend.gather([root]) == [10]
    assert add_values(1, 2, 3) == 6


def _path_after_history(history: int, planned: int) -> bool:
    """In a process that has evaluated ``history`` samples: does a block of 10 samples of
    a run announced at ``planned`` (0: none) take the compiled kernel?"""
    robot = load_robot("double_pendulum")
    cr.count_samples(history)
    with cr.planned_samples(planned) if planned else _nothing():
        return robot.evaluator.kernel_for(10) is not None


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


@pytest.mark.skipif(not cr.numba_available(), reason="the compiled kernel needs numba")
def test_an_announced_run_is_decided_by_its_size_alone(monkeypatch):
    monkeypatch.setenv(cr.ENV, "auto")
    monkeypatch.setattr(cr, "_seen", 0)  # a fresh process
    assert not _path_after_history(0, 1000)
    assert _path_after_history(0, cr.AUTO_SAMPLES)  # large from its first block
    monkeypatch.setattr(cr, "_seen", 0)
    # a long-lived process past the threshold: a small announced run still takes Pinocchio
    assert not _path_after_history(10 * cr.AUTO_SAMPLES, 1000)
    # without an announcement, the process's history decides (as before)
    assert _path_after_history(0, 0)


@pytest.mark.skipif(not cr.numba_available(), reason="the compiled kernel needs numba")
def test_workers_with_another_history_take_the_run_s_path(backend, monkeypatch):
    """Workers that evaluated many samples before and a fresh client: one path per run."""
    monkeypatch.setenv(cr.ENV, "auto")
    monkeypatch.setattr(cr, "_seen", 0)
    backend.client.run(cr.count_samples, 10 * cr.AUTO_SAMPLES)  # long-lived workers
    with cr.planned_samples(1000):
        here = _path_after_history(0, 1000)
        there = backend.gather([backend.submit(_path_after_history, 0, 0) for _ in range(2)])
    assert here is False and there == [False, False]
    with cr.planned_samples(cr.AUTO_SAMPLES):
        there = backend.gather([backend.submit(_path_after_history, 0, 0) for _ in range(2)])
    assert there == [True, True]


def _npz(path, n):
    rng = np.random.default_rng(n)
    np.savez(
        path,
        t=np.arange(n) * 1e-3,
        q=rng.standard_normal((n, 2)),
        dq=rng.standard_normal((n, 2)),
        tau=rng.standard_normal((n, 2)),
    )
    return str(path)


def test_header_samples_counts_what_the_headers_declare(tmp_path):
    a, b = _npz(tmp_path / "a.npz", 120), _npz(tmp_path / "b.npz", 30)
    assert header_samples([a, b]) == 150
    assert header_samples([f"{a}@#10:50", f"{b}@#25:"]) == 40 + 5
    assert header_samples([f"{a}@#100:500"]) == 20  # the window's rows that exist
    assert header_samples([f"{a}@0.01:0.02"]) == 120  # a time window: every row (a bound)
    csv = tmp_path / "c.csv"
    csv.write_text("t,q1\n0,0\n")
    assert header_samples([a, str(csv)]) is None  # a CSV's rows need a pass
    broken = tmp_path / "broken.npz"
    broken.write_bytes(b"\x00" * 64)
    assert header_samples([a, str(broken)]) is None  # its task will name it
    assert header_samples([str(tmp_path / "missing.npz")]) is None
    assert header_samples([]) == 0


def _slow_square(x: int, seconds: float) -> tuple[int, int]:
    import os
    import time

    time.sleep(seconds)
    return x * x, os.getpid()


def test_local_workers_take_one_task_at_a_time_and_map_keeps_order():
    """A local cluster's scheduler hands a single-threaded worker one task at a time
    (Dask's default 1.1 holds two: the last tasks of a run then wait behind a busy worker
    while the other idles); ``DaskBackend.map`` submits the tasks in one graph and returns
    them in order, the values of the serial map."""
    client, cluster = connect("local:2")
    try:
        assert cluster.scheduler.WORKER_SATURATION == execution.LOCAL_SATURATION == 1.0
        backend = DaskBackend(client)
        args = [(k, 0.2) for k in range(8)]
        got = backend.gather(backend.map(_slow_square, args))
        assert [v for v, _ in got] == [k * k for k in range(8)]
        pids = [p for _, p in got]
        # eight equal tasks, handed out as workers free up: each worker ran some
        assert len(set(pids)) == 2, pids
    finally:
        client.close()
        cluster.close()
