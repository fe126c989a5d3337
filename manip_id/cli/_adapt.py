"""``manip-id adapt`` once it runs: the adaptive and the fixed-parameter closed loops,
printed, saved and reported (the options are declared in :mod:`.adapt`).
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from ..control.adaptive import CompositeLaw, default_gains
from ..control.closed_loop import ClosedLoopOptions, compare_fixed, default_reference, with_payload
from ..errors import InputError
from ..simulation import perturb_parameters, require_physical
from ..trajectories import trajectory_to_configuration
from ..viz.adapt_report import write_adapt_report
from ._common import finish, reserve_outputs
from ._runtime import robot_from_args

#: The harmonics of the reference (:func:`~manip_id.control.default_reference`'s default).
HARMONICS = 3


def _compare(robot, args: argparse.Namespace):
    """The adaptive and the fixed-parameter runs on the perturbed plant (:func:`compare_fixed`)."""
    if not (math.isfinite(args.kappa) and args.kappa >= 0):  # checked given or not
        raise InputError(f"--kappa must be a rate >= 0 [1/s], got {args.kappa}")
    if math.isfinite(args.rate) and args.rate > 0 and args.period * args.rate < 2 * HARMONICS:
        raise InputError(
            f"--period {args.period:g} s is too short for the reference's {HARMONICS} harmonics "
            f"at {args.rate:g} Hz: at least {2 * HARMONICS / args.rate:g} s"
        )
    theta0 = robot.nominal_parameters
    require_physical(robot, theta0)  # the simulated plant: a message naming the body
    theta_true = perturb_parameters(robot, args.perturb, seed=args.seed)
    theta_true = with_payload(robot, theta_true, args.payload)
    reference = default_reference(
        robot, amplitude=args.amplitude, period=args.period, harmonics=HARMONICS, seed=args.seed
    )
    q_start = trajectory_to_configuration(robot, reference.sample(0.0)[0])
    gains = default_gains(
        robot,
        theta0,
        q_start,
        lam=args.lam,
        kd_rate=args.kd_rate,
        gamma=args.gamma,
        dead_zone=args.dead_zone,
        composite=CompositeLaw(
            kappa=args.kappa if args.composite else 0.0,
            filter_bandwidth=args.filter,
            gain=args.gain if args.composite else "constant",
            forgetting=args.forgetting,
        ),
    )
    return compare_fixed(
        robot,
        theta_true,
        theta0,
        reference=reference,
        gains=gains,
        options=ClosedLoopOptions(
            duration=args.duration,
            rate=args.rate,
            substeps=args.substeps,
            integrator=args.integrator,
            noise_q=args.noise_q,
            noise_dq=args.noise_dq,
            seed=args.seed,
            record_every=max(int(round(args.rate / 100.0)), 1) if math.isfinite(args.rate) else 1,
        ),
    )


def _print_run(robot, cmp, law: str, args: argparse.Namespace) -> None:
    a, f = cmp.adaptive, cmp.fixed
    print(
        f"robot {robot.name}: nv={robot.nv}, {robot.n_parameters} parameters; true = nominal "
        f"perturbed (perturb_parameters rel={args.perturb:g}, seed={args.seed})"
        + (f" + {args.payload:g} kg payload" if args.payload else "")
    )
    print(
        f"{args.duration:g} s at {args.rate:g} Hz ({args.integrator}, {args.substeps} "
        f"substep(s)), {law} adaptation"
    )
    print(
        f"tracking error |q - q_d| [rad]: start {a.initial_tracking_error:.4g}, "
        f"end {a.final_tracking_error:.3g} (fixed parameters: {f.final_tracking_error:.3g})"
    )
    print(
        f"rms tracking error [rad]: adaptive {a.rms_tracking_error:.4g}, "
        f"fixed {f.rms_tracking_error:.4g}; last quarter: adaptive "
        f"{a.rms_tracking_error_tail:.3g}, fixed {f.rms_tracking_error_tail:.3g}"
    )
    print(
        f"torque prediction error on new states: start {a.initial_prediction_error:.2%}, "
        f"end {a.final_prediction_error:.2%}"
    )
    err0 = np.abs(a.theta0 - a.theta_true)
    err1 = np.abs(a.theta_hat[-1] - a.theta_true)
    print(
        f"parameter error |theta_hat - theta|: start {np.linalg.norm(err0):.4g}, "
        f"end {np.linalg.norm(err1):.4g} (standard parameters need not converge: "
        "only the excited combinations do)"
    )
    order = np.argsort(-err0)[:5]
    print(f"  {'parameter':28s} {'true':>10s} {'start':>10s} {'end':>10s}")
    for i in order:
        print(
            f"  {robot.parameter_names[i]:28s} {a.theta_true[i]:10.4g} {a.theta0[i]:10.4g} "
            f"{a.theta_hat[-1, i]:10.4g}"
        )
    print(f"real-time factor {a.real_time_factor:.1f} (wall {a.wall_time:.3f} s)")


def _document(robot, cmp, law: str, args: argparse.Namespace) -> dict:
    a, f = cmp.adaptive, cmp.fixed
    return {
        "robot": robot.name,
        "law": law,
        "perturb": args.perturb,
        "payload": args.payload,
        **cmp.summary(),
        "rms_tracking_error_per_joint": {
            "adaptive": dict(
                zip(robot.dof_names, a.rms_tracking_error_per_joint.tolist(), strict=True)
            ),
            "fixed": dict(
                zip(robot.dof_names, f.rms_tracking_error_per_joint.tolist(), strict=True)
            ),
        },
        "parameter_names": robot.parameter_names,
        "theta_true": a.theta_true,
        "theta0": a.theta0,
        "theta_hat": a.theta_hat[-1],
        "history": {"t": a.t, "prediction_error": a.prediction_error},
    }


def run(args: argparse.Namespace) -> int:
    """``manip-id adapt``: the closed loop simulated, printed, saved and reported."""
    outputs = reserve_outputs(args)  # every output checked (and the report claimed) first
    robot = robot_from_args(args)
    cmp = _compare(robot, args)
    law = "composite" if cmp.adaptive.composite else "plain"
    _print_run(robot, cmp, law, args)
    out = _document(robot, cmp, law, args)
    if args.json:
        outputs.write_json(args.json, out)
    path = None
    if args.report is not None:
        run_name = (
            f"{robot.name}, {law} Slotine-Li adaptation, {args.duration:g} s at "
            f"{args.rate:g} Hz, perturb {args.perturb:g}"
            + (f", payload {args.payload:g} kg" if args.payload else "")
        )
        settings = {"duration [s]": args.duration, "rate [Hz]": args.rate}
        path = write_adapt_report(
            args.report_claim,
            robot,
            cmp,
            out,
            run_name=run_name,
            settings=settings,
            force=args.force,
        )
    return finish(args, outputs, path)
