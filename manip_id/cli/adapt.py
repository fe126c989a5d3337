"""``manip-id adapt``: Slotine-Li adaptive tracking on a simulated robot with wrong parameters."""

from __future__ import annotations

from ._common import add_robot_arguments, command


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
    p.set_defaults(func=command("manip_id.cli._adapt"))
