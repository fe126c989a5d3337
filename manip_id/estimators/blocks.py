"""Per-block sums over contiguous samples: the block scores of a streamed fit.

Beside the totals of :class:`~manip_id.estimators.InformationAccumulator`, the same
sums are kept per block ``k`` of contiguous samples, per joint ``j``::

    A_kj = sum_{t in k} Y_tj^T Y_tj    b_kj = sum_{t in k} Y_tj^T tau_tj
    zz_kj = sum_{t in k} tau_tj^2      n_k  = samples of block k

so that after the solve the block scores ``s_k = sum_j w_j (b_kj - A_kj theta_hat)``
(``= Y_k^T W e_k``, the block's share of the normal equations at the estimate) are
at hand with no second pass over the data. They give the autocorrelation-consistent
covariance of :mod:`manip_id.estimators.uncertainty`.

**Which samples form a block.** Samples belong to a *stream* (one record: an array,
one file; numbered in the order of the run) and have an offset ``t`` in it. At the
level ``L`` (samples per block, ``block_length * 2^l``) sample ``t`` of stream ``f``
belongs to the block keyed ``(f, t // L)``: blocks are aligned on multiples of ``L``
in each stream, a stream's end (a file boundary) is a block boundary, and blocks are
listed in key order, which is sample order.

**Bounded memory.** When there are more than ``max_blocks`` blocks the level doubles
(pairs ``(2i, 2i+1)`` of a stream merge), until they fit or every stream is down to
one block; a record keeps between ``max_blocks / 2`` and ``max_blocks`` blocks of
``8 nv (p^2 + p + 1)`` bytes (at least one per stream).

**Parts merge exactly.** A part of a stream (a forked worker's samples, a Dask task's
rows of a file) is recorded from its own offset, so its blocks are pieces of the
stream's blocks; merging adds the pieces that share a key and takes the lowest level
at which the union fits. The union of parts has at least as many blocks at a level
as each part, so that level is the same whatever the cut into parts and the order or
grouping of the merges: the blocks equal those of one serial pass, to round-off.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.blas import dsyrk

from .._checks import as_float_array
from ..errors import InputError

#: Default cap on the number of blocks (a power of two: doubling the level halves it).
MAX_BLOCKS = 128
#: Default samples per block at level 0.
BLOCK_LENGTH = 32


def add_joint_sums(A, b, A_joint, b_joint, supports=None) -> None:
    """Add per-joint sums into ``A`` (lower triangles, (nv, p, p)) and ``b`` ((nv, p)) in
    place: ``A_joint[j]``, ``b_joint[j]`` over all columns, or over the columns
    ``supports[j]`` of joint ``j`` when given (the accumulator's and a block's rule)."""
    for j in range(len(A)):
        if supports is None:
            A[j] += np.tril(A_joint[j])
            b[j] += b_joint[j]
        else:
            sj = np.asarray(supports[j], dtype=np.intp)
            A[j][np.ix_(sj, sj)] += np.tril(A_joint[j])
            b[j][sj] += b_joint[j]


class _Block:
    """The sums of one block: ``A`` (nv, p, p) with valid lower triangles, ``b`` (nv, p),
    ``zz`` (nv,), ``n`` samples."""

    __slots__ = ("A", "b", "n", "zz")

    def __init__(self, nv: int, p: int):
        self.A = np.zeros((nv, p, p))
        self.b = np.zeros((nv, p))
        self.zz = np.zeros(nv)
        self.n = 0

    def add(self, other: _Block) -> None:
        self.A += other.A
        self.b += other.b
        self.zz += other.zz
        self.n += other.n

    def copy(self) -> _Block:
        out = _Block.__new__(_Block)
        out.A, out.b, out.zz, out.n = self.A.copy(), self.b.copy(), self.zz.copy(), self.n
        return out


class ScoreBlocks:
    """Per-block sums of contiguous samples (module docstring).

    Parameters
    ----------
    p : int
        Number of columns (those of the accumulator).
    nv : int
        Outputs per sample (joints).
    block_length : int
        Samples per block at level 0.
    max_blocks : int
        Cap on the number of blocks (>= 2), see the module docstring.
    stream : int
        The record the samples come from (its index in the run, in sample order).
    offset : int
        Offset in that record of the first sample added [samples].
    """

    def __init__(
        self,
        p: int,
        nv: int,
        block_length: int = BLOCK_LENGTH,
        max_blocks: int = MAX_BLOCKS,
        *,
        stream: int = 0,
        offset: int = 0,
    ):
        block_length, max_blocks = int(block_length), int(max_blocks)
        if block_length < 1 or max_blocks < 2 or int(stream) < 0 or int(offset) < 0:
            raise InputError(
                f"blocks need block_length >= 1, max_blocks >= 2, stream >= 0 and offset "
                f">= 0, got block_length={block_length}, max_blocks={max_blocks}, "
                f"stream={stream}, offset={offset}"
            )
        self.p, self.nv = int(p), int(nv)
        self.block_length = block_length  # [samples] at level 0
        self.length = block_length  # [samples] per block at the current level
        self.max_blocks = max_blocks
        self.stream = int(stream)
        self.position = int(offset)  # offset in the stream of the next sample added
        self._blocks: dict[tuple[int, int], _Block] = {}
        self._flat_cache: tuple | None = None  # see _flat_supports

    # ------------------------------------------------------------- levels
    def _rebin(self, length: int) -> None:
        """Go to ``length`` samples per block (a multiple of the current one)."""
        if length == self.length:
            return
        ratio = length // self.length
        out: dict[tuple[int, int], _Block] = {}
        for (f, i), blk in sorted(self._blocks.items()):
            key = (f, i // ratio)
            if key in out:
                out[key].add(blk)
            else:
                out[key] = blk
        self._blocks, self.length = out, length

    def _fit(self) -> None:
        """Double the level while there are more than ``max_blocks`` blocks and a stream
        still has two or more."""
        while len(self._blocks) > self.max_blocks:
            streams = [f for f, _ in self._blocks]
            if len(set(streams)) == len(streams):  # one block per stream: nothing to merge
                return
            self._rebin(2 * self.length)

    def _block_at(self, position: int) -> _Block:
        """The block holding sample ``position`` of this stream (created when new)."""
        key = (self.stream, position // self.length)
        if key not in self._blocks:
            self._blocks[key] = _Block(self.nv, self.p)
            self._fit()
            key = (self.stream, position // self.length)  # the level may have doubled
        return self._blocks[key]

    def _segments(self, n: int):
        """Cut ``n`` new samples at block boundaries: yields ``(start, stop, block)``."""
        pos = 0
        while pos < n:
            blk = self._block_at(self.position)
            m = min(n - pos, self.length - self.position % self.length)
            yield pos, pos + m, blk
            blk.n += m
            self.position += m
            pos += m

    # ------------------------------------------------------------- adding
    def add(self, Yt: np.ndarray, tau: np.ndarray) -> None:
        """Samples of the accumulator's columns: ``Yt`` (nv, n, p) C order, ``tau`` (n, nv)."""
        for a, c, blk in self._segments(tau.shape[0]):
            for j in range(self.nv):
                dsyrk(1.0, Yt[j, a:c].T, beta=1.0, c=blk.A[j].T, trans=0, lower=0, overwrite_c=1)
                blk.b[j] += tau[a:c, j] @ Yt[j, a:c]
            blk.zz += np.einsum("nj,nj->j", tau[a:c], tau[a:c])

    def add_rows(self, rows, tau: np.ndarray, supports, keep: np.ndarray | None = None) -> None:
        """Samples given per joint on its non-zero columns.

        ``rows[j]`` (n, r_j): row ``j`` of the regressor of each sample on the columns
        ``supports[j]``; ``tau`` (n, nv) [N m]; ``keep`` (n, nv) bool: the rows that
        count (e.g. a velocity deadband; a row left out adds nothing, its sample still
        counts in ``n_k``).
        """
        flat = self._flat_supports(supports)
        for a, c, blk in self._segments(tau.shape[0]):
            t = tau[a:c] if keep is None else np.where(keep[a:c], tau[a:c], 0.0)
            for j, (sj, fj) in enumerate(flat):
                rj = rows[j][a:c] if keep is None else rows[j][a:c][keep[a:c, j]]
                tj = t[:, j] if keep is None else t[keep[a:c, j], j]
                blk.A[j].reshape(-1)[fj] += (rj.T @ rj).reshape(-1)  # unique indices
                blk.b[j][sj] += tj @ rj
            blk.zz += np.einsum("nj,nj->j", t, t)

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
        """One run of ``n`` samples given by its sums (see
        :meth:`InformationAccumulator.add_sums`): it cannot be cut, and counts in the
        block of its middle sample; the next sample follows it."""
        blk = self._block_at(self.position + int(n) // 2)
        add_joint_sums(blk.A, blk.b, A_joint, b_joint, supports)
        blk.zz += np.asarray(zz_joint, dtype=float)
        blk.n += int(n)
        self.position += int(n)

    def merge(self, other: ScoreBlocks) -> ScoreBlocks:
        """Add the blocks of ``other`` (other samples: another part or stream); returns
        ``self``. Pieces of one block add; the level is the lowest at which the union fits
        (module docstring). Samples added later continue ``other``'s stream."""
        if not isinstance(other, ScoreBlocks):
            raise InputError(f"can merge ScoreBlocks only, got {type(other).__name__}")
        if (other.p, other.nv, other.block_length) != (self.p, self.nv, self.block_length):
            raise InputError(
                f"cannot merge blocks of (p={other.p}, nv={other.nv}, block_length="
                f"{other.block_length}) into (p={self.p}, nv={self.nv}, block_length="
                f"{self.block_length})"
            )
        other = other.copy()
        length = max(self.length, other.length)
        self._rebin(length)
        other._rebin(length)
        for key, blk in other._blocks.items():
            if key in self._blocks:
                self._blocks[key].add(blk)
            else:
                self._blocks[key] = blk
        self.max_blocks = max(self.max_blocks, other.max_blocks)
        self.stream, self.position = other.stream, other.position
        self._fit()
        return self

    def set_stream(self, stream: int) -> ScoreBlocks:
        """Number the record these blocks come from ``stream`` (for a caller that learns
        it after the accumulation, e.g. a file's index in the run); the blocks must all
        be of one record. Returns ``self``."""
        streams = {f for f, _ in self._blocks}
        if len(streams) > 1:
            raise InputError(f"these blocks hold records {sorted(streams)}: cannot renumber")
        if int(stream) < 0:
            raise InputError(f"stream must be >= 0, got {stream}")
        self._blocks = {(int(stream), i): b for (_, i), b in self._blocks.items()}
        self.stream = int(stream)
        return self

    def copy(self) -> ScoreBlocks:
        """An independent copy."""
        out = ScoreBlocks(self.p, self.nv, self.block_length, self.max_blocks, stream=self.stream)
        out.length, out.position = self.length, self.position
        out._blocks = {k: b.copy() for k, b in self._blocks.items()}
        return out

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state["_flat_cache"] = None  # a cache, not data
        return state

    # ---------------------------------------------------------- read back
    def _ordered(self) -> list[_Block]:
        return [self._blocks[k] for k in sorted(self._blocks)]

    @property
    def n_blocks(self) -> int:
        """Number of blocks ``B``."""
        return len(self._blocks)

    @property
    def keys(self) -> list[tuple[int, int]]:
        """``(stream, index)`` of each block in sample order; block ``(f, i)`` holds
        samples ``[i L, (i + 1) L)`` of stream ``f`` (``L`` = :attr:`length`)."""
        return sorted(self._blocks)

    @property
    def counts(self) -> np.ndarray:
        """Samples per block ``n_k`` in sample order, shape (B,)."""
        return np.array([b.n for b in self._ordered()], dtype=np.int64)

    @property
    def A_joint(self) -> np.ndarray:
        """Per-block, per-joint information ``A_kj``, shape (B, nv, p, p), symmetric."""
        blocks = self._ordered()
        if not blocks:
            return np.zeros((0, self.nv, self.p, self.p))
        A = np.stack([b.A for b in blocks])
        return np.tril(A) + np.swapaxes(np.tril(A, -1), -1, -2)

    @property
    def b_joint(self) -> np.ndarray:
        """Per-block, per-joint ``b_kj``, shape (B, nv, p)."""
        return np.array([b.b for b in self._ordered()]).reshape(-1, self.nv, self.p)

    @property
    def zz_joint(self) -> np.ndarray:
        """Per-block, per-joint ``zz_kj`` [(N m)^2], shape (B, nv)."""
        return np.array([b.zz for b in self._ordered()]).reshape(-1, self.nv)

    def information(self, weights=None) -> np.ndarray:
        """``A_k = sum_j w_j A_kj``, shape (B, p, p) (``w_j = 1`` by default)."""
        return np.einsum("j,kjab->kab", self._weights(weights), self.A_joint)

    def scores(self, theta, weights=None) -> np.ndarray:
        """Block scores ``s_k = sum_j w_j (b_kj - A_kj theta)``, shape (B, p).

        At the least-squares estimate they sum to zero; each is ``Y_k^T W e_k``,
        block ``k``'s regressor times its weighted residuals.
        """
        theta = as_float_array(theta, "theta", ndim=1)
        if theta.shape != (self.p,):
            raise InputError(f"theta.shape={theta.shape} but the blocks have p={self.p}")
        res = self.b_joint - np.einsum("kjab,b->kja", self.A_joint, theta)
        return np.einsum("j,kja->ka", self._weights(weights), res)

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
