"""Options of identification, one frozen dataclass per concern.

- :class:`PreprocessOptions`: how each data file is read and preprocessed.
- :class:`ConsistentOptions`: a physically consistent estimate (solver, prior, weight).
- :class:`OnlineOptions`: the online laws (RLS, gradient).
- :class:`ModelOptions`: the acceleration-free models (energy, momentum).
- :class:`RunOptions`: how the work is executed (chunk, workers, scheduler, progress).
- :class:`UncertaintyOptions`: the covariance of the estimate ("auto", "white", "hac";
  defined with its estimators in :mod:`manip_id.estimators.uncertainty`).

and :data:`METHODS`, the one table of estimation methods.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from .._checks import as_int
from ..datasets.stream import READ_CHUNK
from ..errors import InputError
from ..estimators.consistent import DEFAULT_PRIOR_WEIGHT
from ..estimators.consistent import check_options as check_consistent_options
from ..estimators.consistent.bounds import BoundsOptions
from ..estimators.uncertainty import UncertaintyOptions
from ..execution import AUTO, check_workers, resolve_workers
from ..robot.regressor import DEFAULT_CHUNK
from ..signals import DEFAULT_BLOCK, DEFAULT_ORDER

#: The estimation methods: name -> what it is. ``ols`` and ``wls`` solve from the
#: accumulated sums (any partition, any back-end); the online laws need the samples in order.
METHODS: dict[str, str] = {
    "ols": "ordinary least squares",
    "wls": "least squares weighted by per-joint noise variances from the OLS residuals",
    "rls": "one pass of recursive least squares",
    "gradient": "one pass of the normalized gradient law",
}
#: The methods that solve from sums (accumulated anywhere, reduced in a tree).
LEAST_SQUARES: tuple[str, ...] = ("ols", "wls")
#: The online laws.
ONLINE: tuple[str, ...] = ("rls", "gradient")
#: The models of :func:`~manip_id.identification.identify`: "dynamic" uses
#: ``tau = Y(q, dq, ddq) theta``; "energy" and "momentum" need no accelerations.
MODEL_NAMES: tuple[str, ...] = ("dynamic", "energy", "momentum")


def check_method(method: str, allowed=tuple(METHODS), what: str = "method") -> str:
    """``method`` if it is one of ``allowed``, else an :class:`InputError` naming them."""
    if method not in allowed:
        raise InputError(f"{what} must be one of {list(allowed)}, got {method!r}")
    return method


def check_least_squares(method: str, who: str) -> str:
    """``method`` if it solves from sums (:data:`LEAST_SQUARES`), else an :class:`InputError`
    saying that ``who`` (e.g. "data in blocks are solved by") takes only those."""
    check_method(method)
    if method not in LEAST_SQUARES:
        raise InputError(f"{who} least squares ({', '.join(LEAST_SQUARES)}), got {method!r}")
    return method


def options_from(cls, value, what: str):
    """``value`` as ``cls``: None (the defaults), an instance, or a mapping of its fields."""
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    if isinstance(value, Mapping):
        known = [f.name for f in fields(cls)]
        unknown = [k for k in value if k not in known]
        if unknown:
            raise InputError(f"unknown {what} option(s) {unknown}: expected some of {known}")
        return cls(**value)
    raise InputError(
        f"{what} must be {cls.__name__}, a dict of its fields or None, got {type(value).__name__}"
    )


@dataclass(frozen=True)
class PreprocessOptions:
    """How each file is read and preprocessed (one set for every file of a run).

    Attributes
    ----------
    cutoff
        low-pass cut-off [Hz]; None: :data:`~manip_id.signals.DEFAULT_CUTOFF`
        when the file has no ddq, no filtering when it has; ``"auto"``: chosen per file
        from its velocity power spectrum (:mod:`manip_id.signals.bandwidth`).
    order
        Butterworth order of the one-way filter.
    trim
        seconds dropped at each end of each file (window); None: the filter's
        edge transient.
    decimate
        keep every D-th sample after filtering.
    rate
        resampling rate [Hz]; None: the file's mean rate when its steps jitter.
    velocity
        "measured" (filter the logged dq) or "differentiate" (dq from q).
    filter_torque
        low-pass the torques too.
    torque_scale
        one gain, or one per joint (nv): ``tau_j <- G_j tau_j``
        (drive gains [N m/A] from currents, gear ratios); None: 1.
    velocity_deadband
        eps [rad/s or m/s]; the rows of joint j with
        ``|dq_j| < eps`` are left out of the fit and of the error figures.
    drop_bad_rows
        drop (and count) rows holding NaN/Inf instead of refusing the file.
    read_chunk
        rows per block read from the file.
    block
        rows per block of the blocked preprocessing.
    """

    cutoff: float | str | None = None
    order: int = DEFAULT_ORDER
    trim: float | None = None
    decimate: int = 1
    rate: float | None = None
    velocity: str = "measured"
    filter_torque: bool = True
    torque_scale: float | tuple[float, ...] | None = None
    velocity_deadband: float | None = None
    drop_bad_rows: bool = False
    read_chunk: int = READ_CHUNK
    block: int = DEFAULT_BLOCK

    def __post_init__(self):
        ts = self.torque_scale
        if ts is not None and not np.isscalar(ts):
            object.__setattr__(self, "torque_scale", tuple(float(g) for g in np.ravel(ts)))
        eps = self.velocity_deadband
        if eps is not None and not (np.isfinite(eps) and eps > 0):
            raise InputError(f"the velocity deadband must be positive [rad/s], got {eps}")
        if int(self.decimate) != self.decimate or self.decimate < 1:
            raise InputError(f"decimate must be a positive integer, got {self.decimate}")
        if self.trim is not None and not self.trim >= 0:
            raise InputError(f"trim must be >= 0 seconds, got {self.trim}")
        if isinstance(self.cutoff, str):
            if self.cutoff != "auto":
                raise InputError(
                    f"the cut-off must be 'auto' or a frequency [Hz], got {self.cutoff!r}"
                )
        elif self.cutoff is not None and not self.cutoff > 0:
            raise InputError(f"the cut-off must be positive [Hz], got {self.cutoff}")

    def preprocesses(self, has_ddq: bool) -> bool:
        """Whether a file with (or without) ddq is filtered and differentiated."""
        return (
            not has_ddq
            or self.cutoff is not None
            or self.decimate != 1
            or self.trim is not None
            or self.rate is not None
        )

    def to_dict(self) -> dict:
        """The fields as a dict."""
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True)
class ConsistentOptions:
    """A physically consistent estimate (:mod:`manip_id.estimators.consistent`).

    Every body's pseudo-inertia positive definite, ``Ia, fv, fc >= 0``, the same
    (weighted) residual through the base parameters, the null space filled by the prior.

    Attributes
    ----------
    enabled : bool
        Estimate consistent standard parameters (``ols`` / ``wls`` only).
    solver : str
        "sdp" (cvxpy + Clarabel) or "logchol" (log-Cholesky Levenberg-Marquardt).
    prior : str
        "nominal" (the URDF parameters, log-det divergence) or "none".
    prior_weight : float
        Weight of the prior against the fit, in standard deviations [-].
    bounds : str
        "geometry" (each body's mass inside a bounding ellipsoid of its link) or "none"
        (:mod:`manip_id.estimators.consistent.bounds`).
    mass_range : tuple of float or None
        ``(lo, hi)``: each body's mass within ``[lo, hi]`` times its nominal mass [-].
    total_mass : tuple of float or None
        ``(kg, tol)``: the moving bodies' total mass within ``kg +- tol`` [kg].
    """

    enabled: bool = True
    solver: str = "sdp"
    prior: str = "nominal"
    prior_weight: float = DEFAULT_PRIOR_WEIGHT
    bounds: str = "geometry"
    mass_range: tuple[float, float] | None = None
    total_mass: tuple[float, float] | None = None

    def __post_init__(self):
        if self.prior_weight is None:  # the default weight
            object.__setattr__(self, "prior_weight", DEFAULT_PRIOR_WEIGHT)
        if self.enabled:
            check_consistent_options(self.solver, self.prior, self.prior_weight)
            self.bound_options()  # checks them

    def bound_options(self) -> BoundsOptions:
        """The plausibility bounds of the estimate, as the solver takes them."""
        return BoundsOptions(self.bounds, mass_range=self.mass_range, total_mass=self.total_mass)

    @classmethod
    def from_value(cls, value) -> ConsistentOptions:
        """None or False (no consistent estimate), True (the defaults), an instance or a
        mapping of its fields."""
        if value is None or value is False:
            return cls(enabled=False)
        if value is True:
            return cls()
        return options_from(cls, value, "consistent")


@dataclass(frozen=True)
class ModelOptions:
    """The acceleration-free models (:mod:`manip_id.models`).

    Attributes
    ----------
    name : str
        "dynamic" (``tau = Y(q, dq, ddq) theta``, needs ``ddq``), "energy" or "momentum".
    window_length : float or None
        Energy interval / momentum row spacing [s] (default
        :data:`manip_id.models.DEFAULT_WINDOW`); the momentum filter's bandwidth is
        ``3 / window_length`` [rad/s].
    dt : float or None
        Sample time [s] of uniformly sampled data (the models' integration step);
        None: 1 for arrays, the data's mean step for datasets.
    """

    name: str = "dynamic"
    window_length: float | None = None
    dt: float | None = None

    def __post_init__(self):
        check_method(self.name, MODEL_NAMES, "model")
        if self.window_length is not None and not float(self.window_length) > 0:
            raise InputError(f"window_length must be positive [s], got {self.window_length}")

    @classmethod
    def from_value(cls, value) -> ModelOptions:
        """None (dynamic), a model name, an instance or a mapping of its fields."""
        if isinstance(value, str):
            return cls(name=value)
        return options_from(cls, value, "model")


@dataclass(frozen=True)
class RunOptions:
    """How the work is executed (never what is computed: results equal to round-off).

    Attributes
    ----------
    chunk : int
        Samples per regressor chunk.
    workers : int or "auto"
        Forked processes for least squares (contiguous parts, or one file per task).
        ``"auto"`` (default): one per core this process may use for inputs of at least
        :data:`~manip_id.execution.FORK_MIN_SAMPLES` samples, else one
        (:func:`~manip_id.execution.resolve_workers`); an iterable of blocks, whose size
        is not known in advance, is accumulated in this process.
    scheduler : str, distributed.Client or None
        A Dask scheduler (:func:`manip_id.execution.open_backend`): each part or file is
        one task and the sums are added in a tree on the cluster.
    progress : callable or None
        Called as ``progress(done, total)`` as the work goes by.
    echo : callable or None
        Called as ``echo(text)`` with what a file run finds before the fit (the pre-fit
        audit's table, each file's data quality, the temperature reference, the friction
        selection), as it finds it; the same texts are in the result. None: silent.
    verbose : bool
        Echo the full pre-fit audit table and each file's data quality too (else the
        audit's findings only, and the per-file quality stays in the result).
    """

    chunk: int = DEFAULT_CHUNK
    workers: int | str = AUTO
    scheduler: Any = None
    progress: Callable[[int, int], None] | None = None
    echo: Callable[[str], None] | None = None
    verbose: bool = False

    def say(self, text: str) -> None:
        """``echo(text)`` when there is an echo."""
        if self.echo is not None:
            self.echo(text)

    def __post_init__(self):
        if as_int(self.chunk, "chunk") < 1:
            raise InputError(f"chunk must be a positive number of samples, got {self.chunk}")
        object.__setattr__(self, "workers", check_workers(self.workers))

    def workers_for(self, n_samples: int | None) -> int:
        """The forked processes of a run over ``n_samples`` samples (None: unknown) [-]."""
        return resolve_workers(self.workers, n_samples)

    @classmethod
    def from_value(cls, value) -> RunOptions:
        """None (the defaults), an instance or a mapping of its fields."""
        return options_from(cls, value, "run")


@dataclass(frozen=True)
class OnlineOptions:
    """Options of the online laws of :func:`identify` (``method="rls"`` or ``"gradient"``).

    ``None`` means the default. The RLS-only options (``P0``, ``forgetting``, ``p_min``,
    ``p_max``) are refused with the gradient law, and the gradient-only ones (``gamma``,
    ``normalized``) with RLS (:class:`~manip_id.estimators.RLSEstimator`,
    :class:`~manip_id.estimators.GradientEstimator`).

    Attributes
    ----------
    theta0
        initial estimate, shape (r,) [units of the base parameters]; default zeros
    record_every
        keep every k-th estimate in the history (0: none); default
        ``max(1, N // 1000)``, the record the convergence check reads
    bounds
        ``(lower, upper)`` box on the estimate, shapes (r,); default none
    t0
        time of the first sample [s]
    dt
        sample time [s] given to the law (the gradient law's Euler step); default 1
    P0
        RLS initial covariance: scalar (times I), (r,) or (r, r); default 1e6
    forgetting
        RLS forgetting factor lambda in (0, 1]; default 1 (none)
    p_min, p_max
        RLS bounds on trace(P)
    gamma
        gradient gain: scalar, (r,) or (r, r) SPD; default 1
    normalized
        normalized gradient law; default True
    """

    theta0: ArrayLike | None = None
    record_every: int | None = None
    bounds: tuple[ArrayLike, ArrayLike] | None = None
    t0: float = 0.0
    dt: float | None = None
    P0: ArrayLike | None = None
    forgetting: float | None = None
    p_min: float | None = None
    p_max: float | None = None
    gamma: ArrayLike | None = None
    normalized: bool | None = None

    #: options that only one law takes
    RLS_ONLY: ClassVar[tuple[str, ...]] = ("P0", "forgetting", "p_min", "p_max")
    GRADIENT_ONLY: ClassVar[tuple[str, ...]] = ("gamma", "normalized")

    @classmethod
    def from_value(cls, online: OnlineOptions | dict | None) -> OnlineOptions:
        """``online`` as options: None (the defaults), OnlineOptions, or a dict of its fields.

        Raises
        ------
        InputError
            a key that is not a field, or a value that is neither.
        """
        return options_from(cls, online, "online")

    def check_method(self, method: str) -> None:
        """Raise :class:`InputError` for an option the law ``method`` does not take."""
        other = self.GRADIENT_ONLY if method == "rls" else self.RLS_ONLY
        given = [k for k in other if getattr(self, k) is not None]
        if given:
            law = "RLS" if method == "rls" else "the gradient law"
            raise InputError(f"online option(s) {given} do not apply to {law} (method={method!r})")


@dataclass(frozen=True)
class SolveSettings:
    """How :func:`~manip_id.identification.solve` turns a problem into its result.

    Attributes
    ----------
    method : str
        "ols", "wls", or the online law ("rls", "gradient") whose pass the problem holds.
    consistent : ConsistentOptions or None
        A physically consistent estimate ("ols" / "wls").
    minimum_norm : bool
        Solve rank-deficient data with the minimum-norm solution instead of raising.
    uncertainty : UncertaintyOptions or None
        The covariance behind ``std`` (None: ``"auto"``).
    """

    method: str = "wls"
    consistent: ConsistentOptions | None = None
    minimum_norm: bool = False
    uncertainty: UncertaintyOptions | None = None


__all__ = [
    "SolveSettings",
    "LEAST_SQUARES",
    "METHODS",
    "MODEL_NAMES",
    "ONLINE",
    "ConsistentOptions",
    "ModelOptions",
    "OnlineOptions",
    "PreprocessOptions",
    "RunOptions",
    "UncertaintyOptions",
    "check_least_squares",
    "check_method",
    "options_from",
]
