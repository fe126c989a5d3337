"""One execution layer: serial, forked-pool and Dask back-ends behind one interface.

Identification from sums is a map-reduce: the information of disjoint data adds
(:class:`~manip_id.estimators.InformationAccumulator` is a monoid), so a run is a
list of tasks ``fn(*args)`` whose values are added in a tree::

    leaves   s_k = fn(*args_k)                                 k = 1 .. K, anywhere
    tree     S = (s_1 + ... + s_e) + (s_{e+1} + ... + s_2e) + ...   e = split_every

Every back-end has the same methods: :meth:`~Backend.submit` (one task),
:meth:`~Backend.map` (one task per argument tuple), :meth:`~Backend.gather` (the
values), :meth:`~Backend.close`, and is a context manager. :func:`reduce_tree` adds
values in the same grouping on every back-end, so the back-end changes a sum only by
round-off.

- :class:`SerialBackend`: the tasks in this process, eagerly; imports nothing of Dask.
- :class:`ForkBackend`: :meth:`~ForkBackend.map` runs the tasks in ``workers`` forked
  processes; the function and its arguments reach the workers through ``fork`` (never
  pickled, so arrays are shared copy-on-write), the values come back pickled (small
  sums). Single tasks and the reduction run in this process.
- :class:`DaskBackend`: futures on a ``dask.distributed`` cluster: ``"local[:N]"`` (a
  ``LocalCluster`` of N single-threaded worker processes on 127.0.0.1, stopped on
  close), ``"tcp://HOST:PORT"``, a scheduler JSON file, or a ``distributed.Client``
  used as it is. Only the reduced sums come back to the client.
"""

from __future__ import annotations

import multiprocessing as mp
import os
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from .errors import InputError
from .robot import Robot
from .robot_sources import RobotSource

#: Parts added together by one reduction task.
SPLIT_EVERY = 8
#: Worker processes of ``scheduler="local"``.
DEFAULT_LOCAL_WORKERS = 2
#: Environment of the LocalCluster's workers: one BLAS thread (the tasks' matrices are
#: small), and no statistical profiler (it samples the task thread's Python stack every
#: 10 ms, which slowed the regressor loop by about 20 % in ``experiments/bench_fleet.py``).
WORKER_ENV = {
    "OPENBLAS_NUM_THREADS": "1",
    "OMP_NUM_THREADS": "1",
    "DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED": "False",
}


def portable_robot(robot: Robot) -> Robot:
    """A copy of ``robot`` that holds what identification needs and pickles small.

    The Pinocchio model and the joint terms (about 0.2 MB pickled), without any
    geometry or cached evaluator: what is sent to the workers.
    """
    origin = RobotSource(
        robot.model, robot.name, robot.source, list(robot.package_dirs), robot.settings, {}, False
    )
    return Robot(robot.name, robot.model, robot.terms, origin=origin)


def add_values(*values):
    """``values[0] + values[1] + ...`` in their order (one reduction task)."""
    total = values[0]
    for v in values[1:]:
        total = total + v
    return total


class Backend:
    """The interface of every back-end (the serial behaviour; subclasses override).

    Attributes
    ----------
    description : str
        Where the tasks run, for messages (``"in this process"``).
    client : object or None
        The ``distributed.Client`` of a Dask back-end, else None.
    """

    description = "in this process"
    client: Any = None

    def submit(self, fn: Callable, *args) -> Any:
        """One task ``fn(*args)``: its value, or a handle :meth:`gather` resolves."""
        return fn(*args)

    def map(
        self,
        fn: Callable,
        arguments: Iterable[tuple],
        *,
        on_result: Callable[[int, Any], None] | None = None,
    ) -> list:
        """One task ``fn(*args)`` per tuple of ``arguments``: values or handles, in order.

        ``on_result(k, value)`` is called as the k-th value is known (eager back-ends).
        """
        out = []
        for k, args in enumerate(arguments):
            out.append(fn(*args))
            if on_result is not None:
                on_result(k, out[-1])
        return out

    def gather(self, items: Sequence) -> list:
        """The values of ``items`` (handles of :meth:`submit` / :meth:`map`), in order."""
        return list(items)

    def close(self) -> None:
        """Release what the back-end holds (processes, futures, a cluster it started)."""

    def __enter__(self) -> Backend:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class SerialBackend(Backend):
    """The tasks and the tree of a distributed run, in this process, eagerly."""


#: The job of a forked pool, set by :func:`_set_job` in the workers only (inherited).
_forked_job: tuple | None = None


def _set_job(fn: Callable, arguments: list) -> None:
    """Pool initializer: the function and its arguments, inherited through fork."""
    global _forked_job
    _forked_job = (fn, arguments)


def _run_job(k: int):
    assert _forked_job is not None, "_set_job did not run in this process"
    fn, arguments = _forked_job
    return fn(*arguments[k])


class ForkBackend(Backend):
    """:meth:`map` in ``workers`` forked processes (POSIX ``fork``); the rest in this process.

    Parameters
    ----------
    workers : int
        Processes of each :meth:`map` (at most one per task).
    """

    def __init__(self, workers: int):
        if int(workers) < 1:
            raise InputError(f"workers must be a positive number of processes, got {workers}")
        self.workers = int(workers)
        self.description = f"{self.workers} forked processes"

    def map(self, fn, arguments, *, on_result=None) -> list:
        arguments = [tuple(a) for a in arguments]
        if len(arguments) < 2 or self.workers < 2:
            return super().map(fn, arguments, on_result=on_result)
        ctx = mp.get_context("fork")
        n = min(self.workers, len(arguments))
        out = []
        with ctx.Pool(n, initializer=_set_job, initargs=(fn, arguments)) as pool:
            for k, value in enumerate(pool.imap(_run_job, range(len(arguments)))):
                out.append(value)
                if on_result is not None:
                    on_result(k, value)
        return out


def _distributed():
    """``dask.distributed``, or an error saying how to install it."""
    try:
        import distributed  # optional heavy dependency (the fleet extra)
    except ImportError as exc:
        raise InputError(
            "a Dask scheduler needs dask.distributed: pip install 'manip_id[fleet]'"
        ) from exc
    return distributed


def parse_scheduler(spec: str) -> tuple[str, Any]:
    """``"local[:N]"`` -> ("local", N); ``"tcp://HOST:PORT"`` -> ("address", spec);
    an existing ``.json`` file -> ("file", path). Raises :class:`InputError` otherwise."""
    spec = str(spec).strip()
    if spec == "local" or spec.startswith("local:"):
        n_text = spec.partition(":")[2] or str(DEFAULT_LOCAL_WORKERS)
        if not n_text.isdigit() or int(n_text) < 1:
            raise InputError(f"scheduler local:N needs a positive number of workers, got {spec!r}")
        return "local", int(n_text)
    if "://" in spec:
        proto, _, rest = spec.partition("://")
        host, sep, port = rest.rpartition(":")
        if proto not in ("tcp", "tls", "inproc", "ucx") or not sep or not port.isdigit():
            raise InputError(f"scheduler address must look like tcp://HOST:PORT, got {spec!r}")
        return "address", spec
    path = Path(spec).expanduser()
    if path.suffix.lower() == ".json":
        if not path.is_file():
            raise InputError(f"no such scheduler file: {path}")
        return "file", str(path)
    raise InputError(
        f"scheduler must be local[:N], tcp://HOST:PORT or a scheduler JSON file, got {spec!r}"
    )


def connect(spec: str):
    """A ``distributed.Client`` (and the LocalCluster it owns, or None) for a scheduler spec."""
    kind, value = parse_scheduler(spec)
    dist = _distributed()
    try:
        if kind == "local":
            cluster = dist.LocalCluster(
                n_workers=value,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
                env=WORKER_ENV,
            )
            try:
                return dist.Client(cluster), cluster
            except BaseException:
                cluster.close()
                raise
        if kind == "address":
            timeout = os.environ.get("MANIP_ID_DASK_TIMEOUT", "30s")
            return dist.Client(value, timeout=timeout), None
        return dist.Client(scheduler_file=value, timeout="30s"), None
    except (OSError, TimeoutError) as exc:
        raise InputError(f"cannot reach the Dask scheduler {spec!r}: {exc}") from exc


class DaskBackend(Backend):
    """Tasks on a ``dask.distributed`` cluster (futures); only sums come back.

    Parameters
    ----------
    scheduler : str or distributed.Client
        A spec of :func:`parse_scheduler`, or a client used as it is (not closed).
    """

    def __init__(self, scheduler):
        client_type = _distributed().Client
        self._own_client = self._cluster = None
        if isinstance(scheduler, client_type):
            self.client = scheduler
        else:
            self.client, self._cluster = connect(str(scheduler))
            self._own_client = self.client
        self._futures: list = []
        info = self.client.scheduler_info()
        self.n_workers = len(info.get("workers", {}))
        self.description = f"Dask at {self.client.scheduler.address} ({self.n_workers} workers)"

    def submit(self, fn, *args):
        fut = self.client.submit(fn, *args, pure=False)
        self._futures.append(fut)
        return fut

    def map(self, fn, arguments, *, on_result=None) -> list:
        return [self.submit(fn, *args) for args in arguments]

    def gather(self, items) -> list:
        return list(self.client.gather(list(items)))

    def close(self) -> None:
        try:
            if self._futures:
                self.client.cancel(self._futures)
        finally:
            self._futures = []
            if self._own_client is not None:
                self._own_client.close()
                self._own_client = None
            if self._cluster is not None:
                self._cluster.close()
                self._cluster = None


def open_backend(*, workers: int = 1, scheduler=None) -> Backend:
    """The back-end of a run: Dask with ``scheduler``, else forked with ``workers > 1``,
    else serial. Use it as a context manager (``with open_backend(...) as backend:``)."""
    if scheduler is not None:
        return DaskBackend(scheduler)
    if int(workers) > 1:
        return ForkBackend(int(workers))
    return SerialBackend()


def reduce_tree(backend: Backend, items: Sequence, split_every: int = SPLIT_EVERY):
    """Add ``items`` in a tree, ``split_every`` consecutive ones per task; the root (a value
    or a handle). The grouping depends only on ``len(items)`` and ``split_every``."""
    if int(split_every) < 2:
        raise InputError(f"split_every must be >= 2, got {split_every}")
    if not items:
        raise InputError("nothing to reduce")
    items = list(items)
    while len(items) > 1:
        items = [
            backend.submit(add_values, *items[i : i + split_every])
            for i in range(0, len(items), split_every)
        ]
    return items[0]


__all__ = [
    "DEFAULT_LOCAL_WORKERS",
    "SPLIT_EVERY",
    "WORKER_ENV",
    "Backend",
    "DaskBackend",
    "ForkBackend",
    "SerialBackend",
    "add_values",
    "connect",
    "open_backend",
    "parse_scheduler",
    "portable_robot",
    "reduce_tree",
]
