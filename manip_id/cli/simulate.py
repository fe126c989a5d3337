"""``manip-id simulate``: simulated logs, with the truth behind them, to try every command on.

Each file is one excitation (a random Fourier trajectory within the joint limits, its own
seed) simulated with the robot's nominal parameters, or a robot that differs from its
URDF as real ones do (``--joint-terms`` friction values, ``--perturb`` inertias, a
``--tool`` mass on the last body), with torque noise relative to each joint's RMS torque;
``--payload`` adds runs carrying a point mass on the last body, and ``--drive-gains``
writes motor currents instead of torques. The folder also holds
``README.txt`` and ``truth.json``: the robot, the parameters, the payload and the noise
used, so that identified values can be compared with them.
"""

from __future__ import annotations

from ._common import SIM_DEFAULTS, add_robot_arguments, command

FORMATS = ("npz", "csv", "mcap")
#: The payload's and the tool's lever: 0.1 m along the last joint's axis (``with_payload``).
LEVER = 0.1  # [m]


def register(sub) -> None:
    p = sub.add_parser(
        "simulate",
        help="write simulated logs (and their truth) to try the other commands on",
        description="Simulate ROBOT along --files excitation trajectories (each its own seed) "
        "and write one log per trajectory into the new folder --out, with README.txt and "
        "truth.json stating the parameters, payload and noise used. The logs read as --data "
        "of identify, --unloaded/--loaded of payload and drive-gains, and --data of monitor "
        "and audit.",
    )
    add_robot_arguments(p)
    p.add_argument("--out", required=True, metavar="DIR", help="the folder to write (new)")
    p.add_argument(
        "--files",
        type=int,
        default=2,
        metavar="N",
        help="number of logs (unloaded runs), each another trajectory [default 2]",
    )
    p.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help=f"length of each log [s] [default: the --trajectory's, else "
        f"{SIM_DEFAULTS['duration']:g}]",
    )
    p.add_argument(
        "--trajectory",
        default=None,
        metavar="DESIGN.json",
        help="simulate along this designed excitation (the --json of manip-id excite) in "
        "every file, each with its own noise [default: a random excitation per file]",
    )
    p.add_argument(
        "--rate",
        type=float,
        default=SIM_DEFAULTS["rate"],
        metavar="HZ",
        help=f"sampling rate [Hz] [default {SIM_DEFAULTS['rate']:g}]",
    )
    p.add_argument(
        "--noise",
        type=float,
        default=SIM_DEFAULTS["noise"],
        metavar="REL",
        help="torque noise std, relative to each joint's RMS torque (0: exact) "
        f"[default {SIM_DEFAULTS['noise']:g}]",
    )
    p.add_argument(
        "--position-noise",
        type=float,
        default=0.0,
        metavar="RAD",
        help="Gaussian noise std on the logged positions [rad or m] (0: exact) [default 0]",
    )
    p.add_argument(
        "--velocity-noise",
        type=float,
        default=0.0,
        metavar="RAD/S",
        help="Gaussian noise std on the logged velocities [rad/s or m/s] [default 0]",
    )
    p.add_argument(
        "--controller",
        default=None,
        metavar="FILE.toml",
        help="simulate in closed loop: the robot driven by this PD/PID controller (kp, kd[, "
        "ki] per joint) tracking the excitation, which the logs hold as the reference columns "
        "(qref, dqref); the controller reads the noisy measurement; the torque columns are the "
        "commanded torques; no ddq is logged (npz or csv) [default: open loop, inverse "
        "dynamics along the excitation]",
    )
    p.add_argument(
        "--payload",
        default=None,
        metavar="MASS[,MASS...]",
        help="also write --files loaded runs per mass [kg]: a point mass 0.1 m along the last "
        "joint's axis, on the last body [default: none]",
    )
    truth = p.add_argument_group("a robot that differs from its URDF (the truth of the logs)")
    truth.add_argument(
        "--model",
        default=None,
        metavar="RESULT.json",
        help="simulate an identified model (manip-id identify --json, a report's folder): "
        "its physically consistent standard parameters (--consistent), else its base "
        "parameters with the regrouped columns at the URDF's values (the same torques); its "
        "joint terms and joints [default: the URDF's parameters]",
    )
    truth.add_argument(
        "--joint-terms",
        default=None,
        metavar="TERM=VALUE[,...]",
        help="the truth's joint terms, one value for every joint, e.g. fv=0.4,fc=0.6 "
        "(fv [N m s/rad], fc [N m], fo [N m], Ia [kg m^2], k [N m/rad]; the terms must be "
        "modelled: --friction, --armature, --spring) [default: the URDF's]",
    )
    truth.add_argument(
        "--perturb",
        type=float,
        default=0.0,
        metavar="FRACTION",
        help="perturb every body's mass, inertia and centre of mass and the joint terms by "
        "about FRACTION (0.3: tens of percent), physically valid, drawn from --seed "
        "[default 0: the URDF's]",
    )
    truth.add_argument(
        "--tool",
        type=float,
        default=0.0,
        metavar="KG",
        help=f"a tool mass [kg] not in the URDF, in every run: a point mass {LEVER:g} m along "
        "the last joint's axis, on the last body [default 0]",
    )
    p.add_argument(
        "--drive-gains",
        default=None,
        metavar="G[,G...]",
        help="write motor currents tau / G [A] in the torque columns, one gain [N m/A] per "
        "joint or one for all (input of drive-gains) [default: torques]",
    )
    p.add_argument(
        "--format", choices=FORMATS, default="npz", help="file format of the logs [default npz]"
    )
    p.add_argument(
        "--seed",
        type=int,
        default=SIM_DEFAULTS["seed"],
        help="seed of the first trajectory and its noise; file k uses SEED + k "
        f"[default {SIM_DEFAULTS['seed']}]",
    )
    p.add_argument(
        "--transmission",
        metavar="FILE.toml",
        default=None,
        help='the drive train (manip_id.robot.transmission): with signals = "motor" the logs are '
        "motor-side (theta = R (q - offset), tau_motor = R^-T tau) [default: the profile's]",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace an --out folder that manip-id wrote [default: refuse]",
    )
    p.add_argument("--quiet", action="store_true", help="print nothing but errors and warnings")
    p.set_defaults(func=command("manip_id.cli._simulate"))
