"""What the figures share: a canvas without pyplot, checked series, thinning, atomic PNGs.

Figures are built without ``pyplot`` (no global state, no display); the PNG has exactly
``figsize * dpi`` pixels and is written atomically (:func:`manip_id._io.atomic_write`).
Long signals are thinned for drawing: at most :data:`MAX_POINTS` points per line, taken
at an even stride (:func:`stride`; the arrays themselves are not copied).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.text import Text

from .._checks import as_float_array, check_finite
from .._io import atomic_write
from ..errors import InputError

#: Points drawn per line at most (longer signals are strided).
MAX_POINTS = 4000
#: Resolution of the PNG files [dots per inch].
DPI = 100


@dataclass(frozen=True)
class FigureOptions:
    """How a figure is labelled and drawn.

    Attributes
    ----------
    title : str
        The figure's title ("" for the figure's own default).
    joint_names : sequence of str or None
        One name per column (default ``joint 1``, ...).
    units : str or sequence of str
        The columns' unit, or one per column (e.g. ``N m``, ``N``).
    zoom : float
        Span of a zoomed window [s] (torque comparisons).
    bins : int
        Histogram bins (torque comparisons).
    error_label : str
        What a prediction-error axis shows (online histories).
    max_lines : int
        Lines drawn at most (online histories: the parameters that end farthest).
    """

    title: str = ""
    joint_names: Sequence[str] | None = None
    units: str | Sequence[str] = "N m"
    zoom: float = 2.0
    bins: int = 60
    error_label: str = "prediction error [N m]"
    max_lines: int = 12


#: Colors: measured (training), identified prediction, validation, its prediction, nominal.
TRAIN, PRED, VAL, VPRED, NOM = "#7f7f7f", "#1f77b4", "#bcbd22", "#d62728", "#2ca02c"


def stride(n: int) -> int:
    return max(1, int(np.ceil(n / MAX_POINTS)))


def series(t, y, name_t: str, name_y: str, width: int | None = None):
    """Validated ``t`` (N,) and ``y`` (N, n) (a 1-D ``y`` is one column)."""
    t = as_float_array(t, name_t, ndim=1)
    y = as_float_array(y, name_y, ndim=(1, 2))
    if y.ndim == 1:
        y = y[:, None]
    if y.shape[0] != t.shape[0]:
        raise InputError(f"{name_t}.shape={t.shape} but {name_y}.shape={y.shape}: one row per time")
    if y.shape[0] < 1:
        raise InputError(f"{name_y} has no samples ({name_y}.shape={y.shape})")
    if width is not None and y.shape[1] != width:
        raise InputError(f"{name_y}.shape={y.shape} but {width} columns were expected")
    check_finite(t, name_t)
    check_finite(y, name_y)
    return t, y


def names_for(names: Sequence[str] | None, n: int, what: str, default: str) -> list[str]:
    if names is None:
        return [f"{default} {i + 1}" for i in range(n)]
    names = [str(x) for x in names]
    if len(names) != n:
        raise InputError(f"{len(names)} {what} given for {n} columns")
    return names


def units_for(units, n: int) -> list[str]:
    if isinstance(units, str):
        return [units] * n
    units = [str(u) for u in units]
    if len(units) != n:
        raise InputError(f"{len(units)} units given for {n} columns")
    return units


def new_figure(
    n_axes: int,
    *,
    cols: int = 1,
    width: float = 10.0,
    row_height: float = 1.9,
    min_height: float = 3.5,
):
    """A Figure with ``n_axes`` subplots on a grid of ``cols`` columns; returns (fig, axes)."""
    cols = max(1, min(cols, n_axes))
    rows = int(np.ceil(n_axes / cols))
    height = max(min_height, row_height * rows + 1.0)
    fig = Figure(figsize=(width, height), dpi=DPI)
    FigureCanvasAgg(fig)
    axes = [fig.add_subplot(rows, cols, i + 1) for i in range(n_axes)]
    return fig, axes


def no_mathtext(fig: Figure) -> None:
    """Show every title, label, legend and annotation literally: user strings (joint and
    file names, titles) never go through mathtext, so ``$`` is just a character, and bytes
    of a file name that are not UTF-8 show as ``\udcff``. Tick labels (matplotlib's own,
    e.g. ``10^{-2}`` on log axes) keep their formatting."""
    texts: list[Text] = list(fig.texts)  # suptitle, supxlabel, supylabel and fig.text's
    for ax in fig.axes:
        # the axes' Text children: its three titles (center, left, right) and ax.texts
        texts += [a for a in ax.get_children() if isinstance(a, Text)]
        texts += [ax.xaxis.label, ax.yaxis.label]
        legend = ax.get_legend()
        if legend is not None:
            texts += list(legend.get_texts())
            texts.append(legend.get_title())
    for legend in fig.legends:
        texts += list(legend.get_texts())
    for text in texts:
        text.set_parse_math(False)
        raw = text.get_text()
        safe = raw.encode("utf-8", "backslashreplace").decode("utf-8")  # undecodable file names
        if safe != raw:
            text.set_text(safe)


def save(fig: Figure, path) -> Figure:
    no_mathtext(fig)
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=DPI))
    return fig


def png_size(path) -> tuple[int, int]:
    """(width, height) [px] of a PNG file, read from its header; InputError if not a PNG."""
    head = Path(path).read_bytes()[:24]
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        raise InputError(f"{path} is not a PNG file")
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
