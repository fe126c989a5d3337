"""The energy model over intervals (see the package docstring for the math).

One scalar row per window ``[t_a, t_b]`` of ``w`` sampling intervals (``w`` even)::

    z = int_{t_a}^{t_b} tau^T dq dt                               [J]
    E = h(t_b) - h(t_a) + int_{t_a}^{t_b} dq^T Y_joint(q, dq, 0) dt   (p,)

``h`` holds Pinocchio's kinetic and potential energy regressors and the
armature's kinetic energy ``1/2 dq^T (Y_joint(q, 0, dq) - Y_joint(q, 0, 0))``;
the integral is the power of the friction, offset and spring columns. The
integrals use the composite Simpson rule on uniform samples.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .._checks import as_float_array
from ..errors import InputError
from ..estimators import InformationAccumulator
from ..estimators.blocks import ScoreBlocks
from ..identifiability import analyze
from ..robot.model import Robot
from ..robot.regressor import check_states, iter_regressor
from ..trajectories import random_trajectory, trajectory_to_configuration

#: Default window (energy) and row spacing (momentum) [s].
DEFAULT_WINDOW = 0.2
_CHUNK_SAMPLES = 4096


def window_samples(window_length: float | None, dt: float, *, even: bool = True) -> int:
    """Sampling intervals per window: ``round(window_length / dt)``, rounded up to even.

    ``window_length`` [s] (default :data:`DEFAULT_WINDOW`), ``dt`` [s] the sample time.
    """
    dt = float(dt)
    if not (math.isfinite(dt) and dt > 0):
        raise InputError(f"dt must be a positive sample time [s], got {dt}")
    T = DEFAULT_WINDOW if window_length is None else float(window_length)
    if not (math.isfinite(T) and T > 0):
        raise InputError(f"window_length must be a positive time [s], got {window_length}")
    w = max(int(round(T / dt)), 2 if even else 1)
    if even and w % 2:
        w += 1
    return w


def _simpson_weights(w: int, dt: float) -> np.ndarray:
    """Composite Simpson weights on ``w + 1`` points (``w`` even), shape (w + 1,)."""
    c = np.ones(w + 1)
    c[1:-1:2] = 4.0
    c[2:-1:2] = 2.0
    return c * (dt / 3.0)


def check_model_states(robot: Robot, q, dq, tau):
    """``(q, dq, tau)`` of N samples checked for the acceleration-free models."""
    robot.evaluator.refuse_load("the energy and momentum models")
    robot.evaluator.refuse_temperature("the energy and momentum models")
    batched, (q, dq) = check_states(robot, q=q, dq=dq)
    if not batched:
        raise InputError(f"the energy model takes N samples (2-D arrays), got q.shape={q.shape}")
    tau = as_float_array(tau, "tau", ndim=2)
    if tau.shape != dq.shape:
        raise InputError(f"tau.shape={tau.shape} but dq.shape={dq.shape}")
    if not np.isfinite(tau).all():
        k = int(np.argwhere(~np.isfinite(tau))[0, 0])
        raise InputError(f"tau holds NaN or Inf at sample {k}")
    return q, dq, tau


def _energy_at(robot: Robot, ev, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """h(q, dq) at n samples, shape (n, p): rigid energies and the armature's kinetic energy."""
    m, d = robot.model, robot.model.createData()
    n = q.shape[0]
    out = np.zeros((n, robot.n_parameters))
    nr = robot.n_rigid
    for k in range(n):
        out[k, :nr] = pin.computeKineticEnergyRegressor(m, d, q[k], dq[k])
        out[k, :nr] += pin.computePotentialEnergyRegressor(m, d, q[k])
    if robot.terms.armature:
        Ya = np.zeros((n, robot.nv, robot.n_parameters))
        Y0 = np.zeros_like(Ya)
        zero = np.zeros_like(dq)
        ev.fill_joint_terms(Ya, q, zero, dq)
        ev.fill_joint_terms(Y0, q, zero, zero)
        out += 0.5 * np.einsum("nj,njp->np", dq, Ya - Y0)  # [J per unit parameter]
    return out


def energy_rows(
    robot: Robot,
    q,
    dq,
    tau,
    *,
    dt: float,
    window_length: float | None = None,
    chunk: int | None = None,
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Energy-model rows, in chunks of windows: ``(E (n_w, p), z (n_w,))``.

    Parameters
    ----------
    robot
        the robot (its joint terms decide the columns)
    q
        positions [rad or m], shape (N, nq); dq [rad/s or m/s] and tau [N m or N], (N, nv)
    dt
        sample time [s] (uniform sampling)
    window_length
        window [s] (default :data:`DEFAULT_WINDOW`), rounded to an even
        number of sampling intervals ``w``; windows ``[k w, (k + 1) w]`` follow each
        other, ``floor((N - 1) / w)`` of them
    chunk
        windows per yielded block (default: about 4096 samples' worth)
    """
    q, dq, tau = check_model_states(robot, q, dq, tau)
    w = window_samples(window_length, dt)
    n = q.shape[0]
    n_win = (n - 1) // w
    if n_win < 1:
        raise InputError(
            f"{n} samples hold no window of {w} intervals ({w * float(dt):g} s): "
            "shorten window_length or give more samples"
        )
    ev = robot.evaluator
    wts = _simpson_weights(w, float(dt))
    p = robot.n_parameters
    step = max(1, _CHUNK_SAMPLES // w) if chunk is None else int(chunk)
    if step < 1:
        raise InputError(f"chunk must be a positive number of windows, got {chunk}")
    for c0 in range(0, n_win, step):
        c1 = min(c0 + step, n_win)
        s0, s1 = c0 * w, c1 * w + 1  # samples covered
        qs, dqs, taus = q[s0:s1], dq[s0:s1], tau[s0:s1]
        ends = np.arange(0, s1 - s0, w)  # window boundaries, (c1 - c0 + 1,)
        h = _energy_at(robot, ev, qs[ends], dqs[ends])  # (nw + 1, p)
        E = h[1:] - h[:-1]
        power = np.einsum("nj,nj->n", taus, dqs)  # [W]
        Yj = np.zeros((s1 - s0, robot.nv, p))
        ev.fill_joint_terms(Yj, qs, dqs, np.zeros_like(dqs))
        rate = np.einsum("nj,njp->np", dqs, Yj)  # joint-term power per unit parameter
        nw = c1 - c0
        idx = np.arange(nw)[:, None] * w + np.arange(w + 1)[None, :]  # (nw, w + 1)
        z = (power[idx] * wts).sum(axis=1)  # [J]
        E += np.einsum("wk,wkp->wp", np.broadcast_to(wts, idx.shape), rate[idx])
        yield E, z


def accumulate_energy(
    robot: Robot,
    q,
    dq,
    tau,
    *,
    dt: float,
    window_length: float | None = None,
    columns=None,
    blocks: ScoreBlocks | None = None,
) -> InformationAccumulator:
    """The energy rows' information on ``columns`` (default all), one output (``nv = 1``);
    with ``blocks`` (empty, of ``nv = 1``) also per block of consecutive windows."""
    cols = np.arange(robot.n_parameters) if columns is None else np.asarray(columns, np.intp)
    acc = InformationAccumulator(cols.size, 1, blocks=False if blocks is None else blocks)
    for E, z in energy_rows(robot, q, dq, tau, dt=dt, window_length=window_length):
        acc.add(E[:, None, :], z[:, None], columns=cols, check=False)
    return acc


@dataclass(frozen=True)
class EnergyBaseCheck:
    """Whether the energy model identifies the dynamic model's base parameters.

    Attributes
    ----------
    robot_name
        the robot
    n_base_dynamic
        number of base parameters of the dynamic model (structural)
    rank_dynamic
        rank of the dynamic regressor on the check trajectory
    rank_energy
        rank of the energy regressor on the same trajectory's windows
    rank_on_base_columns
        rank of the energy regressor restricted to the dynamic
        model's independent columns (== n_base_dynamic when they are identifiable)
    regrouping_residual
        ``max |E_dep - E_ind K| / max |E|`` with the dynamic K
        (0 up to round-off when the regrouping is the same)
    same
        the energy regressor has full rank on the dynamic model's independent
        columns and the same regrouping (``rank_on_base_columns == n_base_dynamic``
        and a residual below 1e-8): the same base parameters. The two trajectory
        ranks are for information: at ``tolerance`` they may count a direction the
        structural analysis calls unidentifiable (singular values near 1e-9).
    """

    robot_name: str
    n_base_dynamic: int
    rank_dynamic: int
    rank_energy: int
    rank_on_base_columns: int
    regrouping_residual: float
    same: bool


def _rank(X: np.ndarray, tolerance: float) -> int:
    """Rank of the column-scaled ``X`` (zero columns dropped), relative tolerance."""
    nrm = np.linalg.norm(X, axis=0)
    keep = nrm > 0
    if not keep.any():
        return 0
    s = np.linalg.svd(X[:, keep] / nrm[keep], compute_uv=False)
    return int(np.sum(s > tolerance * s[0]))


def check_energy_base(
    robot: Robot,
    base=None,
    *,
    seed: int = 0,
    harmonics: int | None = None,
    wf: float = 0.1,
    rate: float = 50.0,
    window_length: float = 0.04,
    tolerance: float = 1e-8,
) -> EnergyBaseCheck:
    """Rank and regrouping of the energy regressor against the dynamic base parameters.

    Along one period of a random Fourier trajectory within the limits
    (:func:`manip_id.trajectories.random_trajectory` with ``harmonics``, default
    ``max(10, nv)``, and fundamental ``wf`` [rad/s], sampled at ``rate`` [Hz]), the
    energy rows (windows
    of ``window_length`` [s]) and the dynamic regressor are compared with the
    structural base of the dynamic model (``base``, default ``analyze(robot).base``).
    Ranks are those of the column-scaled regressors with relative ``tolerance``.
    The trajectory must be rich: the energy model sees only the power ``dq^T tau``,
    one scalar per instant, and a few harmonics leave some of its directions
    unexcited where the dynamic model's are not (e.g. 3 harmonics on the Panda).
    """
    if base is None:
        base = analyze(robot).base
    if harmonics is None:
        harmonics = max(10, robot.nv)
    traj = random_trajectory(robot, harmonics=harmonics, wf=wf, seed=seed)
    t = np.arange(int(2 * math.pi / wf * rate) + 1) / rate
    angles, dqs, ddqs = traj.sample(t)
    qs = trajectory_to_configuration(robot, angles)
    rows = energy_rows(
        robot, qs, dqs, np.zeros_like(dqs), dt=1.0 / rate, window_length=window_length
    )
    E = np.concatenate([e for e, _ in rows])
    Y = np.concatenate(
        [c.Y.reshape(-1, robot.n_parameters) for c in iter_regressor(robot, qs, dqs, ddqs)]
    )
    r_energy = _rank(E, tolerance)
    r_dyn = _rank(Y, tolerance)
    r_cols = _rank(E[:, base.independent], tolerance)
    scale = max(float(np.abs(E).max()), 1e-300)
    resid = float(np.abs(E[:, base.dependent] - E[:, base.independent] @ base.K).max()) / scale
    n = base.n_base
    same = r_cols == n and resid < 1e-8
    return EnergyBaseCheck(robot.name, n, r_dyn, r_energy, r_cols, resid, same)
