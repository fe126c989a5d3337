"""The rollout figure: measured joint positions against the identified and nominal models
integrated forward from the measured torques (:mod:`manip_id.identification.rollout`).

One row per joint, one column per shown start point; each panel holds the measured
``q`` (thick), the identified model's ``q_sim`` and the nominal model's (dashed) over one
horizon. A model whose rollout diverged ends where its state left the finite numbers.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from ..errors import InputError
from .plotting import NOM, PRED, TRAIN, new_figure, save


def rollout_traces(
    path, traces: Sequence, joint_names: Sequence[str], *, title: str = "rollout"
) -> Figure:
    """Write the figure to ``path`` (PNG) and return it.

    ``traces``: objects with ``t`` (H+1,) [s] and ``measured``, ``identified`` and
    ``nominal`` (None or) arrays of shape (H+1, nv) [rad or m]
    (:class:`~manip_id.identification.rollout.Trace`).
    """
    traces = list(traces)
    if not traces:
        raise InputError("a rollout figure needs at least one trace")
    nv = np.asarray(traces[0].measured).shape[1]
    if len(joint_names) != nv:
        raise InputError(f"{len(joint_names)} joint names but the traces have {nv} joints")
    cols = len(traces)
    fig, axes = new_figure(nv * cols, cols=cols, width=4.0 * cols, row_height=1.5)
    for c, tr in enumerate(traces):
        t = np.asarray(tr.t) - tr.t[0]
        for j in range(nv):
            ax = axes[j * cols + c]
            ax.plot(t, tr.measured[:, j], color=TRAIN, lw=2.4, alpha=0.45, label="measured")
            ax.plot(t, tr.identified[:, j], color=PRED, lw=1.0, label="identified")
            if tr.nominal is not None:
                ax.plot(t, tr.nominal[:, j], color=NOM, lw=1.0, ls="--", label="nominal")
            lo, hi = float(np.min(tr.measured[:, j])), float(np.max(tr.measured[:, j]))
            pad = max(hi - lo, 0.02)
            ax.set_ylim(lo - pad, hi + pad)  # a diverging model leaves the panel, visibly
            ax.tick_params(labelsize=6)
            ax.grid(alpha=0.3)
            if c == 0:
                ax.set_ylabel(f"{joint_names[j]}\n[rad]", fontsize=7)
            if j == 0:
                ax.set_title(f"from t = {tr.t[0]:.2f} s", fontsize=8)
        axes[(nv - 1) * cols + c].set_xlabel("time from start [s]", fontsize=7)
    axes[0].legend(loc="best", fontsize=6)
    fig.suptitle(title)
    return save(fig, path)


__all__ = ["rollout_traces"]
