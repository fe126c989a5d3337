"""Figures of identification and adaptive-control runs (matplotlib, Agg, PNG, no screen).

Every function takes plain arrays (and names and units), writes one PNG
atomically (temporary file, then rename: :func:`manip_id._io.atomic_write`)
and returns the :class:`matplotlib.figure.Figure` it drew, so that callers and
tests can inspect its axes. Figures are built without ``pyplot`` (no global
state, no display); the PNG has exactly ``figsize * dpi`` pixels.

Long signals are thinned for drawing: at most :data:`MAX_POINTS` points per
line, taken at an even stride (the arrays themselves are not copied).

Shapes: ``t`` [s] (N,); per-joint signals (N, n) with one column per joint;
parameter histories (K, p).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .._checks import as_float_array, check_finite
from .._io import atomic_write
from ..errors import InputError
from ..parameters import bounded_range

#: Points drawn per line at most (longer signals are strided).
MAX_POINTS = 4000
#: Resolution of the PNG files [dots per inch].
DPI = 100

_TRAIN, _PRED, _VAL, _VPRED = "#7f7f7f", "#1f77b4", "#bcbd22", "#d62728"


# ------------------------------------------------------------------ helpers
def _stride(n: int) -> int:
    return max(1, int(np.ceil(n / MAX_POINTS)))


def _series(t, y, name_t: str, name_y: str, width: int | None = None):
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


def _names(names: Sequence[str] | None, n: int, what: str, default: str) -> list[str]:
    if names is None:
        return [f"{default} {i + 1}" for i in range(n)]
    names = [str(x) for x in names]
    if len(names) != n:
        raise InputError(f"{len(names)} {what} given for {n} columns")
    return names


def _units(units, n: int) -> list[str]:
    if isinstance(units, str):
        return [units] * n
    units = [str(u) for u in units]
    if len(units) != n:
        raise InputError(f"{len(units)} units given for {n} columns")
    return units


def _figure(
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


def _no_mathtext(fig: Figure) -> None:
    """Show every title, label, legend and annotation literally: user strings (joint and
    file names, titles) never go through mathtext, so ``$`` is just a character, and bytes
    of a file name that are not UTF-8 show as ``\udcff``. Tick labels (matplotlib's own,
    e.g. ``10^{-2}`` on log axes) keep their formatting."""
    from matplotlib.text import Text

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


def _save(fig: Figure, path) -> Figure:
    _no_mathtext(fig)
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=DPI))
    return fig


# ------------------------------------------------------------------ figures
def torque_fit(
    path,
    t,
    tau,
    tau_pred,
    *,
    joint_names: Sequence[str] | None = None,
    units: str | Sequence[str] = "N m",
    t_validation=None,
    tau_validation=None,
    tau_validation_pred=None,
    title: str = "torque fit",
) -> Figure:
    """Measured and predicted torque per joint, training (and validation) data.

    t: training times [s], shape (N,); tau, tau_pred: measured and predicted
    (``Y_b(q, dq, ddq) theta_b``) torques, shape (N, n) [units]. The validation
    triple, when given, has shapes (M,), (M, n), (M, n). One axes per joint.
    """
    t, tau = _series(t, tau, "t", "tau")
    n = tau.shape[1]
    _, tau_pred = _series(t, tau_pred, "t", "tau_pred", width=n)
    val = _validation(t_validation, tau_validation, tau_validation_pred, n, "tau")
    names, units = _names(joint_names, n, "joint names", "joint"), _units(units, n)
    fig, axes = _figure(n, row_height=1.7)
    for j, ax in enumerate(axes):
        k = _stride(len(t))
        ax.plot(t[::k], tau[::k, j], color=_TRAIN, lw=2.4, alpha=0.45, label="measured (training)")
        ax.plot(t[::k], tau_pred[::k, j], color=_PRED, lw=0.9, label="predicted (training)")
        if val is not None:
            tv, mv, pv = val
            k = _stride(len(tv))
            ax.plot(
                tv[::k], mv[::k, j], color=_VAL, lw=2.4, alpha=0.6, label="measured (validation)"
            )
            ax.plot(
                tv[::k], pv[::k, j], color=_VPRED, lw=0.9, ls="--", label="predicted (validation)"
            )
        ax.set_ylabel(f"{names[j]}\n[{units[j]}]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    axes[0].legend(loc="upper right", fontsize=7, ncol=4)
    fig.suptitle(title)
    return _save(fig, path)


def residuals(
    path,
    t,
    residual,
    *,
    joint_names: Sequence[str] | None = None,
    units: str | Sequence[str] = "N m",
    t_validation=None,
    residual_validation=None,
    title: str = "torque residuals",
) -> Figure:
    """Torque residuals ``tau - tau_pred`` per joint over time, with their RMS in the legend.

    t: [s], shape (N,); residual: shape (N, n) [units]; the validation pair has
    shapes (M,), (M, n). One axes per joint.
    """
    t, res = _series(t, residual, "t", "residual")
    n = res.shape[1]
    val = None
    if (t_validation is None) != (residual_validation is None):
        raise InputError("give both t_validation and residual_validation, or neither")
    if t_validation is not None:
        val = _series(
            t_validation, residual_validation, "t_validation", "residual_validation", width=n
        )
    names, units = _names(joint_names, n, "joint names", "joint"), _units(units, n)
    fig, axes = _figure(n, row_height=1.5)
    for j, ax in enumerate(axes):
        k = _stride(len(t))
        rms = float(np.sqrt(np.mean(res[:, j] ** 2)))
        ax.plot(t[::k], res[::k, j], color=_PRED, lw=0.7, label=f"training, RMS {rms:.3g}")
        if val is not None:
            tv, rv = val
            k = _stride(len(tv))
            rms = float(np.sqrt(np.mean(rv[:, j] ** 2)))
            ax.plot(tv[::k], rv[::k, j], color=_VPRED, lw=0.7, label=f"validation, RMS {rms:.3g}")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_ylabel(f"{names[j]}\n[{units[j]}]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(loc="upper right", fontsize=7, ncol=2)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(title)
    return _save(fig, path)


def _validation(t, measured, predicted, n: int, what: str):
    given = [x is not None for x in (t, measured, predicted)]
    if not any(given):
        return None
    if not all(given):
        raise InputError(
            f"validation needs t_validation, {what}_validation and {what}_validation_pred together"
        )
    t, measured = _series(t, measured, "t_validation", f"{what}_validation", width=n)
    _, predicted = _series(t, predicted, "t_validation", f"{what}_validation_pred", width=n)
    return t, measured, predicted


def singular_values(
    path,
    sigma,
    *,
    tolerance: float,
    rank: int | None = None,
    title: str = "singular values",
    ylabel: str = "sigma_i / sigma_1 (column-scaled regressor) [-]",
) -> Figure:
    """Singular-value spectrum ``sigma_i / sigma_1`` (log scale) with the rank threshold.

    sigma: singular values, shape (p,), any order (sorted descending here);
    tolerance: relative rank threshold: ``sigma_i / sigma_1 > tolerance`` counts
    toward the rank. rank: the rank to mark (default: the count above the
    threshold). Zero values are drawn at the bottom of the axis.
    """
    s = as_float_array(sigma, "sigma", ndim=1)
    if s.size == 0:
        raise InputError(f"sigma must hold at least one singular value, got shape {s.shape}")
    check_finite(s, "sigma")
    if np.any(s < 0):
        raise InputError(f"singular values must be >= 0, got min {s.min():.3g}")
    if not (np.isfinite(tolerance) and 0 < tolerance < 1):
        raise InputError(f"tolerance must be a relative threshold in (0, 1), got {tolerance}")
    s = np.sort(s)[::-1]
    if s[0] <= 0:
        raise InputError("all singular values are zero: nothing to plot")
    rel = s / s[0]
    above = rel > tolerance
    r = int(above.sum()) if rank is None else int(rank)
    floor = min(tolerance, rel[rel > 0].min()) * 1e-2
    shown = np.maximum(rel, floor)
    idx = np.arange(1, s.size + 1)
    fig, (ax,) = _figure(1, width=9.0, min_height=4.5)
    ax.semilogy(idx[above], shown[above], "o", color=_PRED, ms=4, label=f"above threshold ({r})")
    if (~above).any():
        ax.semilogy(
            idx[~above],
            shown[~above],
            "x",
            color=_VPRED,
            ms=5,
            label=f"below threshold ({int((~above).sum())})",
        )
    ax.axhline(tolerance, color="k", ls="--", lw=1.0, label=f"rank threshold {tolerance:.2g}")
    if 0 < r < s.size:
        ax.axvline(r + 0.5, color="grey", ls=":", lw=1.0, label=f"rank {r} of {s.size}")
    ax.set_xlabel("index i [-]")
    ax.set_ylabel(ylabel)
    ax.set_ylim(floor * 0.5, 2.0)
    ax.grid(alpha=0.3, which="both")
    ax.legend(loc="lower left", fontsize=8)
    ax.set_title(title)
    return _save(fig, path)


def parameter_history(
    path,
    t,
    theta_hat,
    *,
    names: Sequence[str],
    units: Sequence[str] | None = None,
    theta_true=None,
    max_parameters: int = 12,
    title: str = "parameter estimates",
) -> Figure:
    """Estimates over time of an online law or adaptive controller, with the truth when known.

    t: [s], shape (K,); theta_hat: shape (K, p); names (and units): length p;
    theta_true: shape (p,) or None. At most ``max_parameters`` parameters are
    drawn, one axes each: those whose estimate moved the most relative to its
    scale (``|theta_hat[-1] - theta_hat[0]| / max(|theta_hat|, |theta_true|)``),
    ties broken by the initial error relative to the same scale.
    """
    t, th = _series(t, theta_hat, "t", "theta_hat")
    p = th.shape[1]
    names = _names(names, p, "parameter names", "parameter")
    units = _units(units if units is not None else [""] * p, p)
    true = None
    if theta_true is not None:
        true = as_float_array(theta_true, "theta_true", ndim=1)
        if true.shape != (p,):
            raise InputError(f"theta_true.shape={true.shape} but theta_hat.shape={th.shape}")
        check_finite(true, "theta_true")
    if int(max_parameters) < 1:
        raise InputError(f"max_parameters must be >= 1, got {max_parameters}")
    scale = np.abs(th).max(axis=0)
    if true is not None:
        scale = np.maximum(scale, np.abs(true))
    scale = np.maximum(scale, 1e-12)
    moved = np.abs(th[-1] - th[0]) / scale
    error = np.zeros(p) if true is None else np.abs(th[0] - true) / scale
    order = np.lexsort((-error, -moved))[: min(int(max_parameters), p)]
    fig, axes = _figure(len(order), cols=3, width=12.0, row_height=2.2)
    k = _stride(len(t))
    for ax, i in zip(axes, order, strict=True):
        ax.plot(t[::k], th[::k, i], color=_PRED, lw=1.0, label="estimate")
        if true is not None:
            ax.axhline(true[i], color=_VPRED, ls="--", lw=1.0, label="true")
        unit = f" [{units[i]}]" if units[i] else ""
        ax.set_title(names[i], fontsize=8)
        ax.set_ylabel(f"value{unit}", fontsize=7)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    for ax in axes[-min(3, len(axes)) :]:
        ax.set_xlabel("time [s]", fontsize=8)
    axes[0].legend(fontsize=7)
    shown = f"{len(order)} of {p} parameters" if len(order) < p else f"{p} parameters"
    fig.suptitle(f"{title} ({shown})")
    return _save(fig, path)


def tracking_error(
    path,
    t,
    error,
    *,
    joint_names: Sequence[str] | None = None,
    units: str = "rad",
    baseline=None,
    labels: tuple[str, str] = ("adaptive", "fixed parameters"),
    title: str = "tracking error",
) -> Figure:
    """Tracking error ``q - q_d`` per joint, and its norm against a baseline run.

    t: [s], shape (K,); error: shape (K, n) [units]; baseline: the error of a
    comparison run (e.g. fixed parameters) on the same times, shape (K, n), or
    None. Two axes: per-joint error (top), ``|q - q_d|`` (bottom, log scale).
    """
    t, err = _series(t, error, "t", "error")
    n = err.shape[1]
    base = None
    if baseline is not None:
        _, base = _series(t, baseline, "t", "baseline", width=n)
    names = _names(joint_names, n, "joint names", "joint")
    fig, (top, bottom) = _figure(2, width=10.0, row_height=2.6)
    k = _stride(len(t))
    for j in range(n):
        top.plot(t[::k], err[::k, j], lw=0.9, label=names[j])
    top.set_ylabel(f"q - q_d [{units}]")
    top.legend(fontsize=7, ncol=min(n, 7), loc="upper right")
    top.set_title(f"per joint ({labels[0]})", fontsize=9)
    top.grid(alpha=0.3)
    floor = 1e-12
    bottom.semilogy(
        t[::k], np.maximum(np.linalg.norm(err, axis=1)[::k], floor), color=_PRED, label=labels[0]
    )
    if base is not None:
        bottom.semilogy(
            t[::k],
            np.maximum(np.linalg.norm(base, axis=1)[::k], floor),
            color=_VPRED,
            ls="--",
            label=labels[1],
        )
    bottom.set_ylabel(f"|q - q_d| [{units}]")
    bottom.set_xlabel("time [s]")
    bottom.legend(fontsize=8)
    bottom.grid(alpha=0.3, which="both")
    fig.suptitle(title)
    return _save(fig, path)


def trajectory_limits(
    path,
    t,
    q,
    *,
    lower,
    upper,
    joint_names: Sequence[str] | None = None,
    units: str | Sequence[str] = "rad",
    title: str = "excitation trajectory",
) -> Figure:
    """Joint positions over time against their limits (shaded outside), one axes per joint.

    t: [s], shape (N,); q: shape (N, n) [units]; lower, upper: shape (n,)
    (infinite or absurdly wide limits, over 1e3, are not drawn).
    """
    t, q = _series(t, q, "t", "q")
    n = q.shape[1]
    lo = as_float_array(lower, "lower", ndim=1)
    hi = as_float_array(upper, "upper", ndim=1)
    if lo.shape != (n,) or hi.shape != (n,):
        raise InputError(f"lower.shape={lo.shape}, upper.shape={hi.shape} but q.shape={q.shape}")
    names, units = _names(joint_names, n, "joint names", "joint"), _units(units, n)
    cols = 2 if n > 3 else 1
    fig, axes = _figure(n, cols=cols, width=11.0 if cols == 2 else 9.0, row_height=1.9)
    k = _stride(len(t))
    for j, ax in enumerate(axes):
        ax.plot(t[::k], q[::k, j], color=_PRED, lw=1.0, label="q")
        bounded = bool(bounded_range(lo[j], hi[j]))
        if bounded:
            span = hi[j] - lo[j]
            ymin = min(lo[j], q[:, j].min()) - 0.12 * span
            ymax = max(hi[j], q[:, j].max()) + 0.12 * span
            ax.axhspan(ymin, lo[j], color=_VPRED, alpha=0.15)
            ax.axhspan(hi[j], ymax, color=_VPRED, alpha=0.15)
            ax.axhline(lo[j], color=_VPRED, lw=1.0, label="limits")
            ax.axhline(hi[j], color=_VPRED, lw=1.0)
            ax.set_ylim(ymin, ymax)
            used = (q[:, j].max() - q[:, j].min()) / span
            ax.set_title(f"{names[j]}: {100 * used:.0f} % of the range used", fontsize=8)
        else:
            ax.set_title(f"{names[j]}: no finite limits", fontsize=8)
        ax.set_ylabel(f"q [{units[j]}]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    for ax in axes[-cols:]:
        ax.set_xlabel("time [s]", fontsize=8)
    axes[0].legend(fontsize=7, loc="upper right")
    fig.suptitle(title)
    return _save(fig, path)


def per_file_parameters(
    path,
    estimates,
    stds,
    *,
    pooled,
    names: Sequence[str],
    files: Sequence[str],
    max_parameters: int = 12,
    title: str = "per-file parameters",
) -> Figure:
    """Each file's base parameters with error bars (+-1 std), relative to the pooled fit.

    Parameters
    ----------
    estimates: per-file estimates, shape (F, p) [parameter units]; a row of NaN
        is a file that could not be solved alone (drawn empty)
    stds: their standard deviations, shape (F, p)
    pooled: the pooled estimate, shape (p,)
    names: parameter names (p,); files: file labels (F,)
    max_parameters: the largest ``|pooled|`` parameters shown (at most this many)

    Each parameter ``i`` of file ``f`` is drawn as ``theta_fi / |theta_i|`` with
    error bar ``std_fi / |theta_i|`` (dimensionless, so parameters of different
    units share one axis): files agreeing with the pool sit at +-1; a file that
    drifted stands off by more than its error bar.
    """
    est = as_float_array(estimates, "estimates", ndim=2)
    std = as_float_array(stds, "stds", ndim=2)
    ref = as_float_array(pooled, "pooled", ndim=1)
    n_files, p = est.shape
    if std.shape != est.shape or ref.shape != (p,):
        raise InputError(
            f"estimates.shape={est.shape}, stds.shape={std.shape}, pooled.shape={ref.shape}: "
            "expected (F, p), (F, p) and (p,)"
        )
    names = _names(names, p, "names", "theta")
    files = _names(files, n_files, "file labels", "file")
    check_finite(ref, "pooled")
    if int(max_parameters) < 1:
        raise InputError(f"max_parameters must be >= 1, got {max_parameters}")
    shown = np.argsort(-np.abs(ref), kind="stable")[: int(max_parameters)]
    shown = shown[np.abs(ref[shown]) > 0]
    if shown.size == 0:
        raise InputError("every pooled parameter is zero: nothing to normalize by")
    scale = np.abs(ref[shown])
    fig, (ax,) = _figure(1, width=max(8.0, 0.6 * shown.size + 3.0), min_height=4.5)
    x = np.arange(shown.size, dtype=float)
    offsets = (np.arange(n_files) - (n_files - 1) / 2) * min(0.8 / max(n_files, 1), 0.15)
    for f in range(n_files):
        ax.errorbar(
            x + offsets[f],
            est[f, shown] / scale,
            yerr=np.abs(std[f, shown]) / scale,
            fmt="o",
            ms=3,
            capsize=2,
            lw=1.0,
            label=files[f],
        )
    ax.plot(x, ref[shown] / scale, "k_", ms=14, mew=1.5, label="pooled")
    ax.axhline(0.0, color="grey", lw=0.8)
    ax.set_xticks(x)
    ax.set_xticklabels([names[i] for i in shown], rotation=60, ha="right", fontsize=7)
    ax.set_ylabel("theta_file / |theta_pooled| [-]")
    ax.grid(alpha=0.3)
    if n_files <= 12:
        ax.legend(loc="best", fontsize=7)
    ax.set_title(title)
    return _save(fig, path)


def png_size(path) -> tuple[int, int]:
    """(width, height) [px] of a PNG file, read from its header; InputError if not a PNG."""
    head = Path(path).read_bytes()[:24]
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        raise InputError(f"{path} is not a PNG file")
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


# ------------------------------------------------------- the report's questions
_NOM = "#2ca02c"


def _zoom_window(t: np.ndarray, errors: np.ndarray, span: float) -> tuple[float, float]:
    """A window of ``span`` [s] where the identified and nominal curves differ most
    (the largest moving RMS of ``errors``, shape (N,)), inside ``t``."""
    if t[-1] - t[0] <= span or len(t) < 3:
        return float(t[0]), float(t[-1])
    dt = float(np.median(np.diff(t)))
    w = max(int(span / max(dt, 1e-12)), 2)
    c = np.concatenate([[0.0], np.cumsum(errors**2)])
    k = int(np.argmax(c[w:] - c[:-w]))
    return float(t[k]), float(t[min(k + w, len(t) - 1)])


def torque_comparison(
    path,
    t,
    tau,
    tau_pred,
    tau_nominal,
    *,
    validation_start: float | None = None,
    joint_names: Sequence[str] | None = None,
    units: str | Sequence[str] = "N m",
    zoom: float = 2.0,
    errors: Sequence[tuple[float | None, float | None]] | None = None,
    reference: str = "measured",
    title: str = "torques",
    bins: int = 60,
) -> Figure:
    """Per joint: measured, identified and nominal torques over time, a zoom, the residuals.

    One row per joint, three panels: (1) the whole record with the validation part
    shaded (samples from ``validation_start`` [s] on; gaps are samples left out by
    trimming or windows, drawn as breaks); (2) a ``zoom`` [s] window, in the
    validation part when there is one, where the identified and nominal
    predictions differ most, so the curves can be told apart; (3) histograms of
    the residuals ``tau - tau_pred`` and ``tau - tau_nominal`` [units].

    t: [s], shape (N,); tau, tau_pred, tau_nominal: shape (N, n) [units];
    errors: per joint ``(identified, nominal)`` relative errors shown in the
    titles (fractions); reference: what "measured" is (e.g. "filtered at 3 Hz").
    """
    t, tau = _series(t, tau, "t", "tau")
    n = tau.shape[1]
    _, pred = _series(t, tau_pred, "t", "tau_pred", width=n)
    _, nom = _series(t, tau_nominal, "t", "tau_nominal", width=n)
    names, units = _names(joint_names, n, "joint names", "joint"), _units(units, n)
    if errors is not None and len(errors) != n:
        raise InputError(f"{len(errors)} error pairs given for {n} joints")
    if not (np.isfinite(zoom) and zoom > 0):
        raise InputError(f"zoom must be a positive time [s], got {zoom}")
    fig = Figure(figsize=(14.0, max(3.2, 2.1 * n + 1.2)), dpi=DPI)
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(n, 3, width_ratios=(3.2, 1.6, 1.2))
    step = np.diff(t)
    gap = np.flatnonzero(step > 5.0 * np.median(step)) if len(t) > 2 else np.array([], int)

    def broken(x, y):  # NaN at the gaps, so lines do not bridge left-out samples
        if gap.size == 0 or len(x) < 3:
            return x, y
        dx = np.diff(x)
        at = np.flatnonzero(dx > 5.0 * np.median(dx)) + 1
        return np.insert(x, at, np.nan), np.insert(y, at, np.nan)

    k = _stride(len(t))
    in_val = t >= validation_start if validation_start is not None else np.zeros(len(t), bool)
    pick = in_val if in_val.any() else np.ones(len(t), bool)
    for j in range(n):
        ax = fig.add_subplot(grid[j, 0])
        for y, color, lw, label in (
            (tau[:, j], _TRAIN, 2.2, f"measured ({reference})"),
            (nom[:, j], _NOM, 0.9, "nominal model (URDF)"),
            (pred[:, j], _PRED, 0.9, "identified model"),
        ):
            ax.plot(
                *broken(t[::k], y[::k]),
                color=color,
                lw=lw,
                alpha=0.55 if lw > 2 else 1.0,
                label=label,
            )
        if validation_start is not None and in_val.any():
            ax.axvspan(
                validation_start, t[-1], color=_VAL, alpha=0.12, lw=0, label="validation part"
            )
        for m, g in enumerate(gap):
            ax.axvspan(
                t[g],
                t[g + 1],
                color="k",
                alpha=0.07,
                lw=0,
                label="left out (trimmed filter edges, windows)" if m == 0 else None,
            )
        head = names[j]
        if errors is not None:
            e_id, e_nom = errors[j]
            head += "   error: identified " + ("n/a" if e_id is None else f"{100 * e_id:.2f} %")
            head += ", nominal " + ("n/a" if e_nom is None else f"{100 * e_nom:.1f} %")
        ax.set_title(head, fontsize=8, loc="left")
        ax.set_ylabel(f"[{units[j]}]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        a, b = _zoom_window(t[pick], (pred - nom)[pick, j], zoom)
        ax.axvspan(a, b, fill=False, ec="k", lw=0.6, ls=":")
        zx = fig.add_subplot(grid[j, 1])
        sel = (t >= a) & (t <= b)
        zx.plot(t[sel], tau[sel, j], color=_TRAIN, lw=2.2, alpha=0.55)
        zx.plot(t[sel], nom[sel, j], color=_NOM, lw=1.0)
        zx.plot(t[sel], pred[sel, j], color=_PRED, lw=1.0)
        zx.set_title(f"zoom {a:.1f}-{b:.1f} s", fontsize=8)
        zx.tick_params(labelsize=7)
        zx.grid(alpha=0.3)
        hx = fig.add_subplot(grid[j, 2])
        r_id, r_nom = tau[:, j] - pred[:, j], tau[:, j] - nom[:, j]
        lim = float(np.percentile(np.abs(np.concatenate([r_id, r_nom])), 99.5)) or 1.0
        edges = np.linspace(-lim, lim, int(bins) + 1).tolist()
        hx.hist(r_nom, bins=edges, color=_NOM, alpha=0.5, label="nominal")
        hx.hist(r_id, bins=edges, color=_PRED, alpha=0.7, label="identified")
        hx.set_title(f"residual [{units[j]}]", fontsize=8)
        hx.tick_params(labelsize=7)
        hx.set_yticks([])
        if j == 0:
            handles, labels = ax.get_legend_handles_labels()
            hx.legend(fontsize=7)
    fig.axes[-3].set_xlabel("time [s]")
    height = fig.get_figheight()
    fig.legend(
        handles,
        labels,
        loc="upper center",
        ncol=5,
        fontsize=8,
        bbox_to_anchor=(0.5, 1.0 - 0.42 / height),
    )
    fig.suptitle(title, y=1.0 - 0.08 / height)
    _no_mathtext(fig)
    fig.tight_layout(rect=(0, 0, 1, 1.0 - 0.75 / height))
    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=DPI))
    return fig


def online_history(
    path,
    t,
    theta_hat,
    *,
    names: Sequence[str],
    reference,
    reference_label: str = "final estimate",
    prediction_error=None,
    torque_rms: float | None = None,
    error_label: str = "prediction error [N m]",
    max_lines: int = 12,
    title: str = "online estimate",
) -> Figure:
    """Convergence of an online law: base-parameter relative errors and prediction error.

    Top: ``|theta_hat_i(t) - ref_i| / max(|ref_i|, 1e-3 max|ref|)`` [-] on a log scale for
    the ``max_lines`` parameters that end farthest from ``reference`` (plus the median
    over all of them, black); the last 10 % of the time is shaded, where a converged
    estimate no longer moves. Bottom: the prediction-error norm ``|eps(t)|`` [N m]
    (its moving median), relative to ``torque_rms`` when given (``error_label`` names it
    otherwise, e.g. an error that is already relative).

    t: [s], shape (K,); theta_hat: shape (K, r); reference: shape (r,) (the truth of
    a simulation, or the batch / final estimate); prediction_error: shape (K,).
    """
    t, th = _series(t, theta_hat, "t", "theta_hat")
    r = th.shape[1]
    names = _names(names, r, "parameter names", "parameter")
    ref = as_float_array(reference, "reference", ndim=1)
    if ref.shape != (r,):
        raise InputError(f"reference.shape={ref.shape} but theta_hat.shape={th.shape}")
    check_finite(ref, "reference")
    scale = np.maximum(np.abs(ref), 1e-3 * max(float(np.abs(ref).max()), 1e-300))
    rel = np.abs(th - ref) / scale  # (K, r)
    order = np.argsort(-rel[-1])[: min(int(max_lines), r)]
    n_axes = 2 if prediction_error is not None else 1
    fig, axes = _figure(n_axes, width=11.0, row_height=3.0)
    ax = axes[0]
    k = _stride(len(t))
    floor = 1e-6
    for i in order:
        ax.semilogy(t[::k], np.maximum(rel[::k, i], floor), lw=0.8, label=names[i])
    ax.semilogy(
        t[::k],
        np.maximum(np.median(rel[::k], axis=1), floor),
        color="k",
        lw=1.8,
        label=f"median of {r}",
    )
    tail = t[0] + 0.9 * (t[-1] - t[0])
    for a in axes:
        a.axvspan(tail, t[-1], color=_VAL, alpha=0.15, lw=0)
        a.grid(alpha=0.3, which="both")
        a.tick_params(labelsize=7)
    ax.set_ylabel(f"relative error vs {reference_label} [-]", fontsize=8)
    ax.legend(fontsize=6, ncol=1, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.set_title(
        f"base-parameter estimates: the {len(order)} farthest from the {reference_label} at "
        "the end, and the median (last 10 % of the data shaded)",
        fontsize=9,
    )
    if prediction_error is not None:
        e = as_float_array(prediction_error, "prediction_error", ndim=1)
        if e.shape != t.shape:
            raise InputError(f"prediction_error.shape={e.shape} but t.shape={t.shape}")
        ok = np.isfinite(e)
        w = max(len(t) // 100, 1)
        ee = e[ok]
        smooth = np.array([np.median(ee[max(0, i - w) : i + 1]) for i in range(len(ee))])
        label = error_label
        if torque_rms:
            ee, smooth = ee / torque_rms, smooth / torque_rms
            label = "prediction error relative to the torque RMS [-]"
        bx = axes[1]
        bx.semilogy(
            t[ok][::k],
            np.maximum(ee[::k], 1e-12),
            color=_PRED,
            lw=0.4,
            alpha=0.5,
            label="|eps| per sample",
        )
        bx.semilogy(
            t[ok][::k], np.maximum(smooth[::k], 1e-12), color=_VPRED, lw=1.4, label="moving median"
        )
        bx.set_ylabel(label, fontsize=8)
        bx.legend(fontsize=7)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(title)
    return _save(fig, path)
