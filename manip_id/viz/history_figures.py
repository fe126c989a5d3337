"""Figures of a motion over time: parameter histories, tracking errors, trajectories.

As :mod:`.figures` (re-exported there): plain arrays in, one PNG written atomically, the
:class:`matplotlib.figure.Figure` returned. Shapes: ``t`` [s] (N,); per-joint signals
(N, n); parameter histories (K, p).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from .._checks import as_float_array, check_finite
from ..errors import InputError
from ..robot.parameters import bounded_range
from .plotting import (
    PRED,
    VAL,
    VPRED,
    FigureOptions,
    names_for,
    new_figure,
    save,
    series,
    stride,
    units_for,
)


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
    t, th = series(t, theta_hat, "t", "theta_hat")
    p = th.shape[1]
    names = names_for(names, p, "parameter names", "parameter")
    units = units_for(units if units is not None else [""] * p, p)
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
    fig, axes = new_figure(len(order), cols=3, width=12.0, row_height=2.2)
    k = stride(len(t))
    for ax, i in zip(axes, order, strict=True):
        ax.plot(t[::k], th[::k, i], color=PRED, lw=1.0, label="estimate")
        if true is not None:
            ax.axhline(true[i], color=VPRED, ls="--", lw=1.0, label="true")
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
    return save(fig, path)


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
    t, err = series(t, error, "t", "error")
    n = err.shape[1]
    base = None
    if baseline is not None:
        _, base = series(t, baseline, "t", "baseline", width=n)
    names = names_for(joint_names, n, "joint names", "joint")
    fig, (top, bottom) = new_figure(2, width=10.0, row_height=2.6)
    k = stride(len(t))
    for j in range(n):
        top.plot(t[::k], err[::k, j], lw=0.9, label=names[j])
    top.set_ylabel(f"q - q_d [{units}]")
    top.legend(fontsize=7, ncol=min(n, 7), loc="upper right")
    top.set_title(f"per joint ({labels[0]})", fontsize=9)
    top.grid(alpha=0.3)
    floor = 1e-12
    bottom.semilogy(
        t[::k], np.maximum(np.linalg.norm(err, axis=1)[::k], floor), color=PRED, label=labels[0]
    )
    if base is not None:
        bottom.semilogy(
            t[::k],
            np.maximum(np.linalg.norm(base, axis=1)[::k], floor),
            color=VPRED,
            ls="--",
            label=labels[1],
        )
    bottom.set_ylabel(f"|q - q_d| [{units}]")
    bottom.set_xlabel("time [s]")
    bottom.legend(fontsize=8)
    bottom.grid(alpha=0.3, which="both")
    fig.suptitle(title)
    return save(fig, path)


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
    t, q = series(t, q, "t", "q")
    n = q.shape[1]
    lo = as_float_array(lower, "lower", ndim=1)
    hi = as_float_array(upper, "upper", ndim=1)
    if lo.shape != (n,) or hi.shape != (n,):
        raise InputError(f"lower.shape={lo.shape}, upper.shape={hi.shape} but q.shape={q.shape}")
    names, units = names_for(joint_names, n, "joint names", "joint"), units_for(units, n)
    cols = 2 if n > 3 else 1
    fig, axes = new_figure(n, cols=cols, width=11.0 if cols == 2 else 9.0, row_height=1.9)
    k = stride(len(t))
    for j, ax in enumerate(axes):
        ax.plot(t[::k], q[::k, j], color=PRED, lw=1.0, label="q")
        bounded = bool(bounded_range(lo[j], hi[j]))
        if bounded:
            span = hi[j] - lo[j]
            ymin = min(lo[j], q[:, j].min()) - 0.12 * span
            ymax = max(hi[j], q[:, j].max()) + 0.12 * span
            ax.axhspan(ymin, lo[j], color=VPRED, alpha=0.15)
            ax.axhspan(hi[j], ymax, color=VPRED, alpha=0.15)
            ax.axhline(lo[j], color=VPRED, lw=1.0, label="limits")
            ax.axhline(hi[j], color=VPRED, lw=1.0)
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
    return save(fig, path)


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
    options: FigureOptions | None = None,
) -> Figure:
    """Convergence of an online law: base-parameter relative errors and prediction error.

    Top: ``|theta_hat_i(t) - ref_i| / max(|ref_i|, 1e-3 max|ref|)`` [-] on a log scale for
    the ``max_lines`` parameters that end farthest from ``reference`` (plus the median
    over all of them, black); the last 10 % of the time is shaded, where a converged
    estimate no longer moves. Bottom: the prediction-error norm ``|eps(t)|`` [N m]
    (its moving median), relative to ``torque_rms`` when given (``error_label`` names it
    otherwise, e.g. an error that is already relative).

    t: [s], shape (K,); theta_hat: shape (K, r); reference: shape (r,) (the truth of
    a simulation, or the batch / final estimate); prediction_error: shape (K,);
    options: title, ``error_label``, ``max_lines``.
    """
    o = options or FigureOptions()
    error_label, max_lines, title = o.error_label, o.max_lines, o.title or "online estimate"
    t, th = series(t, theta_hat, "t", "theta_hat")
    r = th.shape[1]
    names = names_for(names, r, "parameter names", "parameter")
    ref = as_float_array(reference, "reference", ndim=1)
    if ref.shape != (r,):
        raise InputError(f"reference.shape={ref.shape} but theta_hat.shape={th.shape}")
    check_finite(ref, "reference")
    scale = np.maximum(np.abs(ref), 1e-3 * max(float(np.abs(ref).max()), 1e-300))
    rel = np.abs(th - ref) / scale  # (K, r)
    order = np.argsort(-rel[-1])[: min(int(max_lines), r)]
    n_axes = 2 if prediction_error is not None else 1
    fig, axes = new_figure(n_axes, width=11.0, row_height=3.0)
    ax = axes[0]
    k = stride(len(t))
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
        a.axvspan(tail, t[-1], color=VAL, alpha=0.15, lw=0)
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
        _prediction_error_panel(axes[1], t, prediction_error, torque_rms, error_label)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(title)
    return save(fig, path)


def _prediction_error_panel(bx, t, prediction_error, torque_rms, error_label: str) -> None:
    """``|eps(t)|`` per sample and its moving median, relative to ``torque_rms`` if given."""
    k = stride(len(t))
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
    bx.semilogy(
        t[ok][::k],
        np.maximum(ee[::k], 1e-12),
        color=PRED,
        lw=0.4,
        alpha=0.5,
        label="|eps| per sample",
    )
    bx.semilogy(
        t[ok][::k], np.maximum(smooth[::k], 1e-12), color=VPRED, lw=1.4, label="moving median"
    )
    bx.set_ylabel(label, fontsize=8)
    bx.legend(fontsize=7)
