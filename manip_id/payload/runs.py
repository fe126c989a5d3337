"""The runs of a payload or drive-gain problem and their information sums.

A run is a Dataset, a tuple ``(q, dq, ddq, tau)`` or a callable giving such blocks
(a long log read block by block); :func:`as_runs` takes any of these. A problem's
*design* maps a regressor chunk ``Y`` (n, nv, p_robot) and the run's torques to the
rows ``X (n, nv, p), z (n, nv)`` of its own least squares; :func:`run_sums`
accumulates them (``A = X^T X``, ``b = X^T z``, per joint) in one pass, and
:func:`accumulate_runs` does so for every run, in this process or as Dask tasks,
adding the sums in a tree. Everything downstream (the solve, the errors, the tests)
works on these sums only.

A call announces its size (:func:`~manip_id.robot.compiled_regressor.planned_samples`) when
every run's is known beforehand (:func:`run_samples`), so that in ``auto`` regressor mode
this process and every worker take the same regressor path, whatever they ran before.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field

import numpy as np

from .._checks import as_float_array, check_finite
from ..datasets import FileSpec
from ..errors import DataError, InputError, ManipIdError
from ..estimators import InformationAccumulator
from ..estimators.uncertainty import UncertaintyOptions
from ..execution import SPLIT_EVERY, header_samples, open_backend, portable_robot, reduce_tree
from ..metrics import relative_error
from ..robot.compiled_regressor import planned_samples
from ..robot.model import Robot
from ..robot.regressor import DEFAULT_CHUNK, check_states


@dataclass(frozen=True)
class Run:
    """One run: a label, a function giving fresh blocks ``(q, dq, ddq, tau)``, joint names,
    and its arrays when it is in memory (for the check that loaded runs are not unloaded)."""

    label: str
    blocks: Callable[[], Iterable[tuple]]
    names: tuple | None = None
    arrays: tuple | None = None


@dataclass(frozen=True)
class InMemory:
    """The blocks of a run held in memory: one block, the arrays themselves."""

    arrays: tuple

    def __call__(self) -> list[tuple]:
        return [self.arrays]


def as_runs(data, what: str) -> list[Run]:
    """``data`` as a list of runs.

    Takes a Dataset (with ``ddq``), a tuple ``(q, dq, ddq, tau)`` of arrays, a function
    of no argument returning an iterable of such tuples (a long log read block by block,
    e.g. from :func:`manip_id.identification.iter_processed`), or a list of those.
    """
    if data is None:
        return []
    if (
        callable(data)
        or (hasattr(data, "tau") and hasattr(data, "q"))
        or (isinstance(data, tuple) and len(data) == 4 and np.ndim(data[0]) == 2)
    ):
        data = [data]
    out = []
    for k, item in enumerate(data):
        label = f"{what} run {k}"
        if callable(item):
            source = getattr(item, "label", None)  # e.g. a file read block by block
            out.append(Run(label if not isinstance(source, str) else f"{label} ({source})", item))
            continue
        if hasattr(item, "tau") and hasattr(item, "q"):
            if getattr(item, "ddq", None) is None:
                raise InputError(
                    f"{what} dataset {k} has no accelerations (ddq): preprocess it first "
                    "(manip_id.signals.preprocess)"
                )
            arrays = (item.q, item.dq, item.ddq, item.tau)
            names = getattr(item, "joint_names", None)
        else:
            try:
                q, dq, ddq, tau = item
            except (TypeError, ValueError) as exc:
                raise InputError(
                    f"{what} data: each run must be a Dataset, a tuple (q, dq, ddq, tau) or a "
                    f"function returning such blocks; item {k} is {type(item).__name__}"
                ) from exc
            arrays, names = (q, dq, ddq, tau), None
        out.append(Run(label, InMemory(arrays), None if names is None else tuple(names), arrays))
    return out


def check_block(robot: Robot, block: tuple, where: str, names=None):
    try:
        q, dq, ddq, tau = block
    except (TypeError, ValueError) as exc:
        raise InputError(f"{where}: each block must be a tuple (q, dq, ddq, tau)") from exc
    if names is not None and list(names) != list(robot.dof_names):
        raise DataError(
            f"{where} names the joints {list(names)} but robot {robot.name!r} has "
            f"{list(robot.dof_names)}"
        )
    try:
        batched, (q, dq, ddq) = check_states(robot, q=q, dq=dq, ddq=ddq)
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from exc
    if not batched:
        raise InputError(f"{where}: give N samples (2-D arrays), got q.shape={q.shape}")
    tau = as_float_array(tau, "tau", ndim=2)
    if tau.shape != dq.shape:
        raise InputError(
            f"{where}: tau.shape={tau.shape} but expected {dq.shape} (N, robot.nv={robot.nv})"
        )
    try:
        check_finite(tau, "tau", robot.dof_names)
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from exc
    return q, dq, ddq, tau


def check_distinct(unloaded: list, loaded: list) -> None:
    """Loaded runs that are unloaded ones carry no payload information."""
    for i, lb in enumerate(loaded):
        for k, ub in enumerate(unloaded):
            if lb.arrays is None or ub.arrays is None:
                continue
            same = all(
                np.shape(a) == np.shape(b) and np.array_equal(np.asarray(a), np.asarray(b))
                for a, b in zip(lb.arrays, ub.arrays, strict=True)
            )
            if same:
                raise DataError(
                    f"loaded run {i} is the same data as unloaded run {k}: the loaded runs "
                    "carry no payload information (record them with the payload mounted)"
                )
    names = {tuple(b.names) for b in unloaded + loaded if b.names is not None}
    if len(names) > 1:
        raise DataError(
            "the unloaded and loaded runs name different joints: "
            + " vs ".join(str(list(n)) for n in sorted(names))
        )


Design = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass
class RunSums:
    """The information sums of some runs (what a Dask task returns; they add).

    Attributes
    ----------
    acc
        the accumulated rows of the runs' design
    left_out
        rows left out by the velocity deadband per joint, shape (nv,)
    runs
        per run, in order, what its source reports (``summary()`` of a run given as
        a callable object that has one, e.g. a file's data quality and preprocessing;
        else None)
    """

    acc: InformationAccumulator
    left_out: np.ndarray
    runs: list = field(default_factory=list)

    def __add__(self, other: RunSums) -> RunSums:
        return RunSums(self.acc + other.acc, self.left_out + other.left_out, self.runs + other.runs)


def run_sums(
    robot: Robot,
    run: Run,
    design: Design,
    chunk: int = DEFAULT_CHUNK,
    deadband: float | None = None,
    stream: int = 0,
) -> RunSums:
    """One run's information sums: the body of the local loop and of a Dask task.

    Reads the run's blocks (a file is read on the worker when the run's blocks come
    from a callable object that reads it), checks each against the robot and
    accumulates ``design(Y, tau) -> (X (n, nv, p), z (n, nv))`` over chunks of
    ``chunk`` samples. Rows of joint ``j`` with ``|dq_j| < deadband`` [rad/s] are left
    out (their row of X and z zeroed, which removes them from every sum).

    Parameters
    ----------
    robot
        the robot (:func:`manip_id.execution.portable_robot` for a worker)
    run
        the run (its label, blocks and joint names); picklable for a worker
    design
        the rows of the problem, a picklable callable with ``n_cols``
    chunk
        samples per regressor chunk; deadband: see above
    stream
        the run's number in the problem: its per-block sums (for the autocorrelation-
        consistent covariance, :mod:`manip_id.estimators.uncertainty`) are a record of
        their own

    Raises
    ------
    InputError / DataError: naming the run (its file for a file), whatever went wrong.
    """
    ev = robot.evaluator
    n_cols = int(design.n_cols)  # type: ignore[attr-defined]
    acc = UncertaintyOptions().accumulator(n_cols, robot.nv, stream=int(stream))
    left_out = np.zeros(robot.nv, dtype=np.int64)
    try:
        for block in run.blocks():
            q, dq, ddq, tau = check_block(robot, block, run.label, run.names)
            for c in ev.iter_regressor(q, dq, ddq, int(chunk)):
                X, z = design(c.Y, tau[c.start : c.stop])
                if deadband is not None:
                    keep = np.abs(dq[c.start : c.stop]) >= deadband  # (n, nv)
                    X = X * keep[:, :, None]
                    z = z * keep
                    left_out += (~keep).sum(axis=0)
                acc.add(X, z, check=False)
    except ManipIdError as exc:
        if run.label in str(exc):
            raise
        cls = InputError if isinstance(exc, InputError) else DataError
        raise cls(f"{run.label}: {exc}") from exc
    except Exception as exc:
        raise DataError(f"{run.label}: {type(exc).__name__}: {exc}") from exc
    summary = getattr(run.blocks, "summary", None)
    return RunSums(acc, left_out, [summary() if callable(summary) else None])


def run_samples(run: Run) -> int | None:
    """The samples of ``run`` known before it is read, else None.

    Its arrays' rows; for a callable, its ``n_samples`` attribute (an int) when it has
    one, else, for one that reads a file (a ``spec`` attribute, a
    :class:`~manip_id.datasets.FileSpec`, as the command line's runs), the rows the file's
    header declares (:func:`~manip_id.execution.header_samples`: an upper bound).
    """
    if run.arrays is not None:
        return int(np.shape(run.arrays[0])[0])
    n = getattr(run.blocks, "n_samples", None)
    if isinstance(n, (int, np.integer)) and not isinstance(n, bool):
        return int(n)
    spec = getattr(run.blocks, "spec", None)
    return header_samples([spec]) if isinstance(spec, FileSpec) else None


def accumulate_runs(
    robot: Robot,
    groups: Sequence[tuple[list[Run], Design]],
    *,
    chunk: int,
    deadband: float | None,
    scheduler=None,
) -> list[RunSums]:
    """Each group's runs summed, one :func:`run_sums` task per run, added in a tree.

    ``scheduler``: None (this process, nothing of Dask imported) or any scheduler of
    :func:`manip_id.execution.open_backend` (``"local[:N]"``, ``"tcp://HOST:PORT"``, a
    scheduler JSON file, a ``distributed.Client``). The same tasks and the same tree
    either way; a failing run fails the whole call (no partial sums). The call is
    announced as one run of the runs' samples when :func:`run_samples` knows them all.
    """
    worker_robot = robot if scheduler is None else portable_robot(robot)
    sizes = [run_samples(run) for runs, _ in groups for run in runs]
    known = all(n is not None for n in sizes) and sum(sizes) > 0  # type: ignore[arg-type]
    announced = planned_samples(sum(sizes)) if known else nullcontext()  # type: ignore[arg-type]
    with announced, open_backend(scheduler=scheduler) as backend:
        args = [
            (worker_robot, run, design, int(chunk), deadband)
            for runs, design in groups
            for run in runs
        ]
        leaves = backend.map(run_sums, [(*a, stream) for stream, a in enumerate(args)])
        roots, at = [], 0  # every run's task at once (balanced), then a tree per group
        for runs, _ in groups:
            roots.append(reduce_tree(backend, leaves[at : at + len(runs)], SPLIT_EVERY))
            at += len(runs)
        return list(backend.gather(roots))


def sub_accumulator(acc: InformationAccumulator, cols: np.ndarray, offset=None, known=None):
    """An accumulator over ``cols`` of ``acc`` for ``z - X[:, other] known``."""
    cols = np.asarray(cols, dtype=np.intp)
    A = acc.A_joint
    b = acc.b_joint
    zz = acc.zz_joint
    out = InformationAccumulator(cols.size, acc.nv)
    Ab, bb, zb = [], [], np.empty(acc.nv)
    for j in range(acc.nv):
        Aj = A[j][np.ix_(cols, cols)]
        bj = b[j][cols]
        zj = zz[j]
        if offset is not None:
            oc = np.asarray(offset, dtype=np.intp)
            bj = bj - A[j][np.ix_(cols, oc)] @ known
            zj = zj - 2.0 * b[j][oc] @ known + known @ A[j][np.ix_(oc, oc)] @ known
        Ab.append(Aj)
        bb.append(bj)
        zb[j] = zj
    out.add_sums(Ab, bb, zb, acc.n)
    return out


def check_deadband(deadband) -> float | None:
    if deadband is None:
        return None
    d = float(deadband)
    if not (math.isfinite(d) and d >= 0):
        raise InputError(f"velocity_deadband must be >= 0 [rad/s], got {deadband}")
    return d if d > 0 else None


def relative_errors(accs: dict, x: np.ndarray) -> tuple[dict, dict]:
    """Per kind of run (``accs``: name -> accumulator or None), the relative error of ``x``
    overall and per joint (:func:`manip_id.metrics.relative_error`); empty kinds are left out."""
    total, per = {}, {}
    for key, acc in accs.items():
        if acc is None or acc.n == 0:
            continue
        total[key], per[key] = relative_error(acc.residual_sum_of_squares(x), acc.zz_joint)
    return total, per


def dof_factor(acc: InformationAccumulator, rank: int, left_out: np.ndarray) -> float:
    """Covariance correction for rows left out: ``(M - rank) / (M - left_out - rank)``."""
    m = acc.n_rows
    dropped = int(left_out.sum())
    if dropped == 0:
        return 1.0
    if m - dropped - rank <= 0:
        raise InputError(
            f"the velocity deadband leaves {m - dropped} rows for {rank} parameters: "
            "lower it or give more data"
        )
    return (m - rank) / (m - dropped - rank)
