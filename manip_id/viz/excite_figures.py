"""The figures of an excitation design (``manip-id excite --report``), drawn from the design.

- :func:`limit_usage_figure`: per limit kind (position, velocity, acceleration, torque) one
  bar per joint, its peak use of the allowed range [%] (100 % = the limit less the margin;
  :attr:`~manip_id.trajectories.verify.DesignCheck.usage`); a kind without a limit shows
  "no limit";
- :func:`motion_figure`: the designed positions [rad or m], velocities and nominal torques
  ``pinocchio.rnea`` [N m or N] over time, one line per joint;
- :func:`std_figure`: the predicted relative std ``std / |value|`` [%] of each base
  parameter after the run (and before it, with a previous result), on a log axis, with the
  line above which a parameter counts as poorly identified.
"""

from __future__ import annotations

import numpy as np

from ..trajectories.verify import KINDS
from .plotting import new_figure, save

#: Sampling of the motion figure [Hz] (at most; the design's own rate when lower).
MOTION_RATE = 100.0


def limit_usage_figure(path, design) -> None:
    """Peak use of each limit per joint [%] (module docstring), 2 x 2 axes."""
    names = list(design.joint_names)
    fig, axes = new_figure(len(KINDS), cols=2, width=11.0, row_height=2.6)
    x = np.arange(len(names))
    for ax, kind in zip(axes, KINDS, strict=True):
        use = 100.0 * np.asarray(design.check.usage[kind], dtype=float)
        shown = np.where(np.isfinite(use), use, 0.0)
        colors = ["#b42318" if u > 100.0 else "#1f77b4" for u in shown]
        ax.bar(x, shown, color=colors)
        for k in np.flatnonzero(~np.isfinite(use)):
            ax.text(x[k], 2.0, "no limit", rotation=90, ha="center", va="bottom", fontsize=7)
        ax.axhline(100.0, color="k", lw=0.8, ls="--")
        ax.set_ylim(0.0, max(110.0, float(np.max(shown, initial=0.0)) * 1.05))
        ax.set_title(f"{kind}: peak use of the allowed range", fontsize=9)
        ax.set_ylabel("[%]")
        ax.set_xticks(x, names, rotation=30, ha="right", fontsize=7)
    fig.suptitle(
        f"limit usage (100 % = the limit less the {100 * design.options.margin:g} % margin)",
        fontsize=10,
    )
    save(fig, path)


def motion_figure(path, design, robot) -> None:
    """Positions, velocities and nominal torques of the designed motion over time."""
    rate = min(MOTION_RATE, design.rate)
    t, q, dq, _ = design.samples(rate)
    tau = design.torques(robot, rate)
    fig, axes = new_figure(3, width=11.0, row_height=2.3)
    for ax, y, label in zip(
        axes,
        (q, dq, tau),
        ("position [rad or m]", "velocity [rad/s or m/s]", "nominal torque [N m or N]"),
        strict=True,
    ):
        for j, name in enumerate(design.joint_names):
            ax.plot(t, y[:, j], lw=0.9, label=name)
        ax.set_ylabel(label, fontsize=8)
        ax.grid(alpha=0.3)
    if design.check.closest_time is not None and np.isfinite(design.check.min_clearance):
        for ax in axes:
            ax.axvline(design.check.closest_time, color="#b42318", lw=0.8, ls=":")
        axes[0].set_title(
            f"the designed motion (dotted: the closest approach, t = "
            f"{design.check.closest_time:.3g} s)",
            fontsize=9,
        )
    else:
        axes[0].set_title("the designed motion", fontsize=9)
    axes[-1].set_xlabel("t [s]")
    axes[0].legend(fontsize=7, ncol=min(len(design.joint_names), 7), loc="lower center",
                   bbox_to_anchor=(0.5, 1.12), frameon=False)  # fmt: skip
    save(fig, path)


def std_figure(path, design, threshold: float) -> None:
    """Predicted relative std per base parameter [%], log axis; before the run with a prior."""
    names = list(design.base_names)
    after = 100.0 * np.asarray(design.predicted_relative_std, dtype=float)
    width = min(24.0, max(8.0, 0.22 * len(names) + 2.0))
    fig, axes = new_figure(1, width=width, row_height=3.6, min_height=4.6)
    ax = axes[0]
    x = np.arange(len(names))
    finite = np.isfinite(after)
    if design.prior_std is not None:
        before = 100.0 * np.asarray(design.prior_relative_std, dtype=float)
        ok = np.isfinite(before)
        ax.bar(x[ok] - 0.2, before[ok], 0.4, color="#bbbbbb", label="before (the result)")
        ax.bar(x[finite] + 0.2, after[finite], 0.4, color="#1f77b4", label="after (predicted)")
    else:
        ax.bar(x[finite], after[finite], 0.7, color="#1f77b4", label="predicted")
    for k in np.flatnonzero(~finite):
        ax.text(x[k], 1.0, "value ~ 0", rotation=90, ha="center", va="bottom", fontsize=5,
                color="#777777")  # fmt: skip
    ax.axhline(100.0 * threshold, color="#b42318", lw=0.8, ls="--", label="poorly identified")
    ax.set_yscale("log")
    ax.set_ylabel("relative std [%]")
    ax.set_xticks(x, names, rotation=90, fontsize=6)
    ax.set_xlim(-0.7, len(names) - 0.3)
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title("predicted relative std of each base parameter (log scale)", fontsize=9)
    save(fig, path)
