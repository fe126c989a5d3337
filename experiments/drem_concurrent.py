"""DREM and concurrent learning on the lesson's mass-spring-damper, beside the gradient law.

The plant, input and regression are the lesson's, shared with ``experiments/msd_gradient.py``
through ``experiments/_lesson.py``
(``y'' = phi^T theta``, ``phi = [-y, -y', u]``, ``theta = [k/m, c/m, b/m] =
[2.5, 0.4, 0.75]``, dt = 0.002 s, theta_hat(0) = [0.4, 0.1, 0.2]; gradient law
Gamma = diag(8, 8, 4)). Two experiments:

1. the multisine input ``u = 1.2 sin 1.1t + 0.7 sin 2.3t`` throughout: DREM
   (Kreisselmeier extension, bandwidth ``alpha``, gain ``gamma``) against the
   gradient law; every ``|theta_tilde_i(t)|`` of DREM is checked non-increasing;
2. the same input held constant after 5 s (no persistent excitation afterwards):
   concurrent learning (the lesson's Gamma, a history stack of 6 samples chosen to
   maximize its minimum singular value) against the gradient law, which stalls.

Prints the time after which ``||theta_tilde|| / ||theta||`` stays below 1 % for
each law (within ``--horizon`` seconds), and writes two figures of the parameter
errors over time (log scale) into ``--out``.

Run: ``.venv/bin/python experiments/drem_concurrent.py [--out DIR] [--horizon 100] [--json OUT]``
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _lesson import DT, GAMMA, THETA, THETA0, run, time_to  # noqa: E402

from manip_id._io import atomic_write, write_json  # noqa: E402
from manip_id.estimators import (  # noqa: E402
    ConcurrentLearningEstimator,
    DREMEstimator,
    GradientEstimator,
)
from manip_id.estimators.drem import DEFAULT_GAMMA  # noqa: E402

HOLD = 5.0  # [s]
NAMES = ("k/m", "c/m", "b/m")


def figure(path: Path, title: str, runs: dict, vline: float | None = None) -> None:
    """|theta_tilde_i(t)| per parameter, one panel each, every law on the same axes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(7.5, 7.0), sharex=True)
    for label, (h, style) in runs.items():
        err = np.abs(h.theta - THETA)
        for i, ax in enumerate(axes):
            ax.semilogy(h.t, np.maximum(err[:, i], 1e-16), style, label=label, lw=1.2)
    for i, ax in enumerate(axes):
        ax.set_ylabel(f"|theta_tilde| {NAMES[i]}")
        ax.grid(True, which="both", alpha=0.3)
        if vline is not None:
            ax.axvline(vline, color="gray", ls=":", lw=1)
    axes[0].set_title(title)
    axes[0].legend(loc="upper right")
    axes[-1].set_xlabel("t [s]")
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=110))
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=".", help="folder for the two PNG figures (default .)")
    ap.add_argument("--horizon", type=float, default=100.0, help="simulated time [s]")
    ap.add_argument("--alpha", type=float, default=0.5, help="DREM extension bandwidth [1/s]")
    ap.add_argument(
        "--gamma",
        type=float,
        default=DEFAULT_GAMMA,
        help="DREM per-parameter rate of the normalized law [1/s]",
    )
    ap.add_argument("--stack", type=int, default=6, help="concurrent-learning stack size")
    ap.add_argument("--json", metavar="OUT", help="write the figures as JSON")
    args = ap.parse_args(argv)
    out = Path(args.out)
    if not out.is_dir():
        ap.error(f"--out {out} is not a folder")
    n = round(args.horizon / DT)
    every = 10

    # 1. persistent excitation: DREM against the gradient law
    grad = GradientEstimator(THETA0, GAMMA, record_every=every)
    drem = DREMEstimator(THETA0, args.gamma, alpha=args.alpha, record_every=every)
    run([grad, drem], n)
    err = np.abs(drem.history.theta - THETA)
    monotone = bool(np.all(np.diff(err, axis=0) <= 1e-12))
    t_grad, t_drem = time_to(grad.history), time_to(drem.history)

    # 2. input held after 5 s: concurrent learning against the gradient law
    grad_h = GradientEstimator(THETA0, GAMMA, record_every=every)
    cl = ConcurrentLearningEstimator(THETA0, GAMMA, stack_size=args.stack, record_every=every)
    run([grad_h, cl], n, hold=HOLD)
    t_grad_h, t_cl = time_to(grad_h.history), time_to(cl.history)
    rel = lambda th: float(np.linalg.norm(th - THETA) / np.linalg.norm(THETA))  # noqa: E731

    fmt = lambda t: "not within the horizon" if t is None else f"{t:.2f} s"  # noqa: E731
    print(f"lesson plant, dt = {DT} s, horizon {args.horizon:g} s; time to 1 % parameter error")
    print(f"  multisine input:      gradient {fmt(t_grad)}, DREM {fmt(t_drem)}")
    print(f"  DREM: every |theta_tilde_i(t)| non-increasing: {monotone}")
    print(
        f"  input held after {HOLD:g} s: gradient {fmt(t_grad_h)}, concurrent learning {fmt(t_cl)}"
    )
    print(
        f"  at the horizon, held input: gradient error {rel(grad_h.theta):.3%}, "
        f"concurrent learning {rel(cl.theta):.2e} (stack rank {cl.stack_rank}, "
        f"sigma_min {cl.sigma_min:.3g})"
    )
    figure(
        out / "drem_vs_gradient.png",
        f"DREM (alpha {args.alpha:g}, gamma {args.gamma:g}) and the gradient law, multisine input",
        {"gradient (lesson)": (grad.history, "C0-"), "DREM": (drem.history, "C3-")},
    )
    figure(
        out / "concurrent_vs_gradient.png",
        f"concurrent learning and the gradient law, input held after {HOLD:g} s",
        {"gradient (lesson)": (grad_h.history, "C0-"), "concurrent learning": (cl.history, "C2-")},
        vline=HOLD,
    )
    print(f"wrote {out / 'drem_vs_gradient.png'} and {out / 'concurrent_vs_gradient.png'}")
    if args.json:
        write_json(
            args.json,
            {
                "horizon": args.horizon,
                "time_to_1pct_gradient": t_grad,
                "time_to_1pct_drem": t_drem,
                "drem_monotone": monotone,
                "time_to_1pct_gradient_held": t_grad_h,
                "time_to_1pct_concurrent_held": t_cl,
                "final_error_gradient_held": rel(grad_h.theta),
                "final_error_concurrent_held": rel(cl.theta),
                "drem": {"alpha": args.alpha, "gamma": args.gamma},
                "stack_size": args.stack,
            },
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
