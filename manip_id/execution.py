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

How many processes: ``workers="auto"`` (the default of
:class:`~manip_id.identification.RunOptions` and of ``--workers``) is resolved by
:func:`resolve_workers` from the size of the input: every core this process may use
(:func:`available_cores`) once there are at least :data:`FORK_MIN_SAMPLES` samples,
else one (serial), because starting a forked pool and bringing its sums back costs
more than the samples save below that size.
"""

from __future__ import annotations

import math
import multiprocessing as mp
import os
import signal
import warnings
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from ._io.reading import read_json
from .datasets import FileSpec, open_source, parse_file_spec
from .datasets.stream import infer_format
from .errors import InputError, ManipIdError, ManipIdWarning
from .robot.compiled_regressor import planned, planned_samples
from .robot.model import Robot
from .robot.sources import RobotSource

#: The automatic number of workers (:func:`resolve_workers`).
AUTO = "auto"
#: Samples from which ``workers="auto"`` forks one process per core. From
#: ``experiments/bench_workers.py`` (ur10 with friction, 2 cores): a forked pool costs
#: about 0.03 s (start, pickled sums back), a sample about 1.2 us with the compiled
#: regressor and 3.5 us with Pinocchio's, so halving the samples' time pays from about
#: 5e4 samples (compiled) and 2e4 (Pinocchio); below this, serial.
FORK_MIN_SAMPLES = 50_000
#: Parts added together by one reduction task.
SPLIT_EVERY = 8
#: The default wait [s] for a scheduler (address or file) to answer, and the variable
#: that overrides it.
CONNECT_TIMEOUT, TIMEOUT_VARIABLE = 5.0, "MANIP_ID_DASK_TIMEOUT"
#: Worker processes of ``scheduler="local"``.
DEFAULT_LOCAL_WORKERS = 2
#: Environment of the LocalCluster's workers: one BLAS thread (the tasks' matrices are
#: small; two threads per worker on two cores only take turns).
#: Tasks a local single-threaded worker holds at once (running or waiting): Dask's default
#: 1.1 rounds up to 2, so the last tasks of a run wait behind a busy worker while the other
#: idles (8 equal payload runs split 5/3 between 2 workers); 1.0 hands each task to the
#: first worker free, at the cost of one scheduler round trip (milliseconds) per task.
LOCAL_SATURATION = 1.0
WORKER_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
#: The LocalCluster's workers' periodic callbacks stopped once they run
#: (:func:`quiet_worker`): the statistical profiler, which samples the task thread's
#: Python stack every 10 ms. (A ``DASK_*`` variable in :data:`WORKER_ENV` cannot: a nanny
#: hands its own configuration to its worker, over the environment.)
STOPPED_CALLBACKS = ("profile", "profile-cycle")
#: glibc's allocator settings of the LocalCluster's workers, read when a process starts
#: (so set in this process's environment while the workers are spawned). Dask sets
#: ``MALLOC_TRIM_THRESHOLD_=65536``, which also fixes glibc's mmap threshold at 128 KiB:
#: every regressor chunk (a few MB) was then a fresh mapping, about 2 10^5 page faults
#: and 0.13 s of system time per task of 10^5 ur5 samples, about 1 s per worker in a new
#: cluster (``experiments/bench_payload_dask.py``). Blocks below 64 MiB come from the
#: heap, and up to 128 MiB of free heap is kept for the next chunk.
WORKER_MALLOC = {
    "MALLOC_MMAP_THRESHOLD_": str(64 * 2**20),
    "MALLOC_TRIM_THRESHOLD_": str(128 * 2**20),
}


def available_cores() -> int:
    """The cores this process may use (its CPU affinity, else the machine's count) [-]."""
    affinity = getattr(os, "sched_getaffinity", None)
    return len(affinity(0)) if affinity is not None else (os.cpu_count() or 1)


def check_workers(value) -> int | str:
    """``"auto"`` or a positive number of processes; raises :class:`InputError` otherwise."""
    if isinstance(value, str) and value.strip().lower() == AUTO:
        return AUTO
    if isinstance(value, bool) or not isinstance(value, (int, str)):
        raise InputError(f"workers must be 'auto' or a positive integer, got {value!r}")
    try:
        n = int(value)
    except ValueError:
        raise InputError(f"workers must be 'auto' or a positive integer, got {value!r}") from None
    if n < 1:
        raise InputError(f"workers must be a positive number of processes, got {value}")
    return n


def resolve_workers(workers, n_samples: int | None) -> int:
    """The processes of a run over ``n_samples`` samples (None: not known in advance).

    An integer is taken as it is; ``"auto"`` gives :func:`available_cores` when
    ``n_samples >= FORK_MIN_SAMPLES`` and 1 otherwise (also when the size is unknown, and
    in a daemonic process, such as a pool's or a Dask worker, which may not fork).
    """
    value = check_workers(workers)
    if value != AUTO:
        return int(value)
    if n_samples is None or int(n_samples) < FORK_MIN_SAMPLES or mp.current_process().daemon:
        return 1
    return available_cores()


#: Formats whose row count is in their headers (:func:`header_samples` reads no data).
HEADER_FORMATS = ("npz",)


def header_samples(specs: Iterable[str | os.PathLike | FileSpec]) -> int | None:
    """Rows the files hold, from their headers alone, or None when any file's count
    needs a pass over its data (a CSV, a ROS bag, a Panda log) or its header fails.

    The size a run announces (:func:`~manip_id.robot.compiled_regressor.planned_samples`) when
    its files are read by the tasks, not by this process: the rows of a ``#A:#B`` window,
    else all of them (an upper bound of the samples left by a time window and the
    preprocessing), the same number for every back-end of the run.
    A file that cannot be opened is left to the task that reads it to report, named.
    """
    total = 0
    for item in specs:
        try:
            spec = parse_file_spec(item)
            fmt = infer_format(spec.path) if spec.format is None else str(spec.format).lower()
            if fmt not in HEADER_FORMATS:
                return None
            n = open_source(spec).n_rows
        except (ManipIdError, OSError):
            return None
        if n is None:
            return None
        w = spec.window
        if w is not None and w.unit == "index":  # rows #A:#B (a time window: all rows)
            n = max(0, min(int(n), n if w.stop is None else int(w.stop)) - int(w.start or 0))
        total += int(n)
    return total


def portable_robot(robot: Robot) -> Robot:
    """A copy of ``robot`` that holds what identification needs and pickles small.

    The Pinocchio model, the joint terms and the drive train (its motor terms are
    parameters; about 0.2 MB pickled), without any geometry or cached evaluator: what is
    sent to the workers.
    """
    origin = RobotSource(
        robot.model, robot.name, robot.source, list(robot.package_dirs), robot.settings, {}, False
    )
    return Robot(
        robot.name, robot.model, robot.terms, origin=origin, transmission=robot.transmission
    )


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
    """Pool initializer: the function and its arguments, inherited through fork.

    The worker also gets the default SIGTERM and SIGINT back: a handler inherited from
    the parent (the CLI raises on SIGTERM) would leave a worker that waits on the pool's
    queue deaf to the pool's own ``terminate``.
    """
    global _forked_job
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C
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
            pool.close()  # the workers end on their own; terminate() only on an error
            pool.join()
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
    an existing ``.json`` scheduler file -> the ("address", ADDRESS) it names (read through
    the checked door, its address parsed as strictly as a given one).

    Raises :class:`InputError` otherwise."""
    spec = str(spec).strip()
    if spec == "local" or spec.startswith("local:"):
        n_text = spec.partition(":")[2] or str(DEFAULT_LOCAL_WORKERS)
        if not n_text.isdigit() or int(n_text) < 1:
            raise InputError(f"scheduler local:N needs a positive number of workers, got {spec!r}")
        return "local", int(n_text)
    if "://" in spec:
        proto, _, rest = spec.partition("://")
        host, sep, port = rest.rpartition(":")
        host = host[1:-1] if host.startswith("[") and host.endswith("]") else host  # IPv6
        if (
            proto not in ("tcp", "tls")
            or not sep
            or not host
            or any(c in host for c in "/@?# ")
            or not port.isdigit()
        ):
            raise InputError(f"scheduler address must look like tcp://HOST:PORT, got {spec!r}")
        if not 1 <= int(port) <= 65535:
            raise InputError(f"scheduler port must be in 1..65535, got {port} in {spec!r}")
        return "address", spec
    path = Path(spec).expanduser()
    if path.suffix.lower() == ".json":
        if not path.exists():
            raise InputError(f"no such scheduler file: {path}")
        doc = read_json(path, "scheduler file", InputError)
        address = doc.get("address") if isinstance(doc, dict) else None
        if not isinstance(address, str) or not address.startswith(("tcp://", "tls://")):
            raise InputError(
                f'scheduler file {path} must be a JSON object with an "address" such as '
                f"tcp://HOST:PORT (as dask-scheduler --scheduler-file writes it), got "
                f"{type(doc).__name__ if not isinstance(doc, dict) else repr(address)[:60]}"
            )
        return parse_scheduler(address)
    raise InputError(
        f"scheduler must be local[:N], tcp://HOST:PORT or a scheduler JSON file, got {spec!r}"
    )


def connect(spec: str):
    """A ``distributed.Client`` (and the LocalCluster it owns, or None) for a scheduler spec.

    ``local:N`` starts at most :func:`available_cores` workers (:func:`cap_local_workers`;
    a :class:`~manip_id.errors.ManipIdWarning` says so when N was more): on a shared
    machine more single-threaded workers than cores only take turns.
    """
    capped, asked = cap_local_workers(spec)
    if asked is not None:
        warnings.warn(
            ManipIdWarning(
                f"scheduler local:{asked} capped at the {available_cores()} cores "
                "this process may use"
            ),
            stacklevel=2,
        )
    kind, value = parse_scheduler(capped)
    dist = _distributed()
    try:
        if kind == "local":
            cluster = _local_cluster(dist, value)
            try:
                client = dist.Client(cluster)
                client.run(quiet_worker)
                return client, cluster
            except BaseException:
                cluster.close()
                raise
        timeout = connect_timeout()
        return dist.Client(value, timeout=timeout), None
    except (OSError, TimeoutError) as exc:
        raise InputError(
            f"cannot reach the Dask scheduler {spec!r} within {connect_timeout()} s "
            f"(is it running? {TIMEOUT_VARIABLE} sets the wait): {_one_line(exc)}"
        ) from exc


def quiet_worker(dask_worker) -> list[str]:
    """Stop a worker's :data:`STOPPED_CALLBACKS` (run on it by ``Client.run``); their names."""
    stopped = []
    for name in STOPPED_CALLBACKS:
        callback = dask_worker.periodic_callbacks.pop(name, None)
        if callback is not None:
            callback.stop()
            stopped.append(name)
    return stopped


def _local_cluster(dist, n: int):
    """A LocalCluster of ``n`` single-threaded worker processes on 127.0.0.1."""
    saved = {k: os.environ.get(k) for k in WORKER_MALLOC}
    os.environ.update(WORKER_MALLOC)  # inherited by the spawned workers (and over Dask's)
    try:
        cluster = dist.LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
            env=WORKER_ENV,
        )
        cluster.scheduler.WORKER_SATURATION = LOCAL_SATURATION  # in-process scheduler
        return cluster
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def connect_timeout() -> float:
    """The wait [s] for a scheduler to answer: ``$MANIP_ID_DASK_TIMEOUT``, else 5 s."""
    text = os.environ.get(TIMEOUT_VARIABLE, "").strip().removesuffix("s")
    if not text:
        return CONNECT_TIMEOUT
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0 < value <= 3600:
        raise InputError(f"{TIMEOUT_VARIABLE} must be a wait in (0, 3600] s, got {text!r}")
    return value


def cap_local_workers(spec: str) -> tuple[str, int | None]:
    """``spec`` with ``local:N`` capped at :func:`available_cores`, and the N it had (else None)."""
    kind, value = parse_scheduler(spec)
    cores = available_cores()
    if kind == "local" and value > cores:
        return f"local:{cores}", value
    return spec, None


def _one_line(exc: BaseException) -> str:
    """The first line of an exception's message (Dask's carry tracebacks of their own)."""
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def planned_task(n_planned: int, fn: Callable, *args):
    """``fn(*args)`` inside :func:`~manip_id.robot.compiled_regressor.planned_samples` of
    ``n_planned`` (a Dask task of a run its client announced; 0: none).

    The regressor path of ``auto`` mode then follows the run, not the history of the
    worker that draws the task: a run announced at least
    :data:`~manip_id.robot.compiled_regressor.AUTO_SAMPLES` large is evaluated by the compiled
    kernel from its first sample on every worker, as in the client's own process.
    """
    if n_planned <= 0:
        return fn(*args)
    with planned_samples(n_planned):
        return fn(*args)


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
        n = planned()  # the client's announced run size travels with the samples' tasks
        if n > 0 and fn is not add_values:
            fut = self.client.submit(planned_task, n, fn, *args, pure=False)
        else:
            fut = self.client.submit(fn, *args, pure=False)
        self._futures.append(fut)
        return fut

    def map(self, fn, arguments, *, on_result=None) -> list:
        """Every task in one graph update: the scheduler sees the whole group at once and
        queues it, handing a task to a worker as one frees up (submitted one by one, the
        first tasks were placed before the group's size was known: 8 equal payload runs
        split 5/3 between 2 workers)."""
        arguments = [tuple(a) for a in arguments]
        if not arguments:
            return []
        columns = [list(c) for c in zip(*arguments, strict=True)]
        n = planned()
        if n > 0 and fn is not add_values:
            k = len(arguments)
            futs = self.client.map(planned_task, [n] * k, [fn] * k, *columns, pure=False)
        else:
            futs = self.client.map(fn, *columns, pure=False)
        self._futures.extend(futs)
        return list(futs)

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


def open_backend(*, workers: int | str = 1, scheduler=None, n_samples=None) -> Backend:
    """The back-end of a run: Dask with ``scheduler``, else forked with more than one
    worker (``"auto"`` resolved against ``n_samples`` by :func:`resolve_workers`), else
    serial. Use it as a context manager (``with open_backend(...) as backend:``)."""
    if scheduler is not None:
        return DaskBackend(scheduler)
    n = resolve_workers(workers, n_samples)
    if n > 1:
        return ForkBackend(n)
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
    "AUTO",
    "DEFAULT_LOCAL_WORKERS",
    "FORK_MIN_SAMPLES",
    "HEADER_FORMATS",
    "SPLIT_EVERY",
    "STOPPED_CALLBACKS",
    "WORKER_ENV",
    "WORKER_MALLOC",
    "Backend",
    "DaskBackend",
    "ForkBackend",
    "SerialBackend",
    "add_values",
    "available_cores",
    "check_workers",
    "connect",
    "open_backend",
    "parse_scheduler",
    "planned_task",
    "quiet_worker",
    "cap_local_workers",
    "connect_timeout",
    "header_samples",
    "portable_robot",
    "reduce_tree",
    "resolve_workers",
]
