"""The accumulated problem of a data set: its sums, counts and per-file records.

For N samples ``(q, dq, ddq, tau)`` and the base columns ``ind`` (r of them), each
joint's rows of the base regressor ``Y_b = Y(q, dq, ddq)[..., ind]`` are added into
the per-joint sums (:class:`~manip_id.estimators.InformationAccumulator`)::

    A_j = sum_k Y_kj^T Y_kj   (r, r)      b_j = sum_k Y_kj^T tau_kj   (r,)
    zz_j = sum_k tau_kj^2                  n = samples

Nothing holds the stacked regressor: memory is O(chunk nv p + nv r^2) whatever N.
Sums of disjoint data add, so a :class:`Problem` is built the same way from arrays,
blocks, files, forked parts or Dask tasks, and :func:`~manip_id.identification.solve`
turns any of them into the one result.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy.linalg.blas import dsyrk

from .._checks import as_float_array, check_finite, check_magnitude
from ..datasets import FileSpec
from ..errors import InputError
from ..estimators import InformationAccumulator
from ..estimators.blocks import ScoreBlocks
from ..execution import ForkBackend
from ..identifiability import BaseParameters, analyze
from ..robot.compiled_regressor import planned_samples
from ..robot.model import Robot
from ..robot.regressor import DEFAULT_CHUNK, check_states, check_temperature
from .options import RunOptions, SolveSettings, UncertaintyOptions


@dataclass
class FileRecord:
    """What is known of one file besides its sums (small, JSON-ready by :meth:`summary`).

    Attributes
    ----------
    spec : FileSpec
        The file and its window.
    n_samples : int
        Samples accumulated (after preprocessing: trimmed, decimated).
    excluded : numpy.ndarray
        Rows left out per joint by the velocity deadband, shape (nv,).
    quality : DataQuality or None
        Its data-quality summary (:class:`~manip_id.datasets.quality.DataQuality`).
    settings : PreprocessSettings or None
        The preprocessing applied (None: the file's ddq used as is).
    torque_scale : numpy.ndarray or None
        The per-joint torque scale applied, shape (nv,).
    n_tasks : int
        Tasks (blocks) it was accumulated in.
    """

    spec: FileSpec
    n_samples: int
    excluded: np.ndarray
    quality: Any = None
    settings: Any = None
    torque_scale: np.ndarray | None = None
    n_tasks: int = 1

    @property
    def label(self) -> str:
        """The file spec as written: ``path[@window]``."""
        return self.spec.label

    def record(self) -> FileRecord:
        """The record alone (no sums)."""
        return FileRecord(
            self.spec,
            int(self.n_samples),
            np.asarray(self.excluded),
            self.quality,
            self.settings,
            self.torque_scale,
            int(self.n_tasks),
        )

    def merged(self, other: FileRecord) -> FileRecord:
        """The record of two blocks of the same file."""
        return replace(
            self.record(),
            n_samples=self.n_samples + other.n_samples,
            excluded=self.excluded + other.excluded,
            n_tasks=self.n_tasks + other.n_tasks,
        )

    def summary(self, joints: Sequence[str]) -> dict:
        """JSON-ready: file, window, samples, rows left out per joint, preprocessing, torque
        scale, tasks."""
        s = self.settings
        return {
            "file": str(self.spec.path),
            "window": None if self.spec.window is None else str(self.spec.window),
            "n_samples": int(self.n_samples),
            "excluded_rows": dict(zip(joints, map(int, self.excluded), strict=True)),
            "preprocess": None if s is None else {k: getattr(s, k) for k in s.__dataclass_fields__},
            "torque_scale": None if self.torque_scale is None else self.torque_scale.tolist(),
            "n_tasks": int(self.n_tasks),
        }


@dataclass
class FileSums:
    """One file's record and its information sums (a validation file of a problem).

    Attributes
    ----------
    record : FileRecord
        The file.
    accumulator : InformationAccumulator
        Its sums over the base columns (the fit's rows).
    still, raw : InformationAccumulator or None
        The rows inside the deadband, and every row against the raw torques
        (:class:`RowSums`).
    """

    record: FileRecord
    accumulator: InformationAccumulator
    still: InformationAccumulator | None = None
    raw: InformationAccumulator | None = None


@dataclass
class OnlineRun:
    """The pass of an online law over the samples (``method="rls"`` or ``"gradient"``).

    Attributes
    ----------
    estimator : RLSEstimator or GradientEstimator
        The law after its pass (``theta``, ``history``, ``record_every``).
    description : str
        The law in words, for the result's ``solver``.
    """

    estimator: Any
    description: str


@dataclass
class Problem:
    """The accumulated information of a data set: what :func:`solve` needs, nothing more.

    Attributes
    ----------
    robot : Robot
        The robot (names, units, nominal parameters, bodies of a consistent estimate).
    base : BaseParameters
        The base parametrization of the accumulated columns (r of them).
    accumulator : InformationAccumulator
        The per-joint sums of the training rows (module docstring).
    n_samples : int
        Training samples N.
    timings : dict
        Seconds per stage so far [s].
    t_start : float
        ``time.perf_counter()`` at the start of the run [s].
    validation_blocks : list or None
        ``(q, dq, ddq, tau)`` blocks streamed once more for the validation error.
    validation_files : list of FileSums or None
        Per validation file its sums (the errors follow from them, no pass).
    files : dict or None
        ``{"train": [FileRecord], "validation": [FileRecord] or None}``.
    model : str
        "dynamic", "energy" or "momentum" (the rows' equation).
    online : OnlineRun or None
        The online law's pass, for ``rls`` / ``gradient``.
    chunk : int
        Samples per regressor chunk of a streamed validation pass.
    still, raw : InformationAccumulator or None
        The training rows inside the velocity deadband (Coulomb column zero), and every
        training row against the raw, unfiltered torques (:class:`RowSums`).
    settings : SolveSettings
        The method and the solve's options (what :func:`solve` uses unless told otherwise).
    context : dict
        What the run knows besides the sums (source, preprocessing, audit, data quality,
        the friction selection ...): merged into the result's ``context``.
    post : list of callable
        Steps ``result -> result`` run by :func:`solve` after the fit, in order (the
        missing-term warnings of a consistent fit, the temperature reference, per-file
        estimates).
    """

    robot: Robot
    base: BaseParameters
    accumulator: InformationAccumulator
    n_samples: int
    timings: dict = field(default_factory=dict)
    t_start: float = field(default_factory=time.perf_counter)
    validation_blocks: list | None = None
    validation_files: list[FileSums] | None = None
    files: dict | None = None
    model: str = "dynamic"
    online: OnlineRun | None = None
    chunk: int = DEFAULT_CHUNK
    still: InformationAccumulator | None = None
    raw: InformationAccumulator | None = None
    settings: SolveSettings = field(default_factory=SolveSettings)
    context: dict = field(default_factory=dict)
    post: list = field(default_factory=list)


# ------------------------------------------------------------------ checks
def resolve_base(robot: Robot, base, timings: dict) -> BaseParameters:
    """``base``, or the structural base of ``robot`` when None (timed in ``timings``)."""
    t0 = time.perf_counter()
    if base is None:
        base = analyze(robot).base
        timings["structural_analysis"] = time.perf_counter() - t0
    elif not isinstance(base, BaseParameters):
        raise InputError(f"base must be BaseParameters, got {type(base).__name__}")
    if len(base.names) != robot.n_parameters:
        raise InputError(
            f"base is for {len(base.names)} parameters but robot.n_parameters={robot.n_parameters}"
        )
    return base


def check_tau(robot: Robot, tau, n: int, name: str = "tau") -> np.ndarray:
    """``tau`` [N m or N] checked: shape (n, nv), finite, of a plausible magnitude."""
    tau = as_float_array(tau, name, ndim=2)
    if tau.shape != (n, robot.nv):
        raise InputError(
            f"{name}.shape={tau.shape} but expected ({n}, robot.nv={robot.nv}) to match the states"
        )
    check_finite(tau, name, robot.dof_names)
    check_magnitude(tau, name, robot.dof_names, kind="tau")  # |tau| <= 1e6, not all tiny
    return tau


def check_samples(robot: Robot, q, dq, ddq, tau, prefix: str = ""):
    """``(q, dq, ddq, tau)`` of N samples checked against ``robot`` (2-D arrays)."""
    batched, (q, dq, ddq) = check_states(robot, q=q, dq=dq, ddq=ddq)
    if not batched:
        raise InputError(
            f"{prefix}identification takes N samples (2-D arrays), got q.shape={q.shape}"
        )
    tau = check_tau(robot, tau, q.shape[0], prefix + "tau")
    return q, dq, ddq, tau


def check_equations(n_rows: int, r: int, what: str = "samples") -> None:
    """Raise unless ``n_rows`` equations are more than ``r`` unknowns."""
    if n_rows <= r:
        raise InputError(
            f"the {what} give {n_rows} equations for {r} base parameters: need more samples"
        )


def validation_blocks(robot: Robot, validation) -> list | None:
    """``validation = (q, dq, ddq, tau[, temp])`` checked as one validation block
    ``(q, dq, ddq, tau[, None, temp])``, or None."""
    if validation is None:
        return None
    try:
        vq, vdq, vddq, vtau, *rest = validation
        if len(rest) > 1:
            raise ValueError
    except (TypeError, ValueError) as exc:
        raise InputError("validation must be a tuple (q, dq, ddq, tau[, temp])") from exc
    block = check_samples(robot, vq, vdq, vddq, vtau, prefix="validation ")
    if not rest or rest[0] is None:
        return [block]
    return [(*block, None, check_temperature(robot, rest[0], block[1]))]


def block_temperature(block) -> np.ndarray | None:
    """The temperature of a block ``(q, dq, ddq, tau[, tau_raw[, temp]])``, or None."""
    return block[5] if len(block) > 5 else None


# ------------------------------------------------------------ accumulation
def row_supports(robot: Robot, columns, n_states: int = 16, seed: int = 12345) -> list[np.ndarray]:
    """Per joint, the positions in ``columns`` whose regressor entry is not identically zero.

    Evaluated at ``n_states`` random states within the limits: an entry that is
    a non-zero function of the state vanishes at random states with probability
    zero, while the structural zeros (bodies that are not in the joint's
    subtree, other joints' terms) are exact zeros in Pinocchio's regressor.
    Returns a list of ``nv`` sorted index arrays.
    """
    q, dq, ddq = robot.random_states(n_states, seed=seed)
    temp = robot.random_temperatures(n_states, seed)
    ev = robot.evaluator
    if ev.needs_history:  # a path state: the random states as one path
        chunks = ev.iter_regressor(q, dq, ddq, n_states, temp=temp)
        Y = np.concatenate([c.Y.copy() for c in chunks])
    else:
        Y = np.stack(
            [
                ev.regressor(q[k], dq[k], ddq[k], temp=None if temp is None else temp[k])
                for k in range(n_states)
            ]
        )
    nonzero = np.abs(Y[:, :, np.asarray(columns, dtype=np.intp)]).max(axis=0) > 0  # (nv, r)
    return [np.flatnonzero(row) for row in nonzero]


@dataclass
class RowSums:
    """The sums of some rows, split as the error figures need them.

    Attributes
    ----------
    fit : InformationAccumulator
        The rows the fit sees (with a velocity deadband: the moving rows only,
        ``|dq_j| >= eps_j``); ``fit.n`` counts every sample.
    still : InformationAccumulator or None
        With a deadband: the rows inside it, their Coulomb column ``sign(dq_j)`` set to
        zero (the model predicts them with the same deadband); ``still.n`` is 0.
    raw : InformationAccumulator or None
        Every row (as in ``fit`` and ``still``) against the raw, unfiltered torques,
        when the fit's torques were filtered and the raw ones were read again.
    timings : dict
        Seconds spent in the regressor and in the updates [s].
    """

    fit: InformationAccumulator
    still: InformationAccumulator | None = None
    raw: InformationAccumulator | None = None
    timings: dict = field(default_factory=dict)

    def __add__(self, other: RowSums) -> RowSums:
        def add(a, b):
            return None if a is None or b is None else a + b

        times = dict(self.timings)
        for k, v in other.timings.items():
            times[k] = times.get(k, 0.0) + v
        return RowSums(
            self.fit + other.fit, add(self.still, other.still), add(self.raw, other.raw), times
        )


def _coulomb_positions(robot: Robot, ind: np.ndarray, supports) -> list[int | None]:
    """Per joint, the position of its Coulomb column ``sign(dq_j)`` in its row support."""
    names = robot.parameter_names
    out: list[int | None] = []
    for j, dof in enumerate(robot.dof_names):
        key = f"{dof}.fc"
        pos = None
        if key in names:
            col = np.flatnonzero(ind == names.index(key))
            if col.size:
                hit = np.flatnonzero(supports[j] == col[0])
                pos = int(hit[0]) if hit.size else None
        out.append(pos)
    return out


class _Sums:
    """Per-joint sums on each joint's row support (lower triangles of A)."""

    def __init__(self, supports, nv: int):
        self.A = [np.zeros((sj.size, sj.size)) for sj in supports]
        self.b = [np.zeros(sj.size) for sj in supports]
        self.zz = np.zeros(nv)

    def add(self, j: int, rows: np.ndarray, tau_j: np.ndarray, gram: bool = True) -> None:
        if gram:  # lower triangle of A[j] (C order) == upper of its Fortran view
            dsyrk(1.0, rows.T, beta=1.0, c=self.A[j].T, trans=0, lower=0, overwrite_c=1)
        self.b[j] += tau_j @ rows
        self.zz[j] += tau_j @ tau_j

    def accumulator(self, r: int, nv: int, n: int, supports, A=None) -> InformationAccumulator:
        return InformationAccumulator(r, nv).add_sums(
            self.A if A is None else A, self.b, self.zz, n, supports
        )


def accumulate_rows(
    robot: Robot,
    blocks,
    ind: np.ndarray,
    chunk: int,
    *,
    deadband: np.ndarray | None = None,
    progress=None,
    total: int = 0,
    record: ScoreBlocks | None = None,
) -> RowSums:
    """Accumulate the base-column information of blocks ``(q, dq, ddq, tau[, tau_raw[,
    temp]])`` (``tau_raw`` may be None; ``temp`` the temperature of the ``temperature`` law,
    (N, nv) or (N, 1), :func:`~manip_id.robot.regressor.check_temperature`).

    Row ``j`` of the regressor is accumulated on its non-zero columns only
    (:func:`row_supports`): in a serial chain that about halves the work of the
    symmetric rank-k updates. ``deadband`` (nv,) [rad/s or m/s]: the rows of joint ``j``
    of samples with ``|dq_j| < deadband_j`` are left out of the fit (standstill, where
    the Coulomb column sign(dq_j) is noise) and summed apart with that column zero
    (:class:`RowSums`); a block's fifth array, the raw torques (N, nv) [N m], is summed
    against every row for the raw-torque errors. Each block is checked. ``record``: an
    empty :class:`~manip_id.estimators.blocks.ScoreBlocks` that also gets the fit's rows
    per block of contiguous samples (for the covariance of correlated residuals); it
    becomes the fit's ``blocks``.
    """
    ev, nv, r = robot.evaluator, robot.nv, len(ind)
    supports = row_supports(robot, ind)
    blocks = ev.sequential(blocks)  # one trajectory: the hysteresis state carries
    fc = _coulomb_positions(robot, np.asarray(ind), supports)
    fit, still, raw = _Sums(supports, nv), _Sums(supports, nv), _Sums(supports, nv)
    t_reg = t_acc = 0.0
    done, with_raw = 0, None
    for block in blocks:
        if not isinstance(block, (tuple, list)) or len(block) not in (4, 5, 6):
            raise InputError("each data block must be a tuple (q, dq, ddq, tau)")
        has_raw = len(block) > 4 and block[4] is not None
        with_raw = has_raw if with_raw is None else with_raw
        prefix = f"block at sample {done}: "
        q, dq, ddq, tau = block[0], block[1], block[2], block[3]
        bq, bdq, bddq, btau = check_samples(robot, q, dq, ddq, tau, prefix=prefix)
        braw = check_tau(robot, block[4], bq.shape[0], "tau_raw") if with_raw else None
        btemp = check_temperature(robot, block[5], bdq) if len(block) > 5 else None
        t0 = time.perf_counter()
        for start, stop, rows in ev.iter_row_supports(bq, bdq, bddq, ind, supports, chunk, btemp):
            t1 = time.perf_counter()
            t_reg += t1 - t0
            tau = btau[start:stop]
            keep = None if deadband is None else np.abs(bdq[start:stop]) >= deadband
            if record is not None:
                record.add_rows(rows, tau, supports, keep)
            for j in range(nv):
                rj, tj = rows[j], tau[:, j]
                rawj = None if braw is None else braw[start:stop, j]
                if keep is not None:  # the moving rows to the fit, the others apart
                    k = keep[:, j]
                    rs = rj[~k].copy()
                    if fc[j] is not None:
                        rs[:, fc[j]] = 0.0  # the deadband's prediction: no sign term
                    still.add(j, rs, tj[~k])
                    if rawj is not None:
                        raw.add(j, rs, rawj[~k], gram=False)
                    rj, tj = rj[k], tj[k]
                    rawj = None if rawj is None else rawj[k]
                fit.add(j, rj, tj)
                if rawj is not None:
                    raw.add(j, rj, rawj, gram=False)
            t0 = time.perf_counter()
            t_acc += t0 - t1
            if progress is not None:
                progress(done + stop, total)
        done += bq.shape[0]
    out = RowSums(fit.accumulator(r, nv, done, supports))
    if record is not None:
        out.fit.attach_blocks(record)
    if deadband is not None:
        out.still = still.accumulator(r, nv, 0, supports)
    if with_raw:
        gram = [a + b for a, b in zip(fit.A, still.A, strict=True)]
        out.raw = raw.accumulator(r, nv, done, supports, A=gram)
    out.timings = {"regressor": t_reg, "accumulate": t_acc}
    return out


def accumulate_blocks(
    robot: Robot,
    blocks,
    ind: np.ndarray,
    chunk: int,
    progress=None,
    total: int = 0,
    record: ScoreBlocks | None = None,
) -> tuple[InformationAccumulator, dict[str, float]]:
    """The fit's sums of blocks ``(q, dq, ddq, tau)`` (:func:`accumulate_rows` without a
    deadband, ``record`` the same) and the seconds spent."""
    sums = accumulate_rows(robot, blocks, ind, chunk, progress=progress, total=total, record=record)
    return sums.fit, sums.timings


def _part_accumulate(robot: Robot, func, args, ind, chunk: int, record=None):
    """One part ``(func, args)``: the blocks ``func(*args)`` accumulated (a task)."""
    return accumulate_blocks(robot, func(*args), ind, chunk, record=record)


def accumulate_forked(
    robot: Robot, parts, ind, chunk: int, workers: int, progress=None, records=None
):
    """Accumulate ``parts`` (each ``(func, args)`` with ``func(*args)`` yielding blocks) in
    ``workers`` forked processes; the accumulators merge by addition in part order.
    ``records``: per part an empty :class:`~manip_id.estimators.blocks.ScoreBlocks` (of
    the part's stream and offset) or None. Returns the sums and the seconds summed over
    the parts."""
    parts = list(parts)
    records = [None] * len(parts) if records is None else list(records)

    def report(k: int, _value) -> None:
        if progress is not None:
            progress(k + 1, len(parts))

    with ForkBackend(workers) as backend:
        results = backend.map(
            _part_accumulate,
            [
                (robot, func, args, ind, chunk, rec)
                for (func, args), rec in zip(parts, records, strict=True)
            ],
            on_result=report,
        )
    acc = results[0][0].copy()
    for other, _ in results[1:]:
        acc.merge(other)
    times = {
        "regressor": sum(t["regressor"] for _, t in results),
        "accumulate": sum(t["accumulate"] for _, t in results),
    }
    return acc, times


def array_part(q, dq, ddq, tau, start: int, stop: int, temp=None):
    """The one block of samples ``start:stop`` (the arrays reach forked workers by fork);
    ``temp`` the temperature (N, nv) of the temperature law, or None."""
    s = slice(start, stop)
    if temp is None:
        yield q[s], dq[s], ddq[s], tau[s]
    else:
        yield q[s], dq[s], ddq[s], tau[s], None, temp[s]


def path_part(robot: Robot, q, dq, ddq, tau, start: int, stop: int, temp=None):
    """:func:`array_part`, the robot's hysteresis state first run over the samples before
    ``start`` (:meth:`~manip_id.robot.regressor.RegressorEvaluator.advance`): the part's path
    starts where the serial pass has it."""
    robot.evaluator.advance(q[:start])
    yield from array_part(q, dq, ddq, tau, start, stop, temp)


def accumulate_arrays(
    robot: Robot,
    q,
    dq,
    ddq,
    tau,
    ind,
    *,
    run: RunOptions,
    uncertainty: UncertaintyOptions | None = None,
    temp=None,
):
    """The samples' information: in this process, or in ``run.workers_for(n)`` contiguous
    parts in forked processes merged by addition (equal to the serial sums to round-off,
    the per-block sums of ``uncertainty`` too); ``temp`` the checked temperature (N, nv)."""
    n = q.shape[0]
    unc = UncertaintyOptions.from_value(uncertainty)
    with planned_samples(n):
        arrays = (q, dq, ddq, tau, temp)
        return _accumulate_arrays(robot, arrays, ind, run, run.workers_for(n), unc)


def _accumulate_arrays(robot: Robot, arrays, ind, run: RunOptions, workers: int, unc):
    q, dq, ddq, tau, temp = arrays
    n, chunk, progress = q.shape[0], run.chunk, run.progress
    r, nv = len(ind), robot.nv
    if workers > 1 and n >= 2 * workers:
        t0 = time.perf_counter()
        cuts = np.linspace(0, n, workers + 1).astype(int)
        parts = [
            (path_part, (robot, q, dq, ddq, tau, int(a), int(b), temp))
            for a, b in zip(cuts[:-1], cuts[1:], strict=True)
        ]
        records = [unc.blocks(r, nv, offset=int(a)) for a in cuts[:-1]]
        acc, times = accumulate_forked(robot, parts, ind, chunk, workers, records=records)
        times["accumulate_wall"] = time.perf_counter() - t0
        return acc, times
    record = unc.blocks(r, nv)
    block = next(array_part(q, dq, ddq, tau, 0, n, temp))
    return accumulate_blocks(robot, [block], ind, chunk, progress=progress, total=n, record=record)


__all__ = [
    "FileRecord",
    "FileSums",
    "OnlineRun",
    "RowSums",
    "Problem",
    "accumulate_arrays",
    "accumulate_blocks",
    "accumulate_forked",
    "accumulate_rows",
    "array_part",
    "block_temperature",
    "check_equations",
    "check_samples",
    "check_tau",
    "resolve_base",
    "row_supports",
    "validation_blocks",
]
