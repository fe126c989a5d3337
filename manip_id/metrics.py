"""Error figures and JSON numbers shared by every layer (numpy only).

The relative torque error of a fit, over stacked samples ``k`` and joints ``j``::

    e   = sqrt( sum_j RSS_j / sum_j ZZ_j )         RSS_j = sum_k (tau_kj - tau_hat_kj)^2
    e_j = sqrt( RSS_j / ZZ_j )                     ZZ_j  = sum_k tau_kj^2

from the per-joint sums alone (:func:`relative_error`), so that errors of files, blocks
and workers pool by adding their sums. ``finite_or_none`` is the JSON form of a number:
inf and NaN become ``None`` (``null``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike


@dataclass(frozen=True)
class ErrorFigures:
    """A relative error overall and per output.

    Attributes
    ----------
    total : float
        ``sqrt(sum RSS / sum ZZ)`` [-]; NaN when ``sum ZZ = 0``.
    per_joint : numpy.ndarray
        ``sqrt(RSS_j / ZZ_j)`` [-], shape (nv,); NaN or inf where ``ZZ_j = 0``.
    """

    total: float
    per_joint: np.ndarray

    def __iter__(self):  # unpacks as ``total, per_joint``
        return iter((self.total, self.per_joint))


def relative_error(rss: ArrayLike, zz: ArrayLike) -> ErrorFigures:
    """Relative error from per-output sums of squares (module docstring).

    Parameters
    ----------
    rss : array_like
        Residual sums of squares per output, shape (nv,) [(N m)^2].
    zz : array_like
        Sums of the squared measured outputs, shape (nv,) [(N m)^2].
    """
    rss = np.atleast_1d(np.asarray(rss, dtype=float))
    zz = np.atleast_1d(np.asarray(zz, dtype=float))
    with np.errstate(divide="ignore", invalid="ignore"):
        per_joint = np.sqrt(rss / zz)
    total = float(np.sqrt(rss.sum() / zz.sum())) if zz.sum() > 0 else float("nan")
    return ErrorFigures(total, per_joint)


def finite_or_none(x) -> float | None:
    """``float(x)`` when finite, else None (the JSON form of inf, NaN and None)."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def finite_list(x) -> list[float | None] | None:
    """An array as a list of :func:`finite_or_none` values (None stays None)."""
    if x is None:
        return None
    return [finite_or_none(v) for v in np.atleast_1d(np.asarray(x, dtype=float))]


__all__ = ["ErrorFigures", "finite_list", "finite_or_none", "relative_error"]
