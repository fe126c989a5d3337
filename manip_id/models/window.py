"""The window of the acceleration-free models, chosen from the data when not given.

The energy model gives one scalar row per window of ``w`` sampling intervals, the
momentum model ``nv`` rows every ``w`` samples; ``N`` samples give::

    rows(w) = floor((N - 1) / w) * rows_per_window

The chosen window is the default one (:data:`~manip_id.models.DEFAULT_WINDOW`, 0.2 s)
when it gives at least ``rows_per_parameter * n_base`` rows (default
:data:`ROWS_PER_PARAMETER` = 5 rows per base parameter), else the longest window
that does::

    w = floor((N - 1) / ceil(rows_per_parameter n_base / rows_per_window))

(rounded down to even for the energy model's Simpson rule, at least 2 intervals, 1 for
momentum). Longer windows average more noise per row; shorter ones give more rows: the
rule keeps the default where the data allow it and shortens it only as far as the
least-squares fit needs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import InputError
from .energy import DEFAULT_WINDOW

#: Rows per base parameter the chosen window must give at least.
ROWS_PER_PARAMETER = 5


@dataclass(frozen=True)
class WindowChoice:
    """The window of an energy or momentum run.

    Attributes
    ----------
    length : float
        Window length [s] (``samples * dt``).
    samples : int
        Sampling intervals per window.
    rows : int
        Rows the data give with it.
    chosen : bool
        True when chosen from the data, False when given by the user.
    rule : str
        Why, in words (printed by the CLI, saved in the JSON).
    """

    length: float
    samples: int
    rows: int
    chosen: bool
    rule: str

    def to_dict(self) -> dict:
        """JSON-ready fields."""
        return {
            "length": self.length,
            "samples": self.samples,
            "rows": self.rows,
            "chosen": self.chosen,
            "rule": self.rule,
        }


def choose_window(
    n_samples: int,
    dt: float,
    n_base: int,
    *,
    rows_per_window: int = 1,
    even: bool = True,
    rows_per_parameter: int = ROWS_PER_PARAMETER,
) -> WindowChoice:
    """The window (module docstring) for ``n_samples`` samples every ``dt`` [s].

    Parameters
    ----------
    n_samples : int
        Samples N of the training data.
    dt : float
        Sample time [s].
    n_base : int
        Base parameters to identify.
    rows_per_window : int
        Rows one window gives (1 energy, nv momentum).
    even : bool
        Whether the window must be an even number of intervals (energy: Simpson).
    rows_per_parameter : int
        Rows wanted per base parameter.

    Raises
    ------
    InputError
        When even the shortest window gives no more rows than base parameters.
    """
    if not (math.isfinite(dt) and dt > 0):
        raise InputError(f"dt must be a positive sample time [s], got {dt}")
    shortest = 2 if even else 1
    intervals = max(int(n_samples) - 1, 0)

    def rows(w: int) -> int:
        return (intervals // w) * rows_per_window

    wanted = rows_per_parameter * n_base
    default = max(int(round(DEFAULT_WINDOW / dt)), shortest)
    if even and default % 2:
        default += 1
    if rows(default) >= wanted:
        w = default
        rule = (
            f"the default {DEFAULT_WINDOW:g} s gives {rows(w)} rows, at least "
            f"{rows_per_parameter} per base parameter ({n_base})"
        )
    else:
        windows = math.ceil(wanted / rows_per_window)
        w = max(intervals // max(windows, 1), shortest)
        if even and w % 2:
            w = max(w - 1, shortest)
        rule = (
            f"the longest window giving at least {rows_per_parameter} rows per base "
            f"parameter ({wanted} rows for {n_base}; the default {DEFAULT_WINDOW:g} s "
            f"gives {rows(default)})"
        )
    if rows(w) <= n_base:
        raise InputError(
            f"{n_samples} samples give {rows(w)} rows with the shortest window ({w} "
            f"intervals) for {n_base} base parameters: give more samples"
        )
    return WindowChoice(w * float(dt), w, rows(w), True, rule)
