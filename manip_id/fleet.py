"""Fleet scale: identification over many logs, accumulated on Dask and solved on the client.

Least squares over a fleet of logs is a map-reduce, because the information
sums of disjoint data add (:class:`~manip_id.estimators.InformationAccumulator`
is a monoid). For files ``f`` cut into blocks ``b`` (each one task), per joint ``j``::

    A_j  = sum_f sum_b  Y_fbj^T Y_fbj        (r, r)    on the workers
    b_j  = sum_f sum_b  Y_fbj^T tau_fbj      (r,)
    zz_j = sum_f sum_b  tau_fbj^T tau_fbj
    theta_b = solve(sum_j A_j, sum_j b_j)              on the client

Each task reads its file, checks it against the robot, preprocesses it (when
the file lacks ``ddq`` or preprocessing is asked for) and accumulates its block
of base-regressor rows; the parts are added in a tree (``split_every`` at a
time: blocks into files, files into the fleet), always in the same grouping,
so the partition and the number of workers change the sums only by round-off.
The client receives ``nv`` matrices of ``r x r`` (one per file as well with
``per_file``), never samples.

Weighted least squares needs no second pass: the per-joint residual sums at an
estimate are linear in the sums, ``RSS_j(theta) = sum_tasks (zz_j - 2 b_j.theta +
theta.A_j.theta)``, i.e. the sum of the per-task residual sums, so the variances
``sigma_j^2 = RSS_j / (n - r / nv)`` and the re-weighted solve come from the
reduced sums alone, exactly as in the local run.

Back-ends: no scheduler runs the same tasks and the same tree in this process
(and imports nothing of Dask); ``"local"`` / ``"local:N"`` starts a
``LocalCluster`` of N single-threaded worker processes on 127.0.0.1 (stopped at
the end); ``"tcp://HOST:PORT"`` connects to a running scheduler; a path to a
scheduler JSON file (``dask scheduler --scheduler-file``) too; a
``distributed.Client`` is used as it is. A worker that dies mid-run has its
tasks recomputed by Dask elsewhere; a bad file fails the run with a
:class:`~manip_id.errors.DataError` naming the file, and no result.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .errors import DataError, InputError, ManipIdError, RankDeficiencyError
from .estimators import InformationAccumulator
from .identifiability import BaseParameters
from .identification import (
    IdentificationResult,
    RelativeError,
    _accumulate_blocks,
    _finish,
    _resolve_base,
    _states,
)
from .regressor import DEFAULT_CHUNK
from .robot import Robot

#: Parts added together by one reduction task.
SPLIT_EVERY = 8
#: Methods that accumulate (the online laws need the samples in order).
FLEET_METHODS: tuple[str, ...] = ("ols", "wls")
#: Worker processes of ``scheduler="local"``.
DEFAULT_LOCAL_WORKERS = 2


# ------------------------------------------------------------------ the parts
@dataclass(frozen=True)
class FilePart:
    """One task: the samples ``[start, stop)`` of one file after preprocessing.

    ``stop=None``: to the end of the file. ``file`` is the index of the file
    in the list given to :func:`identify_files`.
    """

    path: str
    file: int
    start: int = 0
    stop: int | None = None


@dataclass
class PartSums:
    """The value carried through the reduction: the information sums of some parts.

    Attributes
    ----------
    acc: the accumulated base-column information (``acc.n`` samples)
    n_parts: number of tasks summed
    timings: seconds per stage, summed over the tasks [s]
    """

    acc: InformationAccumulator
    n_parts: int = 1
    timings: dict[str, float] = field(default_factory=dict)

    def __add__(self, other: PartSums) -> PartSums:
        times = dict(self.timings)
        for k, v in other.timings.items():
            times[k] = times.get(k, 0.0) + v
        return PartSums(self.acc + other.acc, self.n_parts + other.n_parts, times)


@dataclass(frozen=True)
class FileEstimate:
    """One file's own identification, from its own sums (fleet monitoring).

    Attributes
    ----------
    path: the file
    n_samples: samples accumulated from it (after preprocessing)
    n_tasks: tasks (blocks) it was cut into
    result: its identification (same base parameters and method as the pooled
        one), or None when the file alone cannot be solved
    error: why it cannot (e.g. it does not excite every base parameter), else None
    """

    path: str
    n_samples: int
    n_tasks: int
    result: IdentificationResult | None
    error: str | None = None

    def to_dict(self) -> dict:
        """JSON-ready: estimate, std and errors by base parameter name (None if unsolved)."""
        out: dict[str, Any] = {
            "file": self.path,
            "n_samples": int(self.n_samples),
            "n_tasks": int(self.n_tasks),
            "error": self.error,
        }
        res = self.result
        if res is None:
            return out
        d = res.to_dict()
        out.update(
            parameters=[
                {k: p[k] for k in ("name", "estimate", "std", "std_percent")}
                for p in d["parameters"]
            ],
            sigma2=d["sigma2"],
            noise_variance=d["noise_variance"],
            condition_number=d["condition_number"],
            relative_error={
                "train": d["relative_error"]["train"],
                "train_per_joint": d["relative_error"]["train_per_joint"],
            },
        )
        return out


# --------------------------------------------------------------- task bodies
def portable_robot(robot: Robot) -> Robot:
    """A copy of ``robot`` that holds what identification needs and pickles small.

    The Pinocchio model and the joint terms (about 0.2 MB pickled) without the
    meshes a robot of example-robot-data may carry (hundreds of MB): what is
    sent to the workers.
    """
    return Robot(
        robot.name,
        robot.model,
        robot.terms,
        source=robot.source,
        package_dirs=robot.package_dirs,
        settings=robot.settings,
    )


def _prepared_file(robot: Robot, path: str, options: Mapping | None):
    """Read one file, check it against the robot and preprocess it.

    ``options=None``: preprocessed (default settings) only when the file has no
    ``ddq``; a mapping: always, with these keywords of
    :func:`manip_id.signals.preprocess`. The one place that reads a file for a
    task (to be pointed at the chunked per-file reader of the real-log pipeline).
    """
    from .datasets import check_robot, load_dataset
    from .signals import preprocess

    ds = load_dataset(path)
    check_robot(ds, robot)
    if options is not None or ds.ddq is None:
        ds = preprocess(ds, **dict(options or {}))
    return ds


def _named(path: str, exc: BaseException) -> DataError:
    msg = str(exc) if isinstance(exc, ManipIdError) else f"{type(exc).__name__}: {exc}"
    return DataError(msg if path in msg else f"{path}: {msg}")


def file_length(robot: Robot, path: str, options: Mapping | None = None) -> int:
    """Number of samples of a file after preprocessing (what its blocks partition)."""
    try:
        return int(_prepared_file(robot, path, options).n_samples)
    except Exception as exc:
        raise _named(path, exc) from exc


def part_sums(
    robot: Robot,
    part: FilePart,
    columns: np.ndarray,
    chunk: int = DEFAULT_CHUNK,
    options: Mapping | None = None,
) -> PartSums:
    """The task body: read, preprocess and accumulate one part of one file.

    Parameters
    ----------
    robot: the robot (:func:`portable_robot` for a worker)
    part: the file and the block of its preprocessed samples
    columns: the base parameters' independent columns, shape (r,)
    chunk: samples per regressor chunk
    options: preprocessing keywords (see :func:`_prepared_file`)

    Raises
    ------
    DataError: naming the file, whatever went wrong with it.
    """
    t0 = time.perf_counter()
    try:
        ds = _prepared_file(robot, part.path, options)
        t1 = time.perf_counter()
        n = ds.n_samples
        stop = n if part.stop is None else min(int(part.stop), n)
        if not 0 <= part.start < stop:
            raise DataError(f"block [{part.start}, {part.stop}) is outside its {n} samples")
        sl = slice(part.start, stop)
        acc, times = _accumulate_blocks(
            robot,
            [(ds.q[sl], ds.dq[sl], ds.ddq[sl], ds.tau[sl])],
            np.asarray(columns, dtype=np.intp),
            int(chunk),
        )
    except Exception as exc:
        raise _named(part.path, exc) from exc
    return PartSums(acc, 1, {"read_preprocess": t1 - t0, **times})


def _validation_sums(
    robot: Robot,
    path: str,
    columns: np.ndarray,
    estimate: np.ndarray,
    chunk: int,
    options: Mapping | None,
) -> np.ndarray:
    """Per joint ``(sum e_j^2, sum tau_j^2, n)`` of one validation file, shape (3, nv).

    ``e = Y_b theta_b - tau`` [N m]; row 2 holds the sample count (in every column).
    """
    try:
        ds = _prepared_file(robot, path, options)
        q, dq, ddq, tau = _states(robot, ds.q, ds.dq, ds.ddq, ds.tau, prefix="validation ")
        out = np.zeros((3, robot.nv))
        out[2] = q.shape[0]
        ind = np.asarray(columns, dtype=np.intp)
        for c in robot.evaluator.iter_regressor(q, dq, ddq, int(chunk)):
            err = c.Y[:, :, ind] @ estimate - tau[c.start : c.stop]  # [N m]
            out[0] += np.einsum("nj,nj->j", err, err)
            out[1] += np.einsum("nj,nj->j", tau[c.start : c.stop], tau[c.start : c.stop])
    except Exception as exc:
        raise _named(path, exc) from exc
    return out


def _blocks_sums(robot: Robot, func: Callable, args: tuple, columns, chunk: int) -> PartSums:
    """Task body of a generic part ``(func, args)``: accumulate the blocks ``func(*args)``."""
    t0 = time.perf_counter()
    acc, times = _accumulate_blocks(robot, func(*args), np.asarray(columns, np.intp), int(chunk))
    return PartSums(acc, 1, {**times, "task": time.perf_counter() - t0})


def accumulate_parts(
    robot: Robot,
    parts: Sequence[tuple[Callable, tuple]],
    columns,
    chunk: int = DEFAULT_CHUNK,
    scheduler=None,
    split_every: int = SPLIT_EVERY,
) -> tuple[InformationAccumulator, dict[str, float]]:
    """The Dask back-end of :func:`manip_id.identification.identify_chunks`.

    ``parts``: ``(func, args)`` pairs, ``func(*args)`` yielding blocks
    ``(q, dq, ddq, tau)``; ``func`` must be importable on the workers (a
    module-level function) and ``args`` picklable. Each part is one task; the
    sums are added in a tree; returns the accumulator and the summed task times.
    """
    parts = list(parts)
    if not parts:
        raise InputError("no parts to accumulate")
    light = portable_robot(robot)
    backend = _Serial() if scheduler is None else _Dask(scheduler)
    try:
        leaves = [
            backend.submit(_blocks_sums, light, func, tuple(args), columns, chunk)
            for func, args in parts
        ]
        (total,) = backend.gather([_tree(backend, leaves, int(split_every))])
    finally:
        backend.close()
    return total.acc, dict(total.timings)


def _sum(*parts):
    """Add parts in their order (one reduction task)."""
    total = parts[0]
    for p in parts[1:]:
        total = total + p
    return total


# ------------------------------------------------------------------ back-ends
class _Serial:
    """The tasks and the tree of the distributed run, in this process, eagerly."""

    client = None
    description = "in this process"

    def submit(self, fn: Callable, *args):
        return fn(*args)

    def gather(self, items):
        return list(items) if isinstance(items, list) else items

    def close(self) -> None:
        pass


class _Dask:
    """Tasks on a ``dask.distributed`` cluster (futures); only sums come back."""

    def __init__(self, scheduler):
        from distributed import Client

        self._own_client = self._cluster = None
        if isinstance(scheduler, Client):
            self.client = scheduler
        else:
            self.client, self._cluster = _connect(str(scheduler))
            self._own_client = self.client
        self._futures: list = []
        info = self.client.scheduler_info()
        self.n_workers = len(info.get("workers", {}))
        self.description = f"Dask at {self.client.scheduler.address} ({self.n_workers} workers)"

    def submit(self, fn: Callable, *args):
        fut = self.client.submit(fn, *args, pure=False)
        self._futures.append(fut)
        return fut

    def gather(self, items):
        return self.client.gather(items)

    def close(self) -> None:
        try:
            if self._futures:
                self.client.cancel(self._futures)
        finally:
            self._futures = []
            if self._own_client is not None:
                self._own_client.close()
            if self._cluster is not None:
                self._cluster.close()


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


def _connect(spec: str):
    """A client (and the LocalCluster it owns, if any) for a scheduler spec."""
    kind, value = parse_scheduler(spec)
    from distributed import Client, LocalCluster

    try:
        if kind == "local":
            cluster = LocalCluster(
                n_workers=value,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
                env={"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"},
            )
            try:
                return Client(cluster), cluster
            except BaseException:
                cluster.close()
                raise
        if kind == "address":
            return Client(value, timeout=os.environ.get("MANIP_ID_DASK_TIMEOUT", "30s")), None
        return Client(scheduler_file=value, timeout="30s"), None
    except (OSError, TimeoutError) as exc:
        raise InputError(f"cannot reach the Dask scheduler {spec!r}: {exc}") from exc


def _tree(backend, items: list, split_every: int):
    """Add ``items`` in a tree, ``split_every`` consecutive ones per task; the root."""
    while len(items) > 1:
        items = [
            backend.submit(_sum, *items[i : i + split_every])
            for i in range(0, len(items), split_every)
        ]
    return items[0]


# --------------------------------------------------------------------- entry
def _check_paths(paths, what: str) -> list[str]:
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    out = [str(p) for p in paths]
    if not out:
        raise InputError(f"{what}: no files given")
    seen: set[str] = set()
    for p in out:
        key = os.path.realpath(p)
        if key in seen:
            raise InputError(f"{what}: {p} is given twice (its samples would count twice)")
        seen.add(key)
    return out


def identify_files(
    robot: Robot,
    paths: Sequence[str | os.PathLike],
    *,
    scheduler=None,
    method: str = "ols",
    per_file: bool = False,
    block: int | None = None,
    preprocess: Mapping | None = None,
    validation: Sequence[str | os.PathLike] | None = None,
    chunk: int = DEFAULT_CHUNK,
    base: BaseParameters | None = None,
    minimum_norm: bool = False,
    split_every: int = SPLIT_EVERY,
) -> IdentificationResult:
    """Identify the base parameters of ``robot`` from many files, each file a task.

    Parameters
    ----------
    robot: the robot
    paths: data files (any format of :func:`manip_id.datasets.load_dataset`),
        each preprocessed on its own
    scheduler: None (this process, no Dask), ``"local[:N]"``, ``"tcp://HOST:PORT"``,
        a scheduler JSON file, or a ``distributed.Client``
    method: ``"ols"`` or ``"wls"``
    per_file: also each file's own estimate and errors
        (``result.per_file``, a list of :class:`FileEstimate`)
    block: samples (after preprocessing) per task; a longer file is cut into
        blocks, each one task (default: one task per file)
    preprocess: keywords of :func:`manip_id.signals.preprocess` applied to every
        file; default: only files without ``ddq`` are preprocessed, with the
        default settings
    validation: files for the validation error (each one task)
    chunk: samples per regressor chunk
    base: base parametrization; default the structural one
    minimum_norm: solve rank-deficient data with the minimum-norm solution
    split_every: parts added by one reduction task (>= 2)

    Returns
    -------
    The usual :class:`~manip_id.identification.IdentificationResult`, equal to
    the local run's to round-off whatever the workers or the partition; its
    timings hold the summed task times and ``distributed`` (the wall time of
    the map-reduce) [s].

    Raises
    ------
    DataError: a file that cannot be read or used, named (no partial result).
    RankDeficiencyError: the pooled data do not excite every base parameter.
    """
    timings: dict[str, float] = {}
    t_start = time.perf_counter()
    if method not in FLEET_METHODS:
        raise InputError(
            f"fleet identification accumulates {list(FLEET_METHODS)}, got {method!r} "
            "(the online laws need the samples in order)"
        )
    files = _check_paths(paths, "paths")
    vfiles = None if validation is None else _check_paths(validation, "validation")
    if block is not None and int(block) < 1:
        raise InputError(f"block must be a positive number of samples, got {block}")
    if int(chunk) < 1:
        raise InputError(f"chunk must be a positive number of samples, got {chunk}")
    if int(split_every) < 2:
        raise InputError(f"split_every must be >= 2, got {split_every}")
    if preprocess is not None and not isinstance(preprocess, Mapping):
        raise InputError(f"preprocess must be a mapping of keywords, got {type(preprocess)}")
    opts = None if preprocess is None else dict(preprocess)
    base = _resolve_base(robot, base, timings)
    ind = np.asarray(base.independent, dtype=np.intp)
    light = portable_robot(robot)

    backend = _Serial() if scheduler is None else _Dask(scheduler)
    try:
        t0 = time.perf_counter()
        if block is None:
            layout = [[FilePart(p, i)] for i, p in enumerate(files)]
        else:
            lengths = backend.gather([backend.submit(file_length, light, p, opts) for p in files])
            layout = []
            for i, (p, n) in enumerate(zip(files, lengths, strict=True)):
                if n < 1:
                    raise DataError(f"{p}: no samples left after preprocessing")
                cuts = list(range(0, n, int(block))) + [n]
                spans = zip(cuts[:-1], cuts[1:], strict=True)
                layout.append([FilePart(p, i, a, b) for a, b in spans])
        per = [
            _tree(
                backend,
                [backend.submit(part_sums, light, pt, ind, chunk, opts) for pt in lp],
                split_every,
            )
            for lp in layout
        ]
        total = _tree(backend, list(per), split_every)
        fetched = backend.gather([total, *per] if per_file else [total])
        timings["distributed"] = time.perf_counter() - t0
        sums: PartSums = fetched[0]
        timings.update(sums.timings)
        if sums.acc.n * robot.nv <= base.n_base:
            raise InputError(
                f"{sums.acc.n} samples give {sums.acc.n * robot.nv} equations for "
                f"{base.n_base} base parameters: need more samples"
            )
        result = _finish(
            robot,
            sums.acc,
            base,
            method,
            timings,
            t_start,
            chunk=int(chunk),
            minimum_norm=minimum_norm,
        )
        if vfiles is not None:
            t0 = time.perf_counter()
            est = np.asarray(result.estimate, dtype=float)
            vs = [backend.submit(_validation_sums, light, p, ind, est, chunk, opts) for p in vfiles]
            got = backend.gather(vs)
            val, val_j = _relative(np.sum(got, axis=0))
            per_vfile = []
            for path, sums in zip(vfiles, got, strict=True):
                err, err_j = _relative(sums)
                per_vfile.append(
                    {
                        "file": path,
                        "n_samples": int(sums[2, 0]),
                        "error": _finite(err),
                        "per_joint": dict(zip(robot.dof_names, map(_finite, err_j), strict=True)),
                    }
                )
            timings["validation"] = time.perf_counter() - t0
            re = result.relative_error
            result = replace(
                result,
                relative_error=RelativeError(
                    re.train, re.train_per_joint, val, val_j, validation_per_file=per_vfile
                ),
            )
    finally:
        backend.close()

    if per_file:
        estimates = []
        for path, lp, fs in zip(files, layout, fetched[1:], strict=True):
            estimates.append(_file_estimate(robot, path, len(lp), fs, base, method, chunk))
        result = replace(result, per_file=estimates)
    result.timings["total"] = time.perf_counter() - t_start
    return result


def _relative(sums: np.ndarray) -> tuple[float, np.ndarray]:
    """``sqrt(sum e^2 / sum tau^2)`` overall and per joint, from rows 0 and 1 of ``sums``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        per_joint = np.sqrt(sums[0] / sums[1])
    total = float(np.sqrt(sums[0].sum() / sums[1].sum())) if sums[1].sum() > 0 else float("nan")
    return total, per_joint


def _finite(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def _file_estimate(robot, path, n_tasks, fs: PartSums, base, method, chunk) -> FileEstimate:
    try:
        res = _finish(
            robot, fs.acc, base, method, dict(fs.timings), time.perf_counter(), chunk=int(chunk)
        )
        return FileEstimate(path, fs.acc.n, n_tasks, res)
    except (RankDeficiencyError, InputError) as exc:
        return FileEstimate(path, fs.acc.n, n_tasks, None, str(exc))


__all__ = [
    "FileEstimate",
    "accumulate_parts",
    "FilePart",
    "PartSums",
    "file_length",
    "identify_files",
    "parse_scheduler",
    "part_sums",
    "portable_robot",
]
