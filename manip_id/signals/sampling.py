"""Time grids, resampling, central differences and the dataset-level resample, decimate, trim."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .._checks import as_float_array
from ..datasets import Dataset
from ..errors import DataError, InputError

#: Relative jitter of the sampling period above which :func:`preprocess` resamples.
JITTER_TOLERANCE = 1e-6


# ------------------------------------------------------- grids and derivatives
def sampling_rate(t) -> float:
    """Mean sampling rate ``(N - 1) / (t[-1] - t[0])`` [Hz] of time stamps ``t`` [s], shape (N,).

    On jittery stamps this keeps the number of samples when resampling (the
    median step of the real Panda log, 0.99 ms, would upsample its 1.02 ms mean).
    """
    t = as_float_array(t, "t", ndim=1)
    if t.shape[0] < 2:
        raise InputError(f"need at least 2 time stamps, got t.shape={t.shape}")
    if np.any(np.diff(t) <= 0):
        raise InputError("time stamps must increase strictly")
    return float((t.shape[0] - 1) / (t[-1] - t[0]))


def is_uniform(t, tol: float = JITTER_TOLERANCE) -> bool:
    """Whether the steps of ``t`` [s] agree with their mean within ``tol`` (relative)."""
    dt = np.diff(np.asarray(t, dtype=float))
    return bool(np.max(np.abs(dt - dt.mean())) <= tol * abs(dt.mean()))


def uniform_grid(t0: float, t1: float, rate: float) -> np.ndarray:
    """Time stamps ``t0 + k / rate`` [s] for k = 0.. while <= t1, shape (M,)."""
    if not (math.isfinite(rate) and rate > 0):
        raise InputError(f"sampling rate must be positive [Hz], got {rate}")
    n = int(math.floor((t1 - t0) * rate * (1 + 1e-12))) + 1
    return t0 + np.arange(n) / rate


def resample(t, x, t_new, kind: str = "cubic") -> np.ndarray:
    """Values of ``x`` sampled at ``t`` interpolated at ``t_new`` (within [t[0], t[-1]]).

    Parameters
    ----------
    t : array_like
        original time stamps [s], shape (N,), strictly increasing, possibly non-uniform
    x : array_like
        samples, shape (N,) or (N, m)
    t_new : array_like
        target time stamps [s], shape (M,)
    kind : str
        ``"cubic"`` (not-a-knot cubic spline, exact on cubics) or ``"linear"``

    Returns
    -------
    numpy.ndarray
        shape (M,) or (M, m).
    """
    from scipy.interpolate import CubicSpline  # heavy (0.13 s): only when resampling

    t = as_float_array(t, "t", ndim=1)
    x = as_float_array(x, "x", ndim=(1, 2))
    t_new = as_float_array(t_new, "t_new", ndim=1)
    if x.shape[0] != t.shape[0]:
        raise InputError(f"t.shape={t.shape} but x.shape={x.shape}")
    if t_new.size and (t_new[0] < t[0] - 1e-12 or t_new[-1] > t[-1] + 1e-12):
        raise InputError(f"t_new spans [{t_new[0]}, {t_new[-1]}] outside t's [{t[0]}, {t[-1]}]")
    if kind == "cubic":
        return CubicSpline(t, x, axis=0)(t_new)
    if kind == "linear":
        if x.ndim == 1:
            return np.interp(t_new, t, x)
        return np.stack([np.interp(t_new, t, x[:, j]) for j in range(x.shape[1])], axis=1)
    raise InputError(f"unknown interpolation kind {kind!r}; expected 'cubic' or 'linear'")


def derivative(t, x) -> np.ndarray:
    """Central-difference derivative dx/dt along axis 0.

    Parameters
    ----------
    t : array_like
        time stamps [s], shape (N,) (uniform or not), or a scalar step dt [s]
    x : array_like
        samples, shape (N,) or (N, m)

    Returns
    -------
    numpy.ndarray
        dx/dt of x's shape: second-order central differences inside, second-order
        one-sided differences at both ends (``numpy.gradient``, ``edge_order=2``).
    """
    x = np.asarray(x, dtype=float)
    if x.shape[0] < 3:
        raise InputError(f"need at least 3 samples to differentiate, got x.shape={x.shape}")
    spacing = np.asarray(t, dtype=float)
    if spacing.ndim == 1 and spacing.shape[0] != x.shape[0]:
        raise InputError(f"t.shape={spacing.shape} but x.shape={x.shape}")
    return np.gradient(x, spacing, axis=0, edge_order=2)


# --------------------------------------------------------------- on datasets
def resample_dataset(dataset: Dataset, rate: float | None = None, kind: str = "cubic") -> Dataset:
    """The dataset interpolated on the grid ``t[0] + k / rate`` (rate default: the mean rate)."""
    rate = sampling_rate(dataset.t) if rate is None else float(rate)
    t_new = uniform_grid(dataset.t[0], dataset.t[-1], rate)
    fields: dict = {
        name: resample(dataset.t, getattr(dataset, name), t_new, kind)
        for name in ("q", "dq", "tau", "ddq", "temp")
        if getattr(dataset, name) is not None
    }
    return replace(dataset, t=t_new, **fields, meta={**dataset.meta, "rate": rate})


def downsample(dataset: Dataset, factor: int) -> Dataset:
    """Every ``factor``-th sample. Only alias-free after a low-pass below ``rate / (2 factor)``."""
    if int(factor) != factor or factor < 1:
        raise InputError(f"decimation factor must be a positive integer, got {factor}")
    factor = int(factor)
    if factor == 1:
        return dataset
    s = slice(None, None, factor)
    return replace(
        dataset,
        t=dataset.t[s],
        q=dataset.q[s],
        dq=dataset.dq[s],
        tau=dataset.tau[s],
        ddq=None if dataset.ddq is None else dataset.ddq[s],
        temp=None if dataset.temp is None else dataset.temp[s],
    )


def trim_samples(dataset: Dataset, start: int, stop: int | None = None) -> Dataset:
    """Drop ``start`` samples at the beginning and ``stop`` (default ``start``) at the end."""
    stop = start if stop is None else stop
    if start < 0 or stop < 0:
        raise InputError(f"trim counts must be >= 0, got {start}, {stop}")
    n = dataset.n_samples
    if start + stop > n - 2:
        raise DataError(
            f"trimming {float(start):.4g} + {float(stop):.4g} samples leaves fewer than 2 of {n}"
        )
    return dataset.slice(start, n - stop)
