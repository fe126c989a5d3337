"""Streaming least squares: the information accumulated over chunks of samples.

For a vector output ``tau_k = Y_k theta + e_k`` (``Y_k`` of shape (nv, p)) the
least-squares problem over N samples only needs, per joint ``j``::

    A_j  = sum_k Y_kj^T Y_kj     (p, p)     information matrix
    b_j  = sum_k Y_kj^T tau_kj   (p,)
    zz_j = sum_k tau_kj^2        scalar
    n    = N                     number of samples

where ``Y_kj`` is row ``j`` of ``Y_k``. Keeping the joints apart costs
O(nv p^2) memory and lets weighted least squares re-weight joints without a
second pass over the data. Accumulators of disjoint data merge by addition.

Optionally (``blocks=True``) the same sums are also kept per block of contiguous
samples (:class:`~manip_id.estimators.blocks.ScoreBlocks`, memory bounded), for the
covariance that holds for correlated residuals
(:mod:`manip_id.estimators.uncertainty`); the totals are accumulated exactly as
without blocks, so the estimate does not depend on whether blocks are recorded.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.blas import dsyrk

from .._checks import as_float_array
from ..errors import InputError
from .blocks import ScoreBlocks, add_joint_sums


class InformationAccumulator:
    """Per-joint sums ``A_j``, ``b_j``, ``zz_j`` and the sample count ``n``.

    Parameters
    ----------
    p : int
        Number of parameters (columns accumulated).
    nv : int
        Number of outputs per sample (joints).
    blocks : bool or ScoreBlocks
        Also record the sums per block of contiguous samples (:attr:`blocks`): True
        for the default :class:`~manip_id.estimators.blocks.ScoreBlocks`, or an empty
        one of given settings (e.g. the stream and offset of a part of a record).

    ``add(Y, tau)`` takes Y of shape (n, nv, P) and tau of shape (n, nv); with
    ``columns`` (P >= p) only those columns of Y are accumulated (e.g. the
    independent columns of a base regressor). The hot loop is one BLAS
    ``dsyrk`` per joint on a contiguous block, updating the lower triangle in
    place; :attr:`A_joint` returns the symmetrized matrices.
    """

    def __init__(
        self,
        p: int,
        nv: int,
        *,
        blocks: bool | ScoreBlocks = False,
    ):
        p, nv = int(p), int(nv)
        if p < 1 or nv < 1:
            raise InputError(f"an accumulator needs p >= 1 and nv >= 1, got p={p}, nv={nv}")
        self.p = p
        self.nv = nv
        self._A = np.zeros((nv, p, p))  # lower triangles (C order) are up to date
        self._b = np.zeros((nv, p))
        self._zz = np.zeros(nv)
        self.n = 0
        #: The per-block sums (None when not recorded, or after merging data without them).
        self.blocks: ScoreBlocks | None = None
        if isinstance(blocks, ScoreBlocks):
            if (blocks.p, blocks.nv, blocks.n_blocks) != (p, nv, 0):
                raise InputError(
                    f"blocks must be empty ScoreBlocks of p={p}, nv={nv}; got {blocks!r}"
                )
            self.blocks = blocks
        elif blocks:
            self.blocks = ScoreBlocks(p, nv)

    # ------------------------------------------------------------- adding
    def add(self, Y, tau, *, columns=None, check: bool = True) -> InformationAccumulator:
        """Accumulate samples: Y of shape (n, nv, P), tau of shape (n, nv) [N m or N].

        A scalar output (nv = 1) also takes Y of shape (n, P) and tau of shape (n,).
        ``columns``: indices of the columns of Y to accumulate (``len == p``);
        default all (then P must equal p). ``check=False`` skips the NaN/Inf
        scan (for callers that have already validated their inputs).
        Returns ``self``.
        """
        Y = np.asarray(Y, dtype=np.float64)
        tau = np.asarray(tau, dtype=np.float64)
        if Y.ndim == 2 and self.nv == 1 and tau.ndim == 1:  # scalar output: phi rows
            Y, tau = Y[:, None, :], tau[:, None]
        if Y.ndim != 3 or Y.shape[1] != self.nv:
            raise InputError(f"Y.shape={Y.shape} but expected (n, nv={self.nv}, columns)")
        n = Y.shape[0]
        if tau.shape != (n, self.nv):
            raise InputError(
                f"Y.shape={Y.shape} but tau.shape={tau.shape}; expected tau of "
                f"shape ({n}, {self.nv})"
            )
        if columns is None:
            if Y.shape[2] != self.p:
                raise InputError(f"Y.shape={Y.shape} but the accumulator has p={self.p} columns")
            Yt = np.ascontiguousarray(Y.transpose(1, 0, 2))
        else:
            columns = np.asarray(columns, dtype=np.intp)
            if columns.shape != (self.p,):
                raise InputError(
                    f"columns.shape={columns.shape} but the accumulator has p={self.p}"
                )
            if columns.size and (columns.max() >= Y.shape[2] or columns.min() < -Y.shape[2]):
                raise InputError(f"Y.shape={Y.shape} has no column {int(columns.max())}")
            Yt = np.take(Y.transpose(1, 0, 2), columns, axis=2)  # one copy, C order
        if check:
            check_finite_rows(Yt, "Y", self.n)
            check_finite_rows(tau.T, "tau", self.n)
        if n == 0:
            return self
        for j in range(self.nv):
            # C = Yj^T Yj + C on the upper triangle of the Fortran view == lower triangle here
            dsyrk(1.0, Yt[j].T, beta=1.0, c=self._A[j].T, trans=0, lower=0, overwrite_c=1)
            self._b[j] += tau[:, j] @ Yt[j]
        self._zz += np.einsum("nj,nj->j", tau, tau)
        self.n += n
        if self.blocks is not None:
            self.blocks.add(Yt, tau)
        return self

    def add_sums(self, A_joint, b_joint, zz_joint, n: int, supports=None) -> InformationAccumulator:
        """Add per-joint sums computed elsewhere (e.g. on each joint's non-zero columns).

        ``A_joint[j]`` (r_j, r_j) with a valid lower triangle, ``b_joint[j]`` (r_j,)
        are the sums over the columns ``supports[j]`` of this accumulator (all
        columns when ``supports`` is None); ``zz_joint`` (nv,), ``n`` samples. With
        :attr:`blocks`, the sums count as one contiguous run of samples (one block, or
        part of the open one when it has room).
        """
        if self.blocks is not None:
            self.blocks.add_sums(A_joint, b_joint, zz_joint, n, supports)
        add_joint_sums(self._A, self._b, A_joint, b_joint, supports)
        self._zz += np.asarray(zz_joint, dtype=float)
        self.n += int(n)
        return self

    def merge(self, other: InformationAccumulator) -> InformationAccumulator:
        """Add the sums of ``other`` into ``self`` (data concatenated); returns ``self``."""
        if not isinstance(other, InformationAccumulator):
            raise InputError(
                f"can merge an InformationAccumulator only, got {type(other).__name__}"
            )
        if (other.p, other.nv) != (self.p, self.nv):
            raise InputError(
                f"cannot merge an accumulator of (p={other.p}, nv={other.nv}) "
                f"into one of (p={self.p}, nv={self.nv})"
            )
        self._A += other._A
        self._b += other._b
        self._zz += other._zz
        if self.blocks is not None and other.blocks is not None:
            self.blocks.merge(other.blocks)
        elif other.n > 0 and self.blocks is not None:
            self.blocks = None  # data without blocks: no block scores for the whole
        elif self.n == 0 and other.blocks is not None:
            self.blocks = other.blocks.copy()
        self.n += other.n
        return self

    def __add__(self, other: InformationAccumulator) -> InformationAccumulator:
        return self.copy().merge(other)

    def copy(self) -> InformationAccumulator:
        """An independent copy (with a copy of the blocks)."""
        out = InformationAccumulator(self.p, self.nv)
        out._A[:] = self._A
        out._b[:] = self._b
        out._zz[:] = self._zz
        out.n = self.n
        out.blocks = None if self.blocks is None else self.blocks.copy()
        return out

    def attach_blocks(self, blocks: ScoreBlocks) -> InformationAccumulator:
        """Use ``blocks``, recorded by the caller over the same samples, as :attr:`blocks`.

        For callers that accumulate the totals themselves (on each joint's non-zero
        columns, :meth:`add_sums`) and the blocks alongside (:meth:`ScoreBlocks.add_rows`).
        Returns ``self``.
        """
        if not isinstance(blocks, ScoreBlocks):
            raise InputError(f"expected ScoreBlocks, got {type(blocks).__name__}")
        if (blocks.p, blocks.nv) != (self.p, self.nv) or int(blocks.counts.sum()) != self.n:
            raise InputError(
                f"blocks of (p={blocks.p}, nv={blocks.nv}, n={int(blocks.counts.sum())}) do "
                f"not match the accumulator's (p={self.p}, nv={self.nv}, n={self.n})"
            )
        self.blocks = blocks
        return self

    # ---------------------------------------------------------- read back
    @property
    def A_joint(self) -> np.ndarray:
        """Per-joint information matrices ``A_j``, shape (nv, p, p)."""
        low = np.tril(self._A)
        return low + np.swapaxes(np.tril(self._A, -1), 1, 2)

    @property
    def b_joint(self) -> np.ndarray:
        """Per-joint ``b_j = Y_j^T tau_j``, shape (nv, p)."""
        return self._b.copy()

    @property
    def zz_joint(self) -> np.ndarray:
        """Per-joint ``zz_j = tau_j^T tau_j``, shape (nv,) [(N m)^2]."""
        return self._zz.copy()

    @property
    def A(self) -> np.ndarray:
        """Information matrix ``Phi^T Phi = sum_j A_j``, shape (p, p)."""
        return self.A_joint.sum(axis=0)

    @property
    def b(self) -> np.ndarray:
        """``Phi^T z = sum_j b_j``, shape (p,)."""
        return self._b.sum(axis=0)

    @property
    def zz(self) -> float:
        """``z^T z``, the sum of squared torques [(N m)^2]."""
        return float(self._zz.sum())

    @property
    def n_rows(self) -> int:
        """Number of stacked rows ``n * nv``."""
        return self.n * self.nv

    def weighted(self, weights) -> tuple[np.ndarray, np.ndarray, float]:
        """``(sum_j w_j A_j, sum_j w_j b_j, sum_j w_j zz_j)`` for per-joint weights, shape (nv,)."""
        w = as_float_array(weights, "weights", ndim=1)
        if w.shape != (self.nv,):
            raise InputError(f"weights.shape={w.shape} but the accumulator has nv={self.nv}")
        return (np.einsum("j,jab->ab", w, self.A_joint), w @ self._b, float(w @ self._zz))

    def residual_sum_of_squares(self, theta) -> np.ndarray:
        """Per-joint ``||tau_j - Y_j theta||^2 = zz_j - 2 b_j.theta + theta.A_j.theta``, (nv,).

        Computed from the sums alone (no pass over the data); clipped at zero
        (round-off makes tiny residuals slightly negative).
        """
        theta = as_float_array(theta, "theta", ndim=1)
        if theta.shape != (self.p,):
            raise InputError(f"theta.shape={theta.shape} but the accumulator has p={self.p}")
        quad = np.einsum("a,jab,b->j", theta, self.A_joint, theta)
        return np.maximum(self._zz - 2.0 * self._b @ theta + quad, 0.0)

    def __repr__(self) -> str:
        blocks = "" if self.blocks is None else f", blocks={self.blocks.n_blocks}"
        return f"InformationAccumulator(p={self.p}, nv={self.nv}, n={self.n}{blocks})"


def check_finite_rows(arr: np.ndarray, name: str, offset: int) -> None:
    """NaN/Inf check of a (nv, n, ...) block, naming the global sample index."""
    if np.isfinite(arr).all():
        return
    bad = np.argwhere(~np.isfinite(arr))[0]
    where = f"sample {offset + int(bad[1])}, joint {int(bad[0])}"
    if arr.ndim == 3:
        where += f", column {int(bad[2])}"
    raise InputError(f"{name} holds {arr[tuple(bad)]} at {where}")
