"""Slotine-Li adaptive control on the panda and the ur5: the figures of issue 6.

    python experiments/adaptive_control.py [--robots panda ur5] [--duration 10] [--json OUT]

For each robot (true parameters: nominal perturbed by manip_id.simulation.perturb_parameters
with rel = 0.1, seed 1,
plus a 1 kg payload 0.1 m along the last joint axis; the estimate starts at the
nominal parameters):

1. Lyapunov check (armature and viscous friction modelled, RK4 at 5 kHz, 1 s):
   V = 1/2 s^T M s + 1/2 theta_tilde^T Gamma^-1 theta_tilde must not increase and
   its decrease must equal the integral of s^T (K_D + F_v) s (+ kappa |eps|^2).
2. Tracking at 1 kHz: tracking error at start and end; RMS tracking error with
   adaptation and with the wrong parameters held fixed (same run).
3. Torque prediction on new states (uniform in the region the reference excites):
   relative error over time for the plain and the composite law, and the time at
   which each falls (for good) below 50 %, 20 %, 10 % of its initial value.
"""

from __future__ import annotations

import argparse

import numpy as np

from manip_id import load_robot
from manip_id.control.adaptive import default_gains, lyapunov_function
from manip_id.control.closed_loop import (
    ClosedLoopOptions,
    default_reference,
    simulate,
    with_payload,
)
from manip_id.simulation import perturb_parameters


def lyapunov_check(name: str) -> dict:
    robot = load_robot(name, armature=True, friction="viscous")
    theta0 = robot.nominal_parameters.copy()
    theta0[robot.n_rigid :] = 0.05  # armature [kg m^2] and viscous friction [N m s/rad]
    theta = with_payload(robot, perturb_parameters(robot, 0.1, seed=1, theta=theta0), 1.0)
    out = {}
    for law, kappa in (("plain", 0.0), ("composite", 50.0)):
        gains = default_gains(robot, theta0, composite=kappa)
        run = simulate(
            robot,
            theta,
            theta0,
            gains=gains,
            options=ClosedLoopOptions(duration=1.0, rate=5000, integrator="rk4", record_every=5),
        )
        V = lyapunov_function(robot, theta, run.gamma, run.q, run.s, run.theta_hat)
        out[law] = {
            "V_start": float(V[0]),
            "V_end": float(V[-1]),
            "max_increase_over_V0": float(np.diff(V).max() / V[0]),
            "decrease": float(V[0] - V[-1]),
            "predicted_decrease": run.dissipation,
        }
    return out


def tracking_and_prediction(name: str, duration: float) -> dict:
    robot = load_robot(name)
    theta0 = robot.nominal_parameters
    theta = with_payload(robot, perturb_parameters(robot, 0.1, seed=1), 1.0)
    ref = default_reference(robot)
    runs = {}
    for law, kappa, adapt in (
        ("plain", 0.0, True),
        ("composite", 50.0, True),
        ("fixed", 0.0, False),
    ):
        gains = default_gains(robot, theta0, composite=kappa)
        runs[law] = simulate(
            robot,
            theta,
            theta0,
            reference=ref,
            gains=gains,
            adapt=adapt,
            options=ClosedLoopOptions(duration=duration, rate=1000, record_every=10),
        )
    plain, comp = runs["plain"], runs["composite"]
    at = [t for t in (0.0, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0) if t <= duration]
    idx = [int(np.argmin(np.abs(plain.t - t))) for t in at]
    pe0 = plain.initial_prediction_error
    return {
        "initial_tracking_error": plain.initial_tracking_error,
        "final_tracking_error": {k: r.final_tracking_error for k, r in runs.items()},
        "rms_tracking_error": {k: r.rms_tracking_error for k, r in runs.items()},
        "rms_tracking_error_last_quarter": {k: r.rms_tracking_error_tail for k, r in runs.items()},
        "prediction_error_at": {
            law: {f"{t:g}s": float(r.prediction_error[i]) for t, i in zip(at, idx, strict=True)}
            for law, r in (("plain", plain), ("composite", comp))
        },
        "time_to_fraction_of_initial_prediction_error": {
            law: {f"{f:g}": r.time_to_prediction_error(f * pe0) for f in (0.5, 0.2, 0.1)}
            for law, r in (("plain", plain), ("composite", comp))
        },
        "real_time_factor": {k: r.real_time_factor for k, r in runs.items()},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", nargs="+", default=["panda", "ur5"])
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    report = {}
    for name in args.robots:
        lyap = lyapunov_check(name)
        res = tracking_and_prediction(name, args.duration)
        report[name] = {"lyapunov": lyap, **res}
        print(f"== {name}: true = perturb_parameters(rel=0.1, seed=1) + 1 kg payload")
        for law, v in lyap.items():
            rel = (v["decrease"] - v["predicted_decrease"]) / v["predicted_decrease"]
            print(
                f"  Lyapunov ({law}, RK4 5 kHz, 1 s): V {v['V_start']:.4g} -> {v['V_end']:.4g}"
                f", max step increase / V0 = {v['max_increase_over_V0']:.2e}, decrease "
                f"{v['decrease']:.4g} vs predicted {v['predicted_decrease']:.4g} "
                f"({rel:+.2%})"
            )
        fe, rms, tail = (
            res["final_tracking_error"],
            res["rms_tracking_error"],
            res["rms_tracking_error_last_quarter"],
        )
        print(
            f"  tracking |q - q_d| [rad] ({args.duration:g} s at 1 kHz): start "
            f"{res['initial_tracking_error']:.4g}; end plain {fe['plain']:.3g}, composite "
            f"{fe['composite']:.3g}, fixed {fe['fixed']:.3g}"
        )
        print(
            f"  rms tracking error [rad]: plain {rms['plain']:.4g}, composite "
            f"{rms['composite']:.4g}, fixed {rms['fixed']:.4g}; last quarter: plain "
            f"{tail['plain']:.3g}, composite {tail['composite']:.3g}, fixed {tail['fixed']:.3g}"
        )
        for law in ("plain", "composite"):
            pe = "  ".join(f"{t} {v:.2%}" for t, v in res["prediction_error_at"][law].items())
            tt = ", ".join(
                f"{f}: {v:.2f} s"
                for f, v in res["time_to_fraction_of_initial_prediction_error"][law].items()
            )
            print(f"  prediction error {law:9s}: {pe}")
            print(f"    time to fraction of initial ({tt})")
        rtf = res["real_time_factor"]
        print(
            f"  real-time factor: plain {rtf['plain']:.1f}, composite {rtf['composite']:.1f}, "
            f"fixed {rtf['fixed']:.1f}"
        )
    if args.json:
        from manip_id.cli._common import write_json

        write_json(args.json, report)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
