"""Resources estimated before allocation: every large array is sized and refused up front.

A command given a huge size (``rank --samples 1e9``, ``adapt --duration 1e9``, a profile
with ``harmonics = 1e12``, a 300-joint chain) must say so in one line before it
allocates, not run out of memory. Each site computes its estimate [bytes] from the
shapes it is about to allocate (float64: 8 bytes a value) and calls
:func:`check_memory`, which compares it with :data:`MEMORY_SHARE` of the memory
available now; counts without a natural byte size (harmonics, the relative size of a
perturbation) have fixed limits here.

The error is :class:`~manip_id.errors.ResourceError` (an InputError: exit status 2 on
the command line), whose message gives the estimate and the limit.
"""

from __future__ import annotations

from ._checks import memory_budget
from .errors import ResourceError

#: Share of the memory available now [-] that one allocation may take.
MEMORY_SHARE = 0.5
#: Bytes of one float64 value.
FLOAT = 8
#: The largest buffer [bytes] of a dense regressor chunk (samples x nv x p): beyond it the
#: model is too large for the dense per-sample regressor (a chain of some 300 joints).
REGRESSOR_BUFFER_LIMIT = 512 * 2**20
#: Allocations below this [bytes] are not checked against the memory available.
SMALL = 64 * 2**20
#: The most time steps of one closed-loop run (duration x rate x substeps): at some
#: 10 us a step, about 20 minutes.
MAX_STEPS = 10**8
#: The most Fourier harmonics per joint of an excitation trajectory.
MAX_HARMONICS = 1000
#: Largest payload mass accepted [kg] (a manipulator's payload, not a building).
MAX_PAYLOAD_MASS = 1e4
#: The magnitudes a torque scale may have: from the logged unit (mN m, A, counts) to N m.
TORQUE_SCALE_RANGE = (1e-9, 1e9)


def gib(n_bytes: float) -> str:
    """``n_bytes`` in GiB with 3 significant digits (``"1.49e+03 GiB"``)."""
    return f"{n_bytes / 2**30:.3g} GiB"


def check_memory(need: float, what: str, hint: str = "") -> None:
    """Raise :class:`~manip_id.errors.ResourceError` if ``need`` [bytes] would not fit.

    Parameters
    ----------
    need : float
        The estimated peak memory of the allocation [bytes].
    what : str
        What needs it, e.g. ``"a simulation of 2e+11 samples of 1 joints needs"``.
    hint : str
        How to ask for less (``"shorten the duration or lower the rate"``).
    """
    available = memory_budget(1.0)  # [bytes] available now
    if need > MEMORY_SHARE * available:
        raise ResourceError(
            f"{what} about {gib(need)}, more than {MEMORY_SHARE:.0%} of the "
            f"{gib(available)} available" + (f"; {hint}" if hint else "")
        )


def check_regressor_buffer(chunk: int, nv: int, p: int) -> None:
    """Refuse a dense regressor chunk of ``chunk`` samples above :data:`REGRESSOR_BUFFER_LIMIT`.

    The buffer is ``chunk * nv * p`` float64 values (samples x joints x parameters).
    """
    need = FLOAT * float(chunk) * nv * p
    if need > REGRESSOR_BUFFER_LIMIT:
        raise ResourceError(
            f"the regressor of {nv} joints and {p} parameters needs about {gib(need)} for "
            f"{chunk} samples, above the limit of {gib(REGRESSOR_BUFFER_LIMIT)}: the model "
            "is too large for manip-id (split the chain or lock joints)"
        )
    if need > SMALL:  # (asking the system costs more than a small buffer)
        check_memory(need, f"the regressor of {nv} joints and {p} parameters needs")


#: Bytes of one Pinocchio ``Data`` per nv^3 [bytes]: its second-order derivative tensors
#: (``d2tau_dqdq`` and three more, nv x nv x nv each) outgrow everything else (measured:
#: 36 MiB at nv = 100, 111 MiB at nv = 150).
DATA_BYTES_PER_NV3 = 4 * FLOAT
#: The largest Pinocchio ``Data`` [bytes] a robot may need (nv of about 200): a robot holds
#: several (its own, a pool's, each worker's), and a model this large is refused by the
#: regressor's limit anyway (:data:`REGRESSOR_BUFFER_LIMIT`), after its Data were built.
DATA_LIMIT = 256 * 2**20


def check_model_size(nv: int) -> None:
    """Refuse a model of ``nv`` joints whose Pinocchio ``Data`` would exceed
    :data:`DATA_LIMIT`, before any is built (a 300-joint chain's takes 0.8 GiB)."""
    need = DATA_BYTES_PER_NV3 * float(nv) ** 3
    if need > DATA_LIMIT:
        raise ResourceError(
            f"a model of {nv} joints needs about {gib(need)} for each Pinocchio Data (its "
            f"second-order derivative tensors hold 4 nv^3 values), above the limit of "
            f"{gib(DATA_LIMIT)}: the model is too large for manip-id (split the chain or lock "
            "joints)"
        )


def check_count(value: float, limit: float, what: str, unit: str = "") -> None:
    """Refuse ``value`` above ``limit`` (a count or size with a fixed bound), naming both."""
    if value > limit:
        raise ResourceError(f"{what} is {value:.3g}{unit}, above the limit of {limit:.3g}{unit}")


__all__ = [
    "FLOAT",
    "MAX_HARMONICS",
    "MAX_PAYLOAD_MASS",
    "MAX_STEPS",
    "MEMORY_SHARE",
    "REGRESSOR_BUFFER_LIMIT",
    "TORQUE_SCALE_RANGE",
    "check_count",
    "check_memory",
    "check_regressor_buffer",
    "gib",
]
