"""``manip-id warmup``: compile the numba kernels ahead, so a user's first real run is as
fast as the next one.

The kernels (the batched regressor, the momentum regressor, the zero-phase low-pass, the
CSV reader) are compiled on first use and cached on disk; ``warmup`` runs identify on a
small simulated log in the formats and paths a real run takes, so that every kernel is
compiled and cached once (``make demo`` and ``make test`` run it).
"""

from __future__ import annotations

from ._common import command


def register(sub) -> None:
    p = sub.add_parser(
        "warmup",
        help="compile the numba kernels ahead (once per install; later runs load them)",
        description="Compile and cache the numba kernels (regressor, momentum regressor, "
        "low-pass filter, CSV reader) by identifying a small simulated log, so that the "
        "first real run pays no compilation. Without numba there is nothing to compile.",
    )
    p.add_argument("--quiet", action="store_true", help="print nothing but errors and warnings")
    p.set_defaults(func=command("manip_id.cli._warmup"))
