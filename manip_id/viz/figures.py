"""Figures of identification runs (matplotlib, Agg, PNG, no screen).

Every function takes plain arrays (and names and units), writes one PNG
atomically (temporary file, then rename: :func:`manip_id._io.atomic_write`)
and returns the :class:`matplotlib.figure.Figure` it drew, so that callers and
tests can inspect its axes (:mod:`.plotting`: the canvas they share).

Shapes: ``t`` [s] (N,); per-joint signals (N, n) with one column per joint;
parameter histories (K, p). The figures of a motion over time (parameter
histories, tracking errors, trajectories against limits) are in
:mod:`.history_figures` and re-exported here.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .._checks import as_float_array, check_finite
from .._io import atomic_write
from ..errors import InputError
from .history_figures import online_history, parameter_history, tracking_error, trajectory_limits
from .plotting import (
    DPI,
    MAX_POINTS,
    NOM,
    PRED,
    TRAIN,
    VAL,
    VPRED,
    FigureOptions,
    names_for,
    new_figure,
    no_mathtext,
    png_size,
    save,
    series,
    stride,
    units_for,
)

__all__ = [
    "DPI",
    "FigureOptions",
    "MAX_POINTS",
    "online_history",
    "parameter_history",
    "per_file_parameters",
    "png_size",
    "residuals",
    "singular_values",
    "torque_comparison",
    "torque_fit",
    "tracking_error",
    "trajectory_limits",
]


def torque_fit(
    path,
    t,
    tau,
    tau_pred,
    *,
    t_validation=None,
    tau_validation=None,
    tau_validation_pred=None,
    options: FigureOptions | None = None,
) -> Figure:
    """Measured and predicted torque per joint, training (and validation) data.

    t: training times [s], shape (N,); tau, tau_pred: measured and predicted
    (``Y_b(q, dq, ddq) theta_b``) torques, shape (N, n) [units]. The validation
    triple, when given, has shapes (M,), (M, n), (M, n). One axes per joint.
    options: title (default "torque fit"), joint names and units.
    """
    o = options or FigureOptions()
    title = o.title or "torque fit"
    t, tau = series(t, tau, "t", "tau")
    n = tau.shape[1]
    _, tau_pred = series(t, tau_pred, "t", "tau_pred", width=n)
    val = _validation(t_validation, tau_validation, tau_validation_pred, n, "tau")
    names, units = names_for(o.joint_names, n, "joint names", "joint"), units_for(o.units, n)
    fig, axes = new_figure(n, row_height=1.7)
    for j, ax in enumerate(axes):
        k = stride(len(t))
        ax.plot(t[::k], tau[::k, j], color=TRAIN, lw=2.4, alpha=0.45, label="measured (training)")
        ax.plot(t[::k], tau_pred[::k, j], color=PRED, lw=0.9, label="predicted (training)")
        if val is not None:
            tv, mv, pv = val
            k = stride(len(tv))
            ax.plot(
                tv[::k], mv[::k, j], color=VAL, lw=2.4, alpha=0.6, label="measured (validation)"
            )
            ax.plot(
                tv[::k], pv[::k, j], color=VPRED, lw=0.9, ls="--", label="predicted (validation)"
            )
        ax.set_ylabel(f"{names[j]}\n[{units[j]}]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    axes[0].legend(loc="upper right", fontsize=7, ncol=4)
    fig.suptitle(title)
    return save(fig, path)


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
    t, res = series(t, residual, "t", "residual")
    n = res.shape[1]
    val = None
    if (t_validation is None) != (residual_validation is None):
        raise InputError("give both t_validation and residual_validation, or neither")
    if t_validation is not None:
        val = series(
            t_validation, residual_validation, "t_validation", "residual_validation", width=n
        )
    names, units = names_for(joint_names, n, "joint names", "joint"), units_for(units, n)
    fig, axes = new_figure(n, row_height=1.5)
    for j, ax in enumerate(axes):
        k = stride(len(t))
        rms = float(np.sqrt(np.mean(res[:, j] ** 2)))
        ax.plot(t[::k], res[::k, j], color=PRED, lw=0.7, label=f"training, RMS {rms:.3g}")
        if val is not None:
            tv, rv = val
            k = stride(len(tv))
            rms = float(np.sqrt(np.mean(rv[:, j] ** 2)))
            ax.plot(tv[::k], rv[::k, j], color=VPRED, lw=0.7, label=f"validation, RMS {rms:.3g}")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_ylabel(f"{names[j]}\n[{units[j]}]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(loc="upper right", fontsize=7, ncol=2)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(title)
    return save(fig, path)


def _validation(t, measured, predicted, n: int, what: str):
    given = [x is not None for x in (t, measured, predicted)]
    if not any(given):
        return None
    if not all(given):
        raise InputError(
            f"validation needs t_validation, {what}_validation and {what}_validation_pred together"
        )
    t, measured = series(t, measured, "t_validation", f"{what}_validation", width=n)
    _, predicted = series(t, predicted, "t_validation", f"{what}_validation_pred", width=n)
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
    fig, (ax,) = new_figure(1, width=9.0, min_height=4.5)
    ax.semilogy(idx[above], shown[above], "o", color=PRED, ms=4, label=f"above threshold ({r})")
    if (~above).any():
        ax.semilogy(
            idx[~above],
            shown[~above],
            "x",
            color=VPRED,
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
    return save(fig, path)


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
    names = names_for(names, p, "names", "theta")
    files = names_for(files, n_files, "file labels", "file")
    check_finite(ref, "pooled")
    if int(max_parameters) < 1:
        raise InputError(f"max_parameters must be >= 1, got {max_parameters}")
    shown = np.argsort(-np.abs(ref), kind="stable")[: int(max_parameters)]
    shown = shown[np.abs(ref[shown]) > 0]
    if shown.size == 0:
        raise InputError("every pooled parameter is zero: nothing to normalize by")
    scale = np.abs(ref[shown])
    fig, (ax,) = new_figure(1, width=max(8.0, 0.6 * shown.size + 3.0), min_height=4.5)
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
    return save(fig, path)


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
    errors: Sequence[tuple[float | None, float | None]] | None = None,
    reference: str = "measured",
    options: FigureOptions | None = None,
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
    titles (fractions); reference: what "measured" is (e.g. "filtered at 3 Hz");
    options: title, joint names, units, the zoom's span [s] and the histograms' bins.
    """
    o = options or FigureOptions()
    joint_names, units, zoom, bins = o.joint_names, o.units, o.zoom, o.bins
    title = o.title or "torques"
    t, tau = series(t, tau, "t", "tau")
    n = tau.shape[1]
    _, pred = series(t, tau_pred, "t", "tau_pred", width=n)
    _, nom = series(t, tau_nominal, "t", "tau_nominal", width=n)
    names, units = names_for(joint_names, n, "joint names", "joint"), units_for(units, n)
    if errors is not None and len(errors) != n:
        raise InputError(f"{len(errors)} error pairs given for {n} joints")
    if not (np.isfinite(zoom) and zoom > 0):
        raise InputError(f"zoom must be a positive time [s], got {zoom}")
    fig = Figure(figsize=(14.0, max(3.2, 2.1 * n + 1.2)), dpi=DPI)
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(n, 3, width_ratios=(3.2, 1.6, 1.2))
    step = np.diff(t)
    gap = np.flatnonzero(step > 5.0 * np.median(step)) if len(t) > 2 else np.array([], int)
    in_val = t >= validation_start if validation_start is not None else np.zeros(len(t), bool)
    pick = in_val if in_val.any() else np.ones(len(t), bool)
    for j in range(n):
        curves = (tau[:, j], nom[:, j], pred[:, j])
        ax = fig.add_subplot(grid[j, 0])
        _record_panel(ax, t, curves, gap, validation_start if in_val.any() else None, reference)
        ax.set_title(
            _joint_title(names[j], None if errors is None else errors[j]), fontsize=8, loc="left"
        )
        ax.set_ylabel(f"[{units[j]}]", fontsize=8)
        a, b = _zoom_window(t[pick], (pred - nom)[pick, j], zoom)
        ax.axvspan(a, b, fill=False, ec="k", lw=0.6, ls=":")
        _zoom_panel(fig.add_subplot(grid[j, 1]), t, curves, a, b)
        hx = fig.add_subplot(grid[j, 2])
        _residual_panel(hx, curves, units[j], bins)
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
    no_mathtext(fig)
    fig.tight_layout(rect=(0, 0, 1, 1.0 - 0.75 / height))
    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=DPI))
    return fig


def _broken(x: np.ndarray, y: np.ndarray, gaps: bool):
    """NaN at the gaps, so lines do not bridge left-out samples."""
    if not gaps or len(x) < 3:
        return x, y
    dx = np.diff(x)
    at = np.flatnonzero(dx > 5.0 * np.median(dx)) + 1
    return np.insert(x, at, np.nan), np.insert(y, at, np.nan)


def _record_panel(ax, t, curves, gap, validation_start, reference: str) -> None:
    """The whole record: measured, nominal and identified ``curves``, validation shaded
    from ``validation_start`` [s] (None: none), the left-out samples (``gap``) greyed."""
    k = stride(len(t))
    styles = (
        (TRAIN, 2.2, f"measured ({reference})"),
        (NOM, 0.9, "nominal model (URDF)"),
        (PRED, 0.9, "identified model"),
    )
    for y, (color, lw, label) in zip(curves, styles, strict=True):
        ax.plot(
            *_broken(t[::k], y[::k], gap.size > 0),
            color=color,
            lw=lw,
            alpha=0.55 if lw > 2 else 1.0,
            label=label,
        )
    if validation_start is not None:
        ax.axvspan(validation_start, t[-1], color=VAL, alpha=0.12, lw=0, label="validation part")
    for m, g in enumerate(gap):
        ax.axvspan(
            t[g],
            t[g + 1],
            color="k",
            alpha=0.07,
            lw=0,
            label="left out (trimmed filter edges, windows)" if m == 0 else None,
        )
    ax.tick_params(labelsize=7)
    ax.grid(alpha=0.3)


def _joint_title(name: str, errors) -> str:
    """``name   error: identified x %, nominal y %`` (errors: a pair of fractions or None)."""
    if errors is None:
        return name
    e_id, e_nom = errors
    head = name + "   error: identified " + ("n/a" if e_id is None else f"{100 * e_id:.2f} %")
    return head + ", nominal " + ("n/a" if e_nom is None else f"{100 * e_nom:.1f} %")


def _zoom_panel(zx, t, curves, a: float, b: float) -> None:
    """The window [a, b] [s] of the measured, nominal and identified ``curves``."""
    tau, nom, pred = curves
    sel = (t >= a) & (t <= b)
    zx.plot(t[sel], tau[sel], color=TRAIN, lw=2.2, alpha=0.55)
    zx.plot(t[sel], nom[sel], color=NOM, lw=1.0)
    zx.plot(t[sel], pred[sel], color=PRED, lw=1.0)
    zx.set_title(f"zoom {a:.1f}-{b:.1f} s", fontsize=8)
    zx.tick_params(labelsize=7)
    zx.grid(alpha=0.3)


def _residual_panel(hx, curves, unit: str, bins: int) -> None:
    """Histograms of the residuals ``tau - tau_nominal`` and ``tau - tau_pred`` [unit]."""
    tau, nom, pred = curves
    r_id, r_nom = tau - pred, tau - nom
    lim = float(np.percentile(np.abs(np.concatenate([r_id, r_nom])), 99.5)) or 1.0
    edges = np.linspace(-lim, lim, int(bins) + 1).tolist()
    hx.hist(r_nom, bins=edges, color=NOM, alpha=0.5, label="nominal")
    hx.hist(r_id, bins=edges, color=PRED, alpha=0.7, label="identified")
    hx.set_title(f"residual [{unit}]", fontsize=8)
    hx.tick_params(labelsize=7)
    hx.set_yticks([])
