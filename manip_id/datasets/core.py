"""The measured-data type :class:`Dataset`, its validation, and the check against a robot.

A dataset is a time series of joint states and torques::

    t    time stamps [s], shape (N,), strictly increasing
    q    positions [rad or m], shape (N, nq)
    dq   velocities [rad/s or m/s], shape (N, nv)
    tau  joint torques [N m or N], shape (N, nv)
    ddq  accelerations [rad/s^2 or m/s^2], shape (N, nv), optional
    temp temperatures [degC or K], shape (N, nv) or (N, 1) (one for every joint), optional
    joint_names  one name per velocity coordinate, optional

Validation on construction: at least 2 samples, one row per time stamp,
consistent widths, strictly increasing time (the error names the first
offending stamp), NaN/Inf reported with sample and column, and a warning when
positions look like degrees. The value checks live in :func:`check_values`,
which the streamed readers call on every block too (with the block's offset in
the file), so a block read in chunks is held to the same rules as a whole array.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from .._checks import as_float_array, as_int, as_real, check_finite, check_magnitude
from ..errors import DataError, DataWarning, InputError
from ..robot.parameters import bounded_range

#: Largest |q| [rad] taken as radians; beyond it positions look like degrees.
DEGREES_THRESHOLD = 8 * np.pi


def check_values(name: str, value, ndim: int, columns=None, offset: int = 0) -> np.ndarray:
    """``value`` as a float64 array of ``ndim`` dimensions with only finite entries.

    The one value validator of measured data (whole arrays and streamed blocks):
    refuses non-numeric and complex data, wrong dimensions, NaN and Inf (naming
    the sample ``offset + k`` and the column), and implausible magnitudes
    (:func:`manip_id._checks.check_magnitude`; time stamps excepted, which may be
    seconds since 1970). Raises :class:`DataError`.
    """
    arr = np.asarray(value) if not isinstance(value, np.ndarray) else value
    if np.iscomplexobj(arr):
        raise DataError(f"{name} holds complex numbers (dtype {arr.dtype}); expected real values")
    try:
        arr = as_float_array(arr, name, ndim=ndim)
    except Exception as exc:
        raise DataError(str(exc)) from exc
    if not np.isfinite(arr).all():
        try:
            check_finite(arr, name, columns)
        except Exception as exc:
            msg = str(exc)
            if offset:
                k = int(np.argwhere(~np.isfinite(arr))[0][0])
                msg = msg.replace(f"at sample {k}", f"at sample {offset + k}", 1)
            raise DataError(msg) from exc
    check_magnitude(arr, name, columns, offset, error=DataError)  # t: epoch seconds pass
    return arr


def check_time(
    t: np.ndarray,
    offset: int = 0,
    previous: float | None = None,
    *,
    rows=None,
    previous_row: int | None = None,
) -> None:
    """Raise :class:`DataError` unless ``t`` increases strictly (after ``previous``, if given).

    The messages name stamp ``k`` as row ``offset + k``, or ``rows[k]`` when the row numbers
    are given (rows dropped in between), and ``previous`` as row ``previous_row`` (default
    the row before the first).
    """
    row = (lambda k: offset + k) if rows is None else (lambda k: rows[k])
    if previous is not None and t.size and not t[0] > previous:
        before = row(0) - 1 if previous_row is None else previous_row
        raise DataError(
            f"time must increase strictly: t[{row(0)}]={t[0]} after t[{before}]={previous}"
        )
    dt = np.diff(t)
    if np.any(dt <= 0):
        k = int(np.argmax(dt <= 0)) + 1
        raise DataError(
            f"time must increase strictly: t[{row(k)}]={t[k]} after t[{row(k - 1)}]={t[k - 1]}"
        )


def check_shapes(shapes: dict[str, tuple[int, ...]], prefix: str = "") -> None:
    """Raise :class:`DataError` unless the arrays agree: one row per time stamp, and tau
    (and ddq) as many columns as dq.

    ``shapes`` maps names (``t`` of shape (N,), ``q``, ``dq``, ``tau``, optionally ``ddq``,
    each 2-D) to shapes, checked in that order; ``prefix`` starts every message (a file name).
    """
    first = "t" if "t" in shapes else "q"  # a log without stamps: its positions
    n = shapes[first][0]
    for name, shape in shapes.items():
        if shape[0] != n:
            raise DataError(
                f"{prefix}{first}.shape={shapes[first]} but {name}.shape={shape}: "
                "every array needs one row per time stamp"
            )
    ref = "dq" if "dq" in shapes else "tau"  # a log of positions only: its torques
    nv = shapes[ref][1]
    for name in ("tau", "ddq"):
        if name in shapes and shapes[name][1] != nv:
            raise DataError(f"{prefix}{ref}.shape={shapes[ref]} but {name}.shape={shapes[name]}")
    temp = shapes.get("temp")
    if temp is not None and (len(temp) > 2 or (len(temp) == 2 and temp[1] not in (1, nv))):
        raise DataError(
            f"{prefix}{ref}.shape={shapes[ref]} but temp.shape={temp}: give one temperature "
            "column per joint or one column for every joint"
        )


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
    temp: np.ndarray | None = None

    def __post_init__(self):
        arrays = {"t": (self.t, 1), "q": (self.q, 2), "dq": (self.dq, 2), "tau": (self.tau, 2)}
        if self.ddq is not None:
            arrays["ddq"] = (self.ddq, 2)
        if self.temp is not None:  # one column: (N,) taken as (N, 1)
            arrays["temp"] = (np.reshape(self.temp, (len(self.temp), -1)), 2)
        clean = {}
        for name, (value, ndim) in arrays.items():
            arr = np.asarray(value) if not isinstance(value, np.ndarray) else value
            if np.iscomplexobj(arr):
                raise DataError(
                    f"{name} holds complex numbers (dtype {arr.dtype}); expected real values"
                )
            try:
                clean[name] = as_float_array(arr, name, ndim=ndim)
            except Exception as exc:
                raise DataError(str(exc)) from exc
        n = clean["t"].shape[0]
        if n < 2:
            raise DataError(f"a dataset needs at least 2 samples, got t.shape={clean['t'].shape}")
        check_shapes({name: arr.shape for name, arr in clean.items()})
        nv = clean["dq"].shape[1]
        if clean["q"].shape[1] < nv:
            raise DataError(
                f"q.shape={clean['q'].shape} has fewer columns than dq.shape={clean['dq'].shape}"
            )
        names = None
        if self.joint_names is not None:
            names = tuple(str(j) for j in self.joint_names)
            if len(names) != nv:
                raise DataError(f"{len(names)} joint_names for nv={nv} velocity columns")
        for name, arr in clean.items():
            check_values(name, arr, arr.ndim, names if arr.shape[-1] == nv else None)
        check_time(clean["t"])
        if np.abs(clean["q"]).max() > DEGREES_THRESHOLD:
            warnings.warn(
                DataWarning(
                    f"positions reach {np.abs(clean['q']).max():.1f}: are they in degrees? "
                    "manip_id expects radians (meters for prismatic joints)"
                ),
                stacklevel=3,
            )
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
        start, stop = as_int(start, "start"), as_int(stop, "stop")
        return replace(
            self,
            t=self.t[start:stop],
            q=self.q[start:stop],
            dq=self.dq[start:stop],
            tau=self.tau[start:stop],
            ddq=None if self.ddq is None else self.ddq[start:stop],
            temp=None if self.temp is None else self.temp[start:stop],
        )

    def split(self, fraction: float) -> tuple[Dataset, Dataset]:
        """Split in time: the first ``fraction`` of samples, then the rest (for validation)."""
        try:
            fraction = as_real(fraction, "split fraction")
        except InputError as exc:
            raise DataError(str(exc)) from exc
        if not 0.0 < fraction < 1.0:
            raise DataError(f"split fraction must be in (0, 1), got {fraction}")
        k = int(round(fraction * self.n_samples))
        k = min(max(k, 2), self.n_samples - 2)
        train, valid = self.slice(0, k), self.slice(k, self.n_samples)
        period = (self.meta or {}).get("period")
        if period and train.duration >= float(period):
            warnings.warn(
                DataWarning(
                    f"the validation part repeats the training motion: the motion is periodic "
                    f"({float(period):g} s) and the training part spans {train.duration:g} s, "
                    "more than one period; its validation error then measures noise, not "
                    "prediction on new motion (validate on another trajectory)"
                ),
                stacklevel=2,
            )
        return train, valid


def check_robot(dataset: Dataset, robot) -> None:
    """Raise :class:`DataError` unless the dataset fits ``robot`` (a :class:`~.robot.Robot`).

    Checks q has ``robot.nq`` columns, dq and tau ``robot.nv``, and, when the
    dataset names its joints, that the names are ``robot.dof_names`` in order.
    """
    if dataset.q.shape[1] != robot.nq or dataset.nv != robot.nv:
        raise DataError(
            f"the data have {dataset.nv} joints (q.shape={dataset.q.shape}, "
            f"dq.shape={dataset.dq.shape}) but robot {robot.name!r} has nq={robot.nq}, "
            f"nv={robot.nv}"
        )
    if dataset.joint_names is not None and list(dataset.joint_names) != list(robot.dof_names):
        if set(dataset.joint_names) == set(robot.dof_names):
            raise DataError(
                f"the data's joints are in the order {list(dataset.joint_names)} but robot "
                f"{robot.name!r} expects {list(robot.dof_names)}"
            )
        extra = [n for n in dataset.joint_names if n not in robot.dof_names]
        raise DataError(
            f"the data name joints {extra} that robot {robot.name!r} does not have "
            f"(its joints: {list(robot.dof_names)})"
        )
    check_position_limits(dataset, robot)


#: Measured positions may pass a position limit by this share of the joint's range.
LIMIT_MARGIN = 0.05


def check_position_limits(dataset: Dataset, robot, margin: float = LIMIT_MARGIN) -> None:
    """Raise :class:`DataError` if a position leaves the robot's (set) limits by more than
    ``margin`` times the joint's range, naming the joint, the sample and the limits."""
    q = dataset.q
    bad = _far_outside(robot, q.min(axis=0), q.max(axis=0), margin)
    if bad is not None:
        i, lo, hi, low_side = bad
        k = int(np.argmin(q[:, i]) if low_side else np.argmax(q[:, i]))
        raise DataError(
            f"q column {i} = {q[k, i]:.4g} at sample {k} (t = {dataset.t[k]:.4g} s) is "
            f"outside the position limits [{lo:.4g}, {hi:.4g}] of robot "
            f"{robot.name!r}: wrong robot, units or zero offset?"
        )


def check_position_range(robot, q_min, q_max, label: str, margin: float = LIMIT_MARGIN) -> None:
    """:func:`check_position_limits` on the per-column extremes of a streamed file.

    Positions slightly past a limit (within ``margin`` of the range) are left to the
    quality summary's warnings; farther out the file is refused.
    """
    bad = _far_outside(robot, np.asarray(q_min, float), np.asarray(q_max, float), margin)
    if bad is not None:
        i, lo, hi, low_side = bad
        value = q_min[i] if low_side else q_max[i]
        raise DataError(
            f"{label}: q column {i} reaches {value:.4g}, outside the position limits "
            f"[{lo:.4g}, {hi:.4g}] of robot {robot.name!r}: wrong robot, units or zero offset?"
        )


def _far_outside(robot, q_min: np.ndarray, q_max: np.ndarray, margin: float):
    """``(column, lower, upper, below?)`` of the first column far outside its limits, or None."""
    lo, hi = robot.lower, robot.upper  # [rad or m], shape (nq,)
    for i in np.flatnonzero(bounded_range(lo, hi)):
        slack = margin * (hi[i] - lo[i])
        below, above = lo[i] - slack - q_min[i], q_max[i] - hi[i] - slack
        if max(below, above) > 0:
            return int(i), float(lo[i]), float(hi[i]), bool(below >= above)
    return None
