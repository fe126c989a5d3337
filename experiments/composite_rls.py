"""Composite adaptive control with an RLS-type gain against the constant-gain laws.

The run of ``manip-id adapt ROBOT --composite`` (true parameters: the nominal
ones perturbed by 30 %, seed 0; reference: the default Fourier reference,
amplitude 0.4, period 5 s; 10 s at 1 kHz; Lambda = 20, K_D = 50 M(q_d(0)),
Gamma = diag(scale^2), kappa = 50 1/s, filter 20 rad/s), with three laws:

- the plain Slotine-Li law (the gradient law on the tracking error ``s``),
- the composite law with the constant gain Gamma,
- the composite law with the RLS-type gain P(t) started at Gamma (Slotine & Li).

Prints, for each, the torque prediction error on new states at the end and the
time after which it stays below 1 % and 0.5 %, and writes a figure of the
prediction error and of the standard-parameter error over time.

Run: ``.venv/bin/python experiments/composite_rls.py [--robot panda] [--out DIR] [--json OUT]``
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from manip_id import load_robot  # noqa: E402
from manip_id._io import atomic_write, write_json  # noqa: E402
from manip_id.control.adaptive import CompositeLaw, default_gains  # noqa: E402
from manip_id.control.closed_loop import ClosedLoopOptions, default_reference, simulate  # noqa: E402
from manip_id.simulation import perturb_parameters  # noqa: E402
from manip_id.trajectories import trajectory_to_configuration  # noqa: E402

LAWS = {
    "plain Slotine-Li (gradient)": CompositeLaw(kappa=0.0),
    "composite, constant Gamma": CompositeLaw(kappa=50.0, gain="constant"),
    "composite, RLS gain P(t)": CompositeLaw(kappa=50.0, gain="rls"),
}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default="panda")
    ap.add_argument("--duration", type=float, default=10.0, help="simulated time [s]")
    ap.add_argument("--out", default=".", help="folder for the PNG figure (default .)")
    ap.add_argument("--json", metavar="OUT", help="write the figures as JSON")
    args = ap.parse_args(argv)
    out = Path(args.out)
    if not out.is_dir():
        ap.error(f"--out {out} is not a folder")
    robot = load_robot(args.robot)
    theta0 = robot.nominal_parameters
    theta_true = perturb_parameters(robot, 0.3, seed=0)
    reference = default_reference(robot, amplitude=0.4, period=5.0, seed=0)
    q_start = trajectory_to_configuration(robot, reference.sample(0.0)[0])
    runs, summary = {}, {}
    for label, law in LAWS.items():
        gains = default_gains(robot, theta0, q_start, lam=20.0, kd_rate=50.0, composite=law)
        run = simulate(
            robot,
            theta_true,
            theta0,
            reference=reference,
            gains=gains,
            options=ClosedLoopOptions(duration=args.duration, rate=1000.0, record_every=10),
        )
        runs[label] = run
        t1, t05 = run.time_to_prediction_error(0.01), run.time_to_prediction_error(0.005)
        summary[label] = {
            "final_prediction_error": run.final_prediction_error,
            "time_to_1pct": None if math.isinf(t1) else t1,
            "time_to_0.5pct": None if math.isinf(t05) else t05,
            "rms_tracking_error_tail": run.rms_tracking_error_tail,
            "wall_time": run.wall_time,
        }
    fmt = lambda t: "never" if t is None else f"{t:.2f} s"  # noqa: E731
    print(f"{robot.name}, {args.duration:g} s at 1 kHz, true = nominal perturbed 30 %")
    print(
        f"{'law':30s} {'final pred. err':>15s} {'< 1 % from':>11s} {'< 0.5 % from':>13s} "
        f"{'tail rms |q~|':>14s}"
    )
    for label, s in summary.items():
        print(
            f"{label:30s} {s['final_prediction_error']:15.3%} {fmt(s['time_to_1pct']):>11s} "
            f"{fmt(s['time_to_0.5pct']):>13s} {s['rms_tracking_error_tail']:14.3g}"
        )

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7.5, 6.0), sharex=True)
    norm = np.linalg.norm(theta_true)
    for (label, run), color in zip(runs.items(), ("C0", "C1", "C3"), strict=True):
        ax1.semilogy(run.t, run.prediction_error, color=color, label=label)
        rel = np.linalg.norm(run.theta_hat - theta_true, axis=1) / norm
        ax2.plot(run.t, rel, color=color, label=label)
    ax1.axhline(0.005, color="gray", ls=":", lw=1)
    ax1.set_ylabel("torque prediction error")
    ax1.legend(loc="upper right")
    ax1.grid(True, which="both", alpha=0.3)
    ax1.set_title(f"{robot.name}: composite adaptation with an RLS-type gain")
    ax2.set_ylabel("||theta_hat - theta|| / ||theta||")
    ax2.set_xlabel("t [s]")
    ax2.grid(True, alpha=0.3)
    fig.tight_layout()
    path = out / f"composite_rls_{robot.name}.png"
    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=110))
    plt.close(fig)
    print(f"wrote {path}")
    if args.json:
        write_json(args.json, {"robot": robot.name, "duration": args.duration, "laws": summary})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
