"""Input validation shared by every boundary of the package."""

from __future__ import annotations

try:
    import resource
except ImportError:  # not a Unix
    resource = None  # type: ignore[assignment]

import numpy as np

from .errors import InputError


def as_float_array(x, name: str, ndim: int | tuple[int, ...] | None = None) -> np.ndarray:
    """``x`` as a C-contiguous float64 array, with a clear error otherwise (complex refused)."""
    if np.iscomplexobj(x):
        raise InputError(
            f"{name} holds complex numbers (dtype {np.asarray(x).dtype}); expected real values"
        )
    try:
        arr = np.asarray(x, dtype=np.float64)
        if not arr.flags.c_contiguous:
            arr = np.ascontiguousarray(arr)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be numeric array-like, got {type(x).__name__}") from exc
    if ndim is not None:
        allowed = (ndim,) if isinstance(ndim, int) else ndim
        if arr.ndim not in allowed:
            raise InputError(
                f"{name} must have {' or '.join(map(str, allowed))} dimensions, "
                f"got {name}.shape={arr.shape}"
            )
    return arr


def check_finite(arr: np.ndarray, name: str, columns=None) -> None:
    """Raise :class:`InputError` naming the first sample (row) and column holding NaN or Inf."""
    if np.isfinite(arr).all():
        return
    bad = np.argwhere(~np.isfinite(arr))[0]
    value = arr[tuple(bad)]
    if arr.ndim == 1:
        raise InputError(f"{name} holds {value} at sample {bad[0]}")
    col = int(bad[-1])
    label = columns[col] if columns is not None and col < len(columns) else f"column {col}"
    raise InputError(f"{name} holds {value} at sample {bad[0]}, {label}")


def as_real(x, name: str, *, minimum: float | None = None, unit: str = "") -> float:
    """``x`` as a finite float (at least ``minimum``), or :class:`InputError` naming ``name``."""
    where = f" [{unit}]" if unit else ""
    if isinstance(x, bool | str | bytes) or np.iscomplexobj(x):
        raise InputError(f"{name} must be a real number{where}, got {x!r}")
    try:
        value = float(x)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a real number{where}, got {x!r}") from exc
    if not np.isfinite(value):
        raise InputError(f"{name} must be finite{where}, got {value}")
    if minimum is not None and value < minimum:
        raise InputError(f"{name} must be >= {minimum:g}{where}, got {value:g}")
    return value


def as_int(x, name: str, *, minimum: int | None = None) -> int:
    """``x`` as an int (at least ``minimum``); floats only when integral (3.0 but not 3.5)."""
    if isinstance(x, bool) or not isinstance(x, int | np.integer | float | np.floating):
        raise InputError(f"{name} must be an integer, got {x!r}")
    if isinstance(x, float | np.floating) and not (np.isfinite(x) and float(x).is_integer()):
        raise InputError(f"{name} must be an integer, got {x!r}")
    value = int(x)
    if minimum is not None and value < minimum:
        raise InputError(f"{name} must be >= {minimum}, got {value}")
    return value


def random_generator(seed, name: str = "seed") -> np.random.Generator:
    """``numpy.random.default_rng(seed)`` for a seed in [0, 2**63), or a :class:`InputError`.

    A :class:`numpy.random.Generator` or ``SeedSequence`` passes through NumPy as is.
    """
    if isinstance(seed, np.random.Generator | np.random.SeedSequence):
        return np.random.default_rng(seed)
    value = as_int(seed, name, minimum=0)
    if value >= 2**63:
        raise InputError(f"{name} must be below 2**63, got {value}")
    return np.random.default_rng(value)


def memory_budget(share: float = 0.5, cap: int | None = None) -> int:
    """``share`` of the memory available now [bytes] (at most ``cap``): what one job may take.

    Available is the system's free memory, or less under an address-space limit
    (``RLIMIT_AS``, ``ulimit -v``: its soft limit minus the address space in use)."""
    import psutil  # optional heavy library, asked only when a memory budget is needed

    available = psutil.virtual_memory().available  # [bytes]
    if resource is not None:
        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft != resource.RLIM_INFINITY:
            used = psutil.Process().memory_info().vms  # [bytes] of address space
            available = min(available, max(int(soft) - used, 0))
    budget = int(share * available)
    return budget if cap is None else min(budget, int(cap))


#: Sane magnitudes of measured fields: name -> (unit, largest |value|). Beyond them a
#: value is a unit or scaling mistake (or garbage), not a measurement.
MEASURED_LIMITS: dict[str, tuple[str, float]] = {
    "t": ("s", 1e11),  # 3000 years: stamps in seconds since 1970 (1.8e9 s) pass
    "q": ("rad or m", 1e4),
    "dq": ("rad/s or m/s", 1e4),
    "ddq": ("rad/s^2 or m/s^2", 1e7),
    "tau": ("N m or N", 1e6),
    "temp": ("degC or K", 1e4),
}
#: Below this, every value of a field is "all tiny": squares underflow double precision.
TINY = 1e-150


def check_magnitude(
    arr: np.ndarray,
    name: str,
    columns=None,
    offset: int = 0,
    error: type = InputError,
    kind: str | None = None,
) -> None:
    """Raise :class:`InputError` unless the finite array ``arr`` has sane magnitudes.

    ``name`` selects the unit and the limit in :data:`MEASURED_LIMITS` (``tau`` is
    refused beyond 1e6 [N m]); the message names the field, the first sample
    (``offset + k``) and the column. A field whose largest magnitude is non-zero but
    below :data:`TINY` (e.g. torques of 1e-300) is refused too: nothing can be
    estimated from it. ``kind`` names the field when ``name`` is a longer label
    (``"validation tau"``). Unknown fields are not checked. Raises ``error`` (an
    :class:`InputError` by default; readers pass :class:`~manip_id.errors.DataError`).
    """
    kind = name if kind is None else kind  # the field whose limits apply
    if kind not in MEASURED_LIMITS or arr.size == 0:
        return
    unit, limit = MEASURED_LIMITS[kind]
    with np.errstate(invalid="ignore"):
        mag = np.abs(arr)
        big = mag > limit  # NaN and Inf are check_finite's business
    if big.any():
        bad = np.argwhere(big)[0]
        where = f"sample {offset + int(bad[0])}"
        if arr.ndim > 1:
            col = int(bad[-1])
            label = columns[col] if columns is not None and col < len(columns) else f"column {col}"
            where += f", {label}"
        raise error(
            f"{name} = {arr[tuple(bad)]:.3g} [{unit}] at {where} is beyond any plausible "
            f"value (|{name}| <= {limit:g} [{unit}]); check the units and scaling"
        )
    finite = mag[np.isfinite(mag)]
    top = float(finite.max()) if finite.size else 0.0
    if 0.0 < top < TINY:
        raise error(
            f"{name} is all tiny: max |{name}| = {top:.3g} [{unit}] (below {TINY:g}); "
            "check the units and scaling"
        )


def positive_vector(x, name: str, n: int, unit: str = "") -> np.ndarray:
    """A positive vector of shape (n,) from a scalar or an (n,) array-like."""
    arr = as_float_array(x, name, ndim=(0, 1))
    arr = np.broadcast_to(arr, (n,)).copy() if arr.ndim == 0 else arr.copy()
    if arr.shape != (n,):
        raise InputError(f"{name} must be a scalar or shape ({n},), got {name}.shape={arr.shape}")
    check_finite(arr, name)
    if np.any(arr <= 0):
        where = f" [{unit}]" if unit else ""
        raise InputError(
            f"{name} must be positive{where}, got {arr.min():g} at index {int(np.argmin(arr))}"
        )
    return arr


def spd_gain(x, name: str, n: int, unit: str = "") -> np.ndarray:
    """A gain given as a scalar, a vector (n,) or a symmetric positive definite (n, n) matrix.

    Returns the positive diagonal, shape (n,), for a scalar or a vector, and the
    checked matrix, shape (n, n), otherwise.
    """
    arr = as_float_array(x, name, ndim=(0, 1, 2))
    if arr.ndim < 2:
        return positive_vector(arr, name, n, unit)
    if arr.shape != (n, n):
        raise InputError(
            f"{name} must be a scalar, shape ({n},) or ({n}, {n}), got {name}.shape={arr.shape}"
        )
    check_finite(arr, name)
    asym = np.abs(arr - arr.T).max()
    if asym > 1e-12 * max(np.abs(arr).max(), 1e-300):
        raise InputError(
            f"{name} must be symmetric positive definite, but it is not symmetric "
            f"(max |G - G^T| = {asym:.3g})"
        )
    low = np.linalg.eigvalsh(arr).min()
    if low <= 0:
        raise InputError(
            f"{name} must be symmetric positive definite, but its smallest eigenvalue is {low:.3g}"
        )
    return arr.copy()


def spd_matrix(x, name: str, n: int, unit: str = "") -> np.ndarray:
    """:func:`spd_gain` as a full (n, n) matrix."""
    g = spd_gain(x, name, n, unit)
    return np.diag(g) if g.ndim == 1 else g
