"""The textbook mass-spring-damper example of the gradient adaptation law, reproduced exactly.

Plant ``m y'' + c y' + k y = b u`` with m = 2, c = 0.8, k = 5, b = 1.5 and
``u(t) = 1.2 sin(1.1 t) + 0.7 sin(2.3 t)``, written as the scalar regression

    y'' = phi^T theta,   phi = [-y, -y', u],   theta = [k/m, c/m, b/m] = [2.5, 0.4, 0.75].

Loop (dt = 0.002 s, 25 s: 12,501 time points, 12,500 updates), at each step k:

1. the true acceleration ``z = y'' = phi_k^T theta`` from the current state;
2. the estimator update with ``eps = phi_k^T theta_hat - z`` (estimate before the
   update), gradient law ``theta_hat += -dt Gamma phi eps``, Gamma = diag(8, 8, 4),
   theta_hat(0) = [0.4, 0.1, 0.2];
3. explicit Euler on the plant: ``y += dt y'``, ``y' += dt y''``; y(0) = 0.4, y'(0) = -0.2.

Expected after 25 s: theta_hat = [2.40306, 0.38472, 0.72280] (not yet converged:
the point of the example) and a mean |eps| over the last 20 % of the updates of
about 0.01132. On the same data, stacked least squares recovers theta to
round-off, and recursive least squares (P0 = p0 I, no forgetting) reaches 1 %
parameter error ``||theta_hat - theta|| / ||theta||`` long before the gradient
law; the script continues the same simulation beyond 25 s to time the gradient law.

Run: ``.venv/bin/python experiments/msd_gradient.py [--json OUT] [--p0 100] [--horizon 100]``
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _lesson import DT, GAMMA, THETA, THETA0, run, time_to  # noqa: E402

from manip_id.cli._common import write_json  # noqa: E402
from manip_id.estimators import (  # noqa: E402
    GradientEstimator,
    InformationAccumulator,
    RLSEstimator,
    solve_accumulator,
    solve_stacked,
)

DURATION = 25.0  # [s]
EXPECTED = np.array([2.40306, 0.38472, 0.72280])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", metavar="OUT", help="write the figures as JSON")
    ap.add_argument("--p0", type=float, default=100.0, help="RLS initial covariance P0 = p0 I")
    ap.add_argument(
        "--horizon",
        type=float,
        default=100.0,
        help="simulated time [s] for the 1%% convergence times",
    )
    args = ap.parse_args(argv)

    n = round(DURATION / DT)  # 12,500 updates, 12,501 time points
    grad = GradientEstimator(THETA0, GAMMA)
    rls = RLSEstimator(THETA0, args.p0)
    lesson = run([grad, rls], n)
    phi, z, e_grad = lesson.phi, lesson.z, lesson.errors[0]
    theta_hat = grad.theta
    tail = e_grad[int(0.8 * n) :]
    mae = float(tail.mean())

    stacked = solve_stacked(phi, z)
    acc = InformationAccumulator(3, 1).add(phi, z)
    streamed = solve_accumulator(acc)
    err_stacked = float(np.max(np.abs(stacked.estimate - THETA) / THETA))
    err_streamed = float(np.max(np.abs(streamed.estimate - THETA) / THETA))

    # the same plant run longer, to time the 1 % convergence of both laws
    n_long = round(args.horizon / DT)
    g_long = GradientEstimator(THETA0, GAMMA, record_every=50)
    r_long = RLSEstimator(THETA0, args.p0, record_every=1)
    run([g_long, r_long], n_long)
    t_rls = time_to(r_long.history, 0.01)
    t_grad = time_to(g_long.history, 0.01)

    print(
        f"gradient law after {DURATION:g} s ({n} updates): theta_hat = "
        f"[{theta_hat[0]:.5f}, {theta_hat[1]:.5f}, {theta_hat[2]:.5f}]  "
        f"(expected [2.40306, 0.38472, 0.72280], max diff {np.abs(theta_hat - EXPECTED).max():.2e})"
    )
    print(f"theta_true = [{THETA[0]:.5f}, {THETA[1]:.5f}, {THETA[2]:.5f}]")
    print(f"mean |eps| over the last 20 % = {mae:.5f}  (expected about 0.01132)")
    print(f"stacked LS: max relative error {err_stacked:.2e}; streamed LS: {err_streamed:.2e}")
    print(
        f"RLS (P0 = {args.p0:g} I) after {DURATION:g} s: "
        f"theta_hat = {np.round(rls.theta, 6).tolist()}"
    )
    fmt = lambda t: "not within the horizon" if t is None else f"{t:.3f} s"  # noqa: E731
    print(
        f"time to 1 % parameter error: RLS {fmt(t_rls)}, gradient {fmt(t_grad)} "
        f"(horizon {args.horizon:g} s)"
    )
    if args.json:
        write_json(
            args.json,
            {
                "theta_hat": theta_hat,
                "theta_true": THETA,
                "theta_expected": EXPECTED,
                "mean_abs_error_last_20pct": mae,
                "n_updates": n,
                "dt": DT,
                "rls_theta_hat": rls.theta,
                "rls_p0": args.p0,
                "stacked_ls_theta": stacked.estimate,
                "stacked_ls_max_rel_error": err_stacked,
                "streamed_ls_theta": streamed.estimate,
                "streamed_ls_max_rel_error": err_streamed,
                "time_to_1pct_rls": t_rls,
                "time_to_1pct_gradient": t_grad,
                "horizon": args.horizon,
            },
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
