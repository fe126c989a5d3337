"""Entry points: :func:`analyze` (the one to reach for) and the specialised analyses.

``analyze(robot)`` is structural; ``analyze(Y, robot=robot)``, ``analyze(dataset,
robot=robot)`` are what the data excite. The specialised ones:
:func:`structural_analysis`, :func:`analyze_trajectory` (streamed states),
:func:`analyze_information` (an accumulated ``Y^T Y``), :func:`analyze_dataset`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .._checks import as_float_array, as_int, as_real
from ..errors import InputError
from ..resources import FLOAT, check_memory, check_regressor_buffer
from ..robot.model import Robot
from ..robot.regressor import iter_regressor
from .accumulator import RFactorAccumulator
from .notes import robot_notes, zero_columns
from .qr import EPS, analyze_factor, default_tolerance
from .results import RankAnalysis

#: States drawn for a structural analysis: at least this many ...
MIN_SAMPLES = 100
#: ... and at least this many stacked rows per parameter.
ROWS_PER_PARAMETER = 20
_CHUNK = 256


def _check_names(names, p: int) -> list[str]:
    if names is None:
        raise InputError("give the parameter names (names=...) or the robot (robot=...)")
    names = [str(n) for n in names]
    if len(names) != p:
        raise InputError(f"the regressor has {p} columns but {len(names)} names were given")
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise InputError(f"parameter names must be unique; {dup!r} repeats")
    return names


def _check_tolerance(tolerance) -> float | None:
    if tolerance is None:
        return None
    tol = as_real(tolerance, "tolerance")
    if not (math.isfinite(tol) and 0.0 < tol < 1.0):
        raise InputError(f"tolerance must be a relative value in (0, 1), got {tolerance}")
    return tol


def _check_rows(n_rows: int, p: int) -> None:
    if n_rows == 0:
        raise InputError("the regressor is empty (0 rows)")
    if n_rows < p:
        raise InputError(
            f"fewer rows than parameters: {n_rows} rows for {p} parameters; "
            f"a rank analysis needs at least {p} rows (more samples)"
        )


def structural_analysis(
    robot, *, seed: int = 0, n_samples: int | None = None, tolerance: float | None = None
) -> RankAnalysis:
    """What no data of this robot can identify: Y stacked over random states within the limits.

    ``n_samples`` defaults to ``max(MIN_SAMPLES, ceil(ROWS_PER_PARAMETER * p / nv))`` states
    from ``robot.random_states(n_samples, seed)``, streamed through
    :func:`manip_id.robot.regressor.iter_regressor` into a (p, p) factor.
    """
    p, nv = robot.n_parameters, robot.nv
    if n_samples is None:
        n_samples = max(MIN_SAMPLES, math.ceil(ROWS_PER_PARAMETER * p / nv))
    n_samples = as_int(n_samples, "n_samples", minimum=1)
    if n_samples * nv < p:
        raise InputError(
            f"n_samples={n_samples} gives {n_samples * nv} rows for {p} parameters; "
            f"need at least {math.ceil(p / nv)} samples"
        )
    tol = _check_tolerance(tolerance)
    check_regressor_buffer(min(_CHUNK, n_samples), nv, p)  # before the states are drawn
    check_memory(  # q, dq, ddq and their draws (about twice)
        2 * FLOAT * n_samples * (robot.nq + 2 * nv),
        f"{n_samples:.3g} random states of {nv} joints need",
        "ask for fewer --samples",
    )
    q, dq, ddq = robot.random_states(n_samples, seed)
    acc = RFactorAccumulator(p, robot.parameter_names)
    temp = robot.random_temperatures(n_samples, seed)  # the temperature law's, or None
    for chunk in iter_regressor(robot, q, dq, ddq, chunk=_CHUNK, temp=temp):
        acc.add(chunk.Y)
    tol = tol if tol is not None else default_tolerance(acc.n_rows, p)
    zero = zero_columns(acc.R, tol)
    return analyze_factor(
        acc.R,
        robot.parameter_names,
        acc.n_rows,
        tol,
        notes=robot_notes(robot, zero),
        source=f"{robot.name} (structural: {n_samples} random states, seed {seed})",
    )


def analyze(
    source,
    *,
    names: Sequence[str] | None = None,
    robot=None,
    structural: RankAnalysis | None = None,
    seed: int = 0,
    n_samples: int | None = None,
    tolerance: float | None = None,
) -> RankAnalysis:
    """Rank analysis of a robot (structural), of a regressor or of a dataset (what data excite).

    The entry point of the package; the specialised functions it dispatches to are
    :func:`structural_analysis` and :func:`analyze_dataset`.

    Parameters
    ----------
    source
        a :class:`~manip_id.robot.model.Robot` (structural analysis, see
        :func:`structural_analysis`; ``seed`` and ``n_samples`` apply), a
        regressor ``Y`` of shape (M, p) or (N, nv, p) (sample-major), or a
        :class:`~manip_id.datasets.Dataset` with accelerations (``robot`` required).
    names
        parameter names, length p (for an array; taken from ``robot`` when given).
    robot
        the robot the array belongs to; then the structural analysis is run too
        (unless ``structural`` is given) and the unexcited directions are reported.
    structural
        a structural :class:`RankAnalysis` to compare the data with.
    tolerance
        relative rank tolerance (module docstring); default
        :func:`default_tolerance`, ``max(max(M, p) * eps, 1e-8)``.

    Returns
    -------
    :class:`RankAnalysis`. A regressor with NaN/Inf, no rows, fewer rows than
    columns, all zeros, or a width other than ``len(names)`` raises :class:`InputError`.
    """
    if isinstance(source, Robot):
        return structural_analysis(source, seed=seed, n_samples=n_samples, tolerance=tolerance)
    if hasattr(source, "q") and hasattr(source, "dq"):  # a Dataset (duck-typed: no import)
        if robot is None:
            raise InputError("analyze(dataset) needs the robot: analyze(dataset, robot=robot)")
        return analyze_dataset(robot, source, structural=structural, tolerance=tolerance)
    Y = as_float_array(source, "Y", ndim=(2, 3))
    p = Y.shape[-1]
    if robot is not None:
        if names is None:
            names = robot.parameter_names
        if p != robot.n_parameters:
            raise InputError(f"Y.shape={Y.shape} but robot.n_parameters={robot.n_parameters}")
    names = _check_names(names, p)
    tol = _check_tolerance(tolerance)
    acc = RFactorAccumulator(p, names)
    step = max(1, (64 * 1024) // max(p * (Y.shape[1] if Y.ndim == 3 else 1), 1))
    for start in range(0, Y.shape[0], step):
        acc.add(Y[start : start + step])
    _check_rows(acc.n_rows, p)
    if robot is not None and structural is None:
        structural = structural_analysis(robot, seed=seed)
    tol = tol if tol is not None else default_tolerance(acc.n_rows, p)
    what = f"{robot.name} data" if robot is not None else "a regressor"
    return analyze_factor(
        acc.R,
        names,
        acc.n_rows,
        tol,
        structural=structural,
        source=f"{what} ({acc.n_rows} rows x {p} columns)",
    )


def analyze_trajectory(
    robot,
    q,
    dq,
    ddq,
    *,
    structural: RankAnalysis | None = None,
    tolerance: float | None = None,
    chunk: int = _CHUNK,
) -> RankAnalysis:
    """What a trajectory excites, streamed: Y(q, dq, ddq) is never stacked.

    ``q`` (N, nq) [rad or m], ``dq``, ``ddq`` (N, nv); the structural analysis
    of ``robot`` is computed when not given, and the unexcited directions reported.
    """
    tol = _check_tolerance(tolerance)
    acc = RFactorAccumulator(robot.n_parameters, robot.parameter_names)
    for c in iter_regressor(robot, q, dq, ddq, chunk=chunk):
        acc.add(c.Y)
    _check_rows(acc.n_rows, robot.n_parameters)
    if structural is None:
        structural = structural_analysis(robot)
    tol = tol if tol is not None else default_tolerance(acc.n_rows, robot.n_parameters)
    n = acc.n_rows // robot.nv
    return analyze_factor(
        acc.R,
        robot.parameter_names,
        acc.n_rows,
        tol,
        structural=structural,
        source=f"{robot.name} trajectory ({n} samples, {acc.n_rows} rows)",
    )


def analyze_information(
    A,
    names: Sequence[str],
    *,
    n_rows: int,
    structural: RankAnalysis | None = None,
    tolerance: float | None = None,
) -> RankAnalysis:
    """Rank analysis from an accumulated information matrix ``A = Y^T Y``, shape (p, p).

    ``n_rows`` is the number of stacked rows M that built ``A``. The factor
    ``R = diag(sqrt(w)) V^T`` of the eigendecomposition ``A = V diag(w) V^T``
    of the column-scaled ``A`` (then unscaled) has the same Gram matrix, so the
    analysis is the one of ``Y``, up to the round-off of forming ``A``: hence the
    default tolerance ``p * sqrt(eps)``.
    With ``structural``, the directions these data fail to excite although they
    are structurally identifiable are reported in ``unexcited``, and
    ``information_eigenvalues`` are those of ``A`` on the structural base columns.
    """
    A = as_float_array(A, "A", ndim=2)
    if A.shape[0] != A.shape[1]:
        raise InputError(f"an information matrix is square (p, p), got A.shape={A.shape}")
    p = A.shape[0]
    names = _check_names(names, p)
    if not np.isfinite(A).all():
        i, j = np.argwhere(~np.isfinite(A))[0]
        raise InputError(f"A holds {A[i, j]} at ({names[i]}, {names[j]})")
    scale = float(np.abs(A).max()) if A.size else 0.0
    if not np.allclose(A, A.T, rtol=1e-10, atol=1e-12 * scale):
        raise InputError("A must be symmetric (an information matrix Y^T Y)")
    _check_rows(int(n_rows), p)
    tol = _check_tolerance(tolerance)
    tol = tol if tol is not None else p * math.sqrt(EPS)
    d = np.sqrt(np.clip(np.diag(A), 0.0, None))  # column norms of Y
    if np.any(np.diag(A) < 0):
        raise InputError("A has a negative diagonal entry: not an information matrix Y^T Y")
    safe = np.where(d > 0, d, 1.0)
    As = A / safe[:, None] / safe[None, :]
    w, V = np.linalg.eigh(0.5 * (As + As.T))
    if w.size and w[0] < -tol * max(w[-1], 0.0):
        raise InputError(
            f"A is not positive semi-definite (smallest scaled eigenvalue "
            f"{w[0]:.3g}): not an information matrix Y^T Y"
        )
    R = (np.sqrt(np.clip(w, 0.0, None))[:, None] * V.T) * safe[None, :]
    return analyze_factor(
        R,
        names,
        int(n_rows),
        tol,
        structural=structural,
        source=f"an information matrix ({n_rows} rows x {p} columns)",
    )


def analyze_dataset(robot, dataset, *, ddq=None, structural=None, tolerance=None) -> RankAnalysis:
    """What a measured dataset excites (``dataset.q``, ``dq``, and ``ddq`` or the given ``ddq``)."""
    acc_arr = dataset.ddq if ddq is None else ddq
    if acc_arr is None:
        raise InputError(
            "the dataset has no accelerations (ddq): estimate them first "
            "(manip_id.signals) or pass ddq="
        )
    out = analyze_trajectory(
        robot, dataset.q, dataset.dq, acc_arr, structural=structural, tolerance=tolerance
    )
    return out
