"""Measured data: the :class:`Dataset` type and its validation.

A dataset is a time series of joint states and torques::

    t    time stamps [s], shape (N,), strictly increasing
    q    positions [rad or m], shape (N, nq)
    dq   velocities [rad/s or m/s], shape (N, nv)
    tau  joint torques [N m or N], shape (N, nv)
    ddq  accelerations [rad/s^2 or m/s^2], shape (N, nv), optional
    joint_names  one name per velocity coordinate, optional
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from ._checks import as_float_array, check_finite
from .errors import DataError


@dataclass(frozen=True)
class Dataset:
    """Joint-space measurements, validated on construction (see module docstring)."""

    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    tau: np.ndarray
    ddq: np.ndarray | None = None
    joint_names: tuple[str, ...] | None = None
    meta: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        arrays = {"t": (self.t, 1), "q": (self.q, 2), "dq": (self.dq, 2), "tau": (self.tau, 2)}
        if self.ddq is not None:
            arrays["ddq"] = (self.ddq, 2)
        clean = {}
        for name, (value, ndim) in arrays.items():
            try:
                arr = as_float_array(value, name, ndim=ndim)
            except Exception as exc:
                raise DataError(str(exc)) from exc
            clean[name] = arr
        n = clean["t"].shape[0]
        if n < 2:
            raise DataError(f"a dataset needs at least 2 samples, got t.shape={clean['t'].shape}")
        for name, arr in clean.items():
            if arr.shape[0] != n:
                raise DataError(f"t.shape={clean['t'].shape} but {name}.shape={arr.shape}: "
                                "every array needs one row per time stamp")
        nv = clean["dq"].shape[1]
        for name in ("tau", "ddq"):
            if name in clean and clean[name].shape[1] != nv:
                raise DataError(f"dq.shape={clean['dq'].shape} but {name}.shape={clean[name].shape}")
        if clean["q"].shape[1] < nv:
            raise DataError(f"q.shape={clean['q'].shape} has fewer columns than dq.shape={clean['dq'].shape}")
        names = None
        if self.joint_names is not None:
            names = tuple(str(j) for j in self.joint_names)
            if len(names) != nv:
                raise DataError(f"{len(names)} joint_names for nv={nv} velocity columns")
        for name, arr in clean.items():
            try:
                check_finite(arr, name, names if name != "q" else None)
            except Exception as exc:
                raise DataError(str(exc)) from exc
        dt = np.diff(clean["t"])
        if np.any(dt <= 0):
            k = int(np.argmax(dt <= 0)) + 1
            raise DataError(f"time must increase strictly: t[{k}]={clean['t'][k]} "
                            f"after t[{k - 1}]={clean['t'][k - 1]}")
        if np.nanmax(np.abs(clean["q"])) > 2 * np.pi * 4:
            warnings.warn(f"positions reach {np.abs(clean['q']).max():.1f}: are they in degrees? "
                          "manip_id expects radians (meters for prismatic joints)", stacklevel=3)
        for name, arr in clean.items():
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "joint_names", names)

    @property
    def n_samples(self) -> int:
        """Number of samples N."""
        return self.t.shape[0]

    @property
    def nv(self) -> int:
        """Number of velocity coordinates."""
        return self.dq.shape[1]

    @property
    def duration(self) -> float:
        """t[-1] - t[0] [s]."""
        return float(self.t[-1] - self.t[0])

    def slice(self, start: int, stop: int) -> Dataset:
        """Samples ``start:stop`` as a new dataset."""
        return replace(
            self,
            t=self.t[start:stop],
            q=self.q[start:stop],
            dq=self.dq[start:stop],
            tau=self.tau[start:stop],
            ddq=None if self.ddq is None else self.ddq[start:stop],
        )

    def split(self, fraction: float) -> tuple[Dataset, Dataset]:
        """Split in time: the first ``fraction`` of samples, then the rest (for validation)."""
        if not 0.0 < fraction < 1.0:
            raise DataError(f"split fraction must be in (0, 1), got {fraction}")
        k = int(round(fraction * self.n_samples))
        k = min(max(k, 2), self.n_samples - 2)
        return self.slice(0, k), self.slice(k, self.n_samples)
