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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg.blas import dsyrk

from .._checks import as_float_array
from ..errors import InputError

#: Default cap on the number of recorded blocks (a power of two: a pair merge halves it).
MAX_BLOCKS = 128
#: Default length of a block [samples] before the first doubling.
BLOCK_LENGTH = 32


@dataclass(frozen=True)
class BlockPlan:
    """Block settings fixed in advance for data of known length.

    A stream of ``n`` samples that starts with blocks of ``block_length`` and doubles
    them at ``max_blocks`` ends with blocks of ``length = block_length 2^k`` (the
    smallest with ``ceil(n / length) <= max_blocks``), aligned on multiples of
    ``length``. Starting every part of the data at that length, with a cap no merge
    reaches (``ceil(n / length) + n_parts``: each part may end on a short block),
    gives the same blocks whatever the cut into parts (forked workers, files, Dask
    partitions) and the order of the merges, as long as the parts that make one
    contiguous record are cut on multiples of ``length``.

    Attributes
    ----------
    length : int
        Samples per block.
    max_blocks : int
        The cap of every part's :class:`ScoreBlocks`.
    """

    length: int
    max_blocks: int

    @classmethod
    def for_samples(
        cls,
        n_samples: int,
        n_parts: int = 1,
        *,
        block_length: int = BLOCK_LENGTH,
        max_blocks: int = MAX_BLOCKS,
    ) -> BlockPlan:
        """The plan for ``n_samples`` in ``n_parts`` separately accumulated parts."""
        n, length = max(int(n_samples), 1), max(int(block_length), 1)
        while -(-n // length) > max_blocks:
            length *= 2
        return cls(length, max(int(max_blocks), -(-n // length) + int(n_parts)))

    def cuts(self, n_samples: int, n_parts: int) -> np.ndarray:
        """Bounds of at most ``n_parts`` non-empty contiguous parts of ``n_samples``, cut
        on block boundaries and as equal as the block length allows, increasing, from 0
        to ``n_samples`` (fewer parts when the record has fewer blocks)."""
        n = int(n_samples)
        even = np.linspace(0, n, max(int(n_parts), 1) + 1)
        bounds = np.minimum(np.round(even / self.length).astype(np.int64) * self.length, n)
        bounds[0], bounds[-1] = 0, n
        return np.unique(bounds)


class ScoreBlocks:
    """Per-block sums over contiguous runs of samples, for scores at the estimate.

    Parameters
    ----------
    p : int
        Number of columns (the accumulator's).
    nv : int
        Outputs per sample (joints).
    block_length : int
        Samples per block until the first doubling.
    max_blocks : int
        Cap on the number of blocks (>= 2); when a new block would exceed it,
        adjacent pairs merge and the block length doubles.

    Block ``k`` holds ``A_kj`` (valid lower triangle), ``b_kj``, ``zz_kj`` for each
    joint ``j`` and its sample count ``n_k``. Only the last block may still take
    samples (:attr:`open`); a block filled by :meth:`add_sums` with more samples
    than the block length is closed as it is.
    """

    def __init__(
        self, p: int, nv: int, block_length: int = BLOCK_LENGTH, max_blocks: int = MAX_BLOCKS
    ):
        block_length, max_blocks = int(block_length), int(max_blocks)
        if block_length < 1 or max_blocks < 2:
            raise InputError(
                f"blocks need block_length >= 1 and max_blocks >= 2, got "
                f"block_length={block_length}, max_blocks={max_blocks}"
            )
        self.p, self.nv = int(p), int(nv)
        self.length = block_length  # [samples] target length of the open block
        self.max_blocks = max_blocks
        self._A: list[np.ndarray] = []  # each (nv, p, p), lower triangles valid
        self._b: list[np.ndarray] = []  # each (nv, p)
        self._zz: list[np.ndarray] = []  # each (nv,)
        self._n: list[int] = []
        self.open = False
        self._flat_cache: tuple | None = None  # see _flat_supports

    # ------------------------------------------------------------- adding
    def _start(self) -> None:
        """Open a new empty block, merging adjacent pairs first when at the cap."""
        if len(self._n) >= self.max_blocks:
            self._merge_pairs()
            self.length *= 2
        self._A.append(np.zeros((self.nv, self.p, self.p)))
        self._b.append(np.zeros((self.nv, self.p)))
        self._zz.append(np.zeros(self.nv))
        self._n.append(0)
        self.open = True

    def _merge_pairs(self) -> None:
        """Blocks (0, 1), (2, 3), ... become one each (an odd last block stays alone)."""
        for name in ("_A", "_b", "_zz"):
            old = getattr(self, name)
            for i in range(0, len(old) - 1, 2):
                old[i] += old[i + 1]  # in place: each block array is owned by this store
            setattr(self, name, old[::2])
        self._n = [sum(self._n[i : i + 2]) for i in range(0, len(self._n), 2)]

    def _segments(self, n: int):
        """Cut ``n`` new samples at block boundaries: yields ``(start, stop)`` in order."""
        pos = 0
        while pos < n:
            if not self.open or self._n[-1] >= self.length:
                self._start()
            m = min(n - pos, self.length - self._n[-1])
            yield pos, pos + m
            self._n[-1] += m
            pos += m

    def add(self, Yt: np.ndarray, tau: np.ndarray) -> None:
        """Samples of the accumulator's columns: ``Yt`` (nv, n, p) C order, ``tau`` (n, nv)."""
        for a, c in self._segments(tau.shape[0]):
            A, b = self._A[-1], self._b[-1]
            for j in range(self.nv):
                dsyrk(1.0, Yt[j, a:c].T, beta=1.0, c=A[j].T, trans=0, lower=0, overwrite_c=1)
                b[j] += tau[a:c, j] @ Yt[j, a:c]
            self._zz[-1] += np.einsum("nj,nj->j", tau[a:c], tau[a:c])

    def add_rows(self, rows, tau: np.ndarray, supports, keep: np.ndarray | None = None) -> None:
        """Samples given per joint on its non-zero columns.

        ``rows[j]`` (n, r_j): row ``j`` of the regressor of each sample on the columns
        ``supports[j]``; ``tau`` (n, nv) [N m]; ``keep`` (n, nv) bool: the rows that
        count (e.g. a velocity deadband; a left-out row adds nothing, its sample still
        counts in ``n_k``).
        """
        flat = self._flat_supports(supports)
        for a, c in self._segments(tau.shape[0]):
            A, b = self._A[-1], self._b[-1]
            t = tau[a:c] if keep is None else np.where(keep[a:c], tau[a:c], 0.0)
            for j, (sj, fj) in enumerate(flat):
                rj = rows[j][a:c] if keep is None else rows[j][a:c][keep[a:c, j]]
                tj = t[:, j] if keep is None else t[keep[a:c, j], j]
                A[j].reshape(-1)[fj] += (rj.T @ rj).reshape(-1)  # unique indices: no add.at
                b[j][sj] += tj @ rj
            self._zz[-1] += np.einsum("nj,nj->j", t, t)

    def _flat_supports(self, supports) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per joint ``(s_j, flat indices of s_j x s_j in a (p, p) block)``, cached for the
        ``supports`` object of the last call (a caller passes the same one every chunk)."""
        if self._flat_cache is not None and self._flat_cache[0] is supports:
            return self._flat_cache[1]
        flat = []
        for sj in supports:
            sj = np.asarray(sj, dtype=np.intp)
            flat.append((sj, (sj[:, None] * self.p + sj[None, :]).reshape(-1)))
        self._flat_cache = (supports, flat)
        return flat

    def add_sums(self, A_joint, b_joint, zz_joint, n: int, supports=None) -> None:
        """One contiguous run of ``n`` samples given by its sums (see
        :meth:`InformationAccumulator.add_sums`): added to the open block when it has
        room, else it starts a block of its own."""
        n = int(n)
        if not self.open or self._n[-1] + n > self.length:
            self._start()
        A, b = self._A[-1], self._b[-1]
        for j in range(self.nv):
            if supports is None:
                A[j] += np.tril(A_joint[j])
                b[j] += b_joint[j]
            else:
                sj = np.asarray(supports[j], dtype=np.intp)
                A[j][np.ix_(sj, sj)] += np.tril(A_joint[j])
                b[j][sj] += b_joint[j]
        self._zz[-1] += np.asarray(zz_joint, dtype=float)
        self._n[-1] += n

    def merge(self, other: ScoreBlocks) -> ScoreBlocks:
        """Append the blocks of ``other`` (data that follows) to ``self``; returns ``self``.

        The last block of ``self`` is closed (the boundary is a block boundary). When the
        total exceeds :attr:`max_blocks`, the adjacent pair with the fewest samples is
        merged (the leftmost of equals) until it fits; the block length becomes the
        larger of the two.
        """
        if (other.p, other.nv) != (self.p, self.nv):
            raise InputError(
                f"cannot merge blocks of (p={other.p}, nv={other.nv}) into (p={self.p}, "
                f"nv={self.nv})"
            )
        other = other.copy()
        self._A += other._A
        self._b += other._b
        self._zz += other._zz
        self._n += other._n
        self.open = other.open
        self.length = max(self.length, other.length)
        self.max_blocks = max(self.max_blocks, other.max_blocks)
        while len(self._n) > self.max_blocks:
            pairs = [self._n[i] + self._n[i + 1] for i in range(len(self._n) - 1)]
            i = int(np.argmin(pairs))
            for name in ("_A", "_b", "_zz", "_n"):
                seq = getattr(self, name)
                seq[i : i + 2] = [seq[i] + seq[i + 1]]
        return self

    def copy(self) -> ScoreBlocks:
        """An independent copy."""
        out = ScoreBlocks(self.p, self.nv, self.length, self.max_blocks)
        out._A = [a.copy() for a in self._A]
        out._b = [b.copy() for b in self._b]
        out._zz = [z.copy() for z in self._zz]
        out._n = list(self._n)
        out.open = self.open
        return out

    # ---------------------------------------------------------- read back
    @property
    def n_blocks(self) -> int:
        """Number of non-empty blocks ``B``."""
        return sum(1 for n in self._n if n > 0)

    @property
    def counts(self) -> np.ndarray:
        """Samples per block ``n_k``, shape (B,)."""
        return np.array([n for n in self._n if n > 0], dtype=np.int64)

    def _kept(self, seq: list[np.ndarray], shape: tuple[int, ...]) -> np.ndarray:
        kept = [x for x, n in zip(seq, self._n, strict=True) if n > 0]
        return np.stack(kept) if kept else np.zeros((0, *shape))

    @property
    def A_joint(self) -> np.ndarray:
        """Per-block, per-joint information ``A_kj``, shape (B, nv, p, p), symmetric."""
        A = self._kept(self._A, (self.nv, self.p, self.p))
        return np.tril(A) + np.swapaxes(np.tril(A, -1), -1, -2)

    @property
    def b_joint(self) -> np.ndarray:
        """Per-block, per-joint ``b_kj``, shape (B, nv, p)."""
        return self._kept(self._b, (self.nv, self.p))

    @property
    def zz_joint(self) -> np.ndarray:
        """Per-block, per-joint ``zz_kj`` [(N m)^2], shape (B, nv)."""
        return self._kept(self._zz, (self.nv,))

    def information(self, weights=None) -> np.ndarray:
        """``A_k = sum_j w_j A_kj``, shape (B, p, p) (``w_j = 1`` by default)."""
        w = self._weights(weights)
        return np.einsum("j,kjab->kab", w, self.A_joint)

    def scores(self, theta, weights=None) -> np.ndarray:
        """Block scores ``s_k = sum_j w_j (b_kj - A_kj theta)``, shape (B, p).

        At the least-squares estimate they sum to zero; each is ``Y_k^T W e_k``,
        block ``k``'s regressor times its weighted residuals.
        """
        theta = as_float_array(theta, "theta", ndim=1)
        if theta.shape != (self.p,):
            raise InputError(f"theta.shape={theta.shape} but the blocks have p={self.p}")
        w = self._weights(weights)
        res = self.b_joint - np.einsum("kjab,b->kja", self.A_joint, theta)
        return np.einsum("j,kja->ka", w, res)

    def _weights(self, weights) -> np.ndarray:
        if weights is None:
            return np.ones(self.nv)
        w = as_float_array(weights, "weights", ndim=1)
        if w.shape != (self.nv,):
            raise InputError(f"weights.shape={w.shape} but the blocks have nv={self.nv}")
        return w

    def __repr__(self) -> str:
        return (
            f"ScoreBlocks(p={self.p}, nv={self.nv}, blocks={self.n_blocks}, "
            f"length={self.length}, max_blocks={self.max_blocks})"
        )


class InformationAccumulator:
    """Per-joint sums ``A_j``, ``b_j``, ``zz_j`` and the sample count ``n``.

    Parameters
    ----------
    p : int
        Number of parameters (columns accumulated).
    nv : int
        Number of outputs per sample (joints).
    blocks : bool
        Also record the sums per block of contiguous samples (:attr:`blocks`, a
        :class:`ScoreBlocks`), for the autocorrelation-consistent covariance.
    block_length : int
        Samples per block until the first doubling (with ``blocks``).
    max_blocks : int
        Cap on the number of blocks (with ``blocks``).

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
        blocks: bool = False,
        block_length: int = BLOCK_LENGTH,
        max_blocks: int = MAX_BLOCKS,
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
        self.blocks: ScoreBlocks | None = (
            ScoreBlocks(p, nv, block_length, max_blocks) if blocks else None
        )

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
        for j in range(self.nv):
            if supports is None:
                self._A[j] += np.tril(A_joint[j])
                self._b[j] += b_joint[j]
            else:
                sj = np.asarray(supports[j], dtype=np.intp)
                self._A[j][np.ix_(sj, sj)] += np.tril(A_joint[j])
                self._b[j][sj] += b_joint[j]
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
