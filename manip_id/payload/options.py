"""The settings of payload and drive-gain identification, one frozen dataclass per entry point.

``identify_payload(..., options=PayloadOptions(method="ols"))`` and the shorthand
``identify_payload(..., method="ols")`` (keyword fields of the options) are the same
call: :func:`resolve_options` merges the keywords into the options and refuses a
name that is no field.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any, TypeVar

from ..errors import InputError
from ..identifiability import BaseParameters
from ..robot.regressor import DEFAULT_CHUNK

#: Methods of :func:`~manip_id.payload.identify_payload`.
PAYLOAD_METHODS: tuple[str, ...] = ("wls", "ols")
#: Methods of :func:`~manip_id.payload.identify_drive_gains`.
GAIN_METHODS: tuple[str, ...] = ("ml", "ols", "wls", "tls")


@dataclass(frozen=True)
class PayloadOptions:
    """How :func:`~manip_id.payload.identify_payload` solves.

    Attributes
    ----------
    method
        str
        "wls" (default: each joint weighted by its residual variance, re-estimated from
        the residuals) or "ols". Noise that differs from joint to joint (the rule on a
        real arm) leaves the OLS standard deviations wrong (mass: predicted 1.1 g,
        observed 2.0 g in ``experiments/payload.py``) and its estimate 2-30 times less
        precise; WLS's are right.
    consistent
        bool
        Constrain the payload's pseudo-inertia to be positive definite.
    velocity_deadband
        float or None
        Leave out the rows of joint j where ``|dq_j| <`` this [rad/s].
    chunk
        int
        Samples per regressor chunk.
    base
        BaseParameters or None
        The robot's base parametrization (default: its structural analysis).
    scheduler
        object
        None (accumulate in this process; nothing of Dask is imported), or a Dask
        scheduler as in :func:`manip_id.execution.open_backend` (``"local[:N]"``,
        ``"tcp://HOST:PORT"``, a scheduler JSON file, a ``distributed.Client``): each
        run is one task (runs and their blocks must pickle), the sums are added in a
        tree on the cluster and the solve happens here; the result equals the local one
        to round-off.
    """

    method: str = "wls"
    consistent: bool = False
    velocity_deadband: float | None = None
    chunk: int = DEFAULT_CHUNK
    base: BaseParameters | None = None
    scheduler: Any = None


@dataclass(frozen=True)
class DriveGainOptions:
    """How :func:`~manip_id.payload.identify_drive_gains` solves.

    Attributes
    ----------
    method
        str
        "ml" (default: maximum likelihood under current noise, Gauss-Newton from the OLS
        start), "ols" (ordinary least squares with the known columns on the right-hand
        side, Gautier & Briot), "wls" (the same, each joint weighted by its residual
        variance) or "tls" (total least squares of the scaled system). OLS/WLS/TLS hold
        the noisy currents in the regressor: they shrink a gain by about
        ``sigma_i^2 / mean(i^2)`` and their standard deviations are optimistic where a
        joint's current is small against its noise; ML is not (and a gain of theirs
        more than :data:`~manip_id.payload.gains.ML_DISAGREEMENT` of its standard
        deviations from the ML one is named in a warning).
    velocity_deadband, chunk, base, scheduler
        As in :class:`PayloadOptions`.
    """

    method: str = "ml"
    velocity_deadband: float | None = None
    chunk: int = DEFAULT_CHUNK
    base: BaseParameters | None = None
    scheduler: Any = None


_Options = TypeVar("_Options", PayloadOptions, DriveGainOptions)


def resolve_options(cls: type[_Options], options: _Options | None, given: dict) -> _Options:
    """``options`` (default ``cls()``) with the keyword fields ``given`` replaced.

    Raises
    ------
    InputError
        ``options`` is not a ``cls``, or a keyword names no field of ``cls``.
    """
    if options is None:
        options = cls()
    elif not isinstance(options, cls):
        raise InputError(f"options must be a {cls.__name__}, got {type(options).__name__}")
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(given) - names)
    if unknown:
        raise InputError(
            f"unexpected keyword(s) {unknown}: the settings are the fields of {cls.__name__} "
            f"({', '.join(sorted(names))})"
        )
    return replace(options, **given) if given else options
