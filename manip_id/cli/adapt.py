"""``manip-id adapt``: Slotine-Li adaptive tracking on a simulated robot with wrong parameters."""

from __future__ import annotations

import argparse

import numpy as np

from ._common import add_robot_arguments, reserve_outputs, robot_from_args


def register(sub) -> None:
    p = sub.add_parser(
        "adapt",
        help="simulate Slotine-Li adaptive tracking control with wrong initial parameters",
        description="Simulate the Slotine-Li adaptive controller tracking a Fourier reference on "
        "a robot whose true parameters are the nominal ones perturbed (and/or "
        "carrying a payload), starting from the nominal estimate. The same run "
        "with the wrong parameters held fixed is the baseline.",
    )
    add_robot_arguments(p)
    p.add_argument("--duration", type=float, default=10.0, help="simulated time [s] (default 10)")
    p.add_argument("--rate", type=float, default=1000.0, help="control rate [Hz] (default 1000)")
    p.add_argument(
        "--substeps", type=int, default=1, help="physics steps per control step (default 1)"
    )
    p.add_argument(
        "--integrator",
        choices=("euler", "rk4"),
        default="euler",
        help="semi-implicit Euler (default) or RK4",
    )
    p.add_argument(
        "--perturb",
        type=float,
        default=0.3,
        help="relative perturbation of the true body masses, centers of mass and "
        "inertias, in [0, 1) (default 0.3)",
    )
    p.add_argument(
        "--payload",
        type=float,
        default=0.0,
        help="point mass added to the last link of the true robot [kg] (default 0)",
    )
    p.add_argument(
        "--composite",
        action="store_true",
        help="composite adaptation (adds the filtered torque prediction error)",
    )
    p.add_argument(
        "--kappa",
        type=float,
        default=50.0,
        help="weight of the normalized prediction-error term with --composite [1/s] (default 50)",
    )
    p.add_argument(
        "--filter",
        type=float,
        default=20.0,
        help="bandwidth of the composite filter [rad/s] (default 20)",
    )
    p.add_argument(
        "--gain",
        choices=("rls", "constant"),
        default="rls",
        help="with --composite: the RLS-type time-varying gain P(t) started at Gamma (default) "
        "or the constant Gamma",
    )
    p.add_argument(
        "--forgetting",
        type=float,
        default=0.0,
        help="bounded-gain forgetting rate of the RLS gain [1/s] (default 0)",
    )
    p.add_argument("--lam", type=float, default=20.0, help="Lambda [1/s] (default 20)")
    p.add_argument(
        "--kd-rate", type=float, default=50.0, help="K_D = kd_rate * M(q_d(0)) [1/s] (default 50)"
    )
    p.add_argument(
        "--gamma",
        type=float,
        default=1.0,
        help="adaptation gain scale: Gamma = gamma diag(scale^2) (default 1)",
    )
    p.add_argument("--dead-zone", type=float, default=0.0, help="dead zone on s [rad/s]")
    p.add_argument("--noise-q", type=float, default=0.0, help="position noise std [rad]")
    p.add_argument("--noise-dq", type=float, default=0.0, help="velocity noise std [rad/s]")
    p.add_argument(
        "--amplitude",
        type=float,
        default=0.4,
        help="reference amplitude, fraction of half the joint range (default 0.4)",
    )
    p.add_argument("--period", type=float, default=5.0, help="reference period [s] (default 5)")
    p.add_argument("--seed", type=int, default=0, help="seed of the reference and perturbation")
    p.add_argument("--json", metavar="OUT", default=None, help="write the figures as JSON")
    p.add_argument(
        "--report",
        metavar="DIR",
        default=None,
        help="write a report folder: result.json, parameter estimates and tracking error over "
        "time, the robot scene animated along the run (scene.html) and index.html",
    )
    p.add_argument("--force", action="store_true", help="replace a non-empty --report folder")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..adaptive import CompositeLaw, default_gains
    from ..closed_loop import ClosedLoopOptions, compare_fixed, default_reference, with_payload
    from ..simulation import perturb_parameters, require_physical
    from ..trajectories import trajectory_to_configuration

    outputs = reserve_outputs(args)  # every output checked (and the report claimed) first
    robot = robot_from_args(args)
    theta0 = robot.nominal_parameters
    require_physical(robot, theta0)  # the simulated plant: a message naming the body
    theta_true = perturb_parameters(robot, args.perturb, seed=args.seed)
    theta_true = with_payload(robot, theta_true, args.payload)
    reference = default_reference(
        robot, amplitude=args.amplitude, period=args.period, seed=args.seed
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
    record_every = max(int(round(args.rate / 100.0)), 1)
    cmp = compare_fixed(
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
            record_every=record_every,
        ),
    )
    a, f = cmp.adaptive, cmp.fixed
    law = "composite" if a.composite else "plain"
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
    out = {
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
    if args.json:
        outputs.write_json(args.json, out)
    if args.report is not None:
        path = _write_report(robot, cmp, out, law, args)
    outputs.publish()  # all outputs appear together, once all are complete
    if args.json:
        print(f"wrote {args.json}")
    if args.report is not None:
        print(f"wrote the report to {path}/index.html")
    return 0


def _write_report(robot, cmp, out: dict, law: str, args):
    """Report folder of an adaptive run (see :func:`manip_id.viz.report.write_report`)."""
    from ..errors import InfeasibleTrajectoryError
    from ..viz import figures
    from ..viz.meshcat_scene import RobotScene
    from ..viz.report import write_report

    a, f = cmp.adaptive, cmp.fixed
    run_name = (
        f"{robot.name}, {law} Slotine-Li adaptation, {args.duration:g} s at {args.rate:g} Hz, "
        f"perturb {args.perturb:g}" + (f", payload {args.payload:g} kg" if args.payload else "")
    )
    joints = list(robot.dof_names)
    from ..identifiability import analyze

    base = analyze(robot).base  # the combinations adaptation can converge to
    figs = {
        "parameter_estimates": lambda path: figures.online_history(
            path,
            a.t,
            base.to_base(a.theta_hat),
            names=base.base_names,
            reference=base.to_base(a.theta_true),
            reference_label="truth",
            prediction_error=a.prediction_error,
            error_label="torque prediction error on new states [-]",
            title=f"base-parameter error and prediction error over time: {run_name}",
        ),
        "tracking_error": lambda path: figures.tracking_error(
            path,
            a.t,
            a.q - a.q_d,
            joint_names=joints if a.q.shape[1] == len(joints) else None,
            baseline=f.q - f.q_d if f.q.shape == a.q.shape else None,
            title=f"tracking error: {run_name}",
        ),
    }
    notes = []
    scene = RobotScene(robot, title=f"manip-id adapt: {run_name}")
    try:
        scene.animate(a.t, a.q)
    except InfeasibleTrajectoryError as exc:
        notes.append(f"scene not animated: {exc}")
    scene.add_inertia(a.theta_true, label="true")
    scene.add_inertia(a.theta_hat[-1], label="final_estimate")
    notes += list(scene.notes)
    rows = [
        {"parameter": n, "unit": u, "true": t, "initial": s0, "final": s1}
        for n, u, t, s0, s1 in zip(
            robot.parameter_names,
            robot.parameter_units,
            a.theta_true,
            a.theta0,
            a.theta_hat[-1],
            strict=True,
        )
    ]
    summary = {
        "robot": robot.name,
        "law": law,
        "duration [s]": args.duration,
        "rate [Hz]": args.rate,
        "rms tracking error, adaptive [rad]": a.rms_tracking_error,
        "rms tracking error, fixed parameters [rad]": f.rms_tracking_error,
        "final tracking error, adaptive [rad]": a.final_tracking_error,
        "final tracking error, fixed parameters [rad]": f.final_tracking_error,
        "torque prediction error, start": f"{100 * a.initial_prediction_error:.3g} %",
        "torque prediction error, end": f"{100 * a.final_prediction_error:.3g} %",
    }
    notes.append(
        f"the estimates are shown as the {base.n_base} base parameters (the combinations the "
        f"regressor can determine); the {robot.n_parameters} standard parameters in the table "
        "need not converge"
    )
    return write_report(
        args.report_claim,
        title=f"manip-id adapt: {run_name}",
        summary=summary,
        parameter_table=rows,
        figures=figs,
        scene=scene,
        json_result=out,
        notes=notes,
        force=args.force,
    )
