"""``manip-id excite ROBOT --duration S --out FILE``: design a safe, informative excitation.

A finite Fourier series per joint, at rest in the start pose at both ends, maximizing the
information about the base parameters (:func:`manip_id.trajectories.design_excitation`)
within the joint position, velocity, acceleration and torque limits, clear of the robot's
own links and of the ``--world`` objects; written as CSV, NPZ, JSON, ROS 2 YAML, a ROS 2
MCAP bag or URScript; ``--report DIR`` a folder to look at before the robot moves.
"""

from __future__ import annotations

from ._common import add_robot_arguments, command

FORMATS = ("csv", "npz", "json", "yaml", "mcap", "urscript")


def register(sub) -> None:
    p = sub.add_parser(
        "excite",
        help="design an excitation trajectory: informative, within every limit, collision-free",
        description="Design a Fourier excitation of ROBOT lasting --duration seconds, at rest "
        "in the start pose at both ends, maximizing the information about the base parameters "
        "(D-optimal by default) within the position, velocity, acceleration and torque limits "
        "and the clearance to the robot's own links and the --world objects; write it to --out.",
    )
    add_robot_arguments(p)
    p.add_argument("--duration", type=float, required=True, metavar="S", help="length [s]")
    p.add_argument("--out", required=True, metavar="FILE", help="the trajectory file to write")
    p.add_argument(
        "--format",
        choices=FORMATS,
        default=None,
        help="format of --out [default: from its suffix: .csv .npz .json .yaml .mcap .script]",
    )
    p.add_argument("--harmonics", type=int, default=5, help="harmonics per joint [default 5]")
    p.add_argument(
        "--base-frequency",
        type=float,
        default=None,
        metavar="HZ",
        help="base frequency [Hz]; the duration must be a whole number of its periods "
        "[default 1 / duration]",
    )
    p.add_argument(
        "--start",
        default=None,
        metavar="Q1,Q2,...",
        help="start and end pose [rad or m], one value per joint [default: the SRDF's "
        "reference configuration, else the neutral pose, clipped to the limits]",
    )
    p.add_argument(
        "--criterion",
        choices=("d", "cond", "e"),
        default="d",
        help="d: log det of the information (default); cond: condition number; e: smallest "
        "eigenvalue",
    )
    p.add_argument(
        "--margin",
        type=float,
        default=0.05,
        help="fraction of every limit kept free [default 0.05]",
    )
    p.add_argument(
        "--acceleration-limit",
        default=None,
        metavar="A[,A...]",
        help="joint acceleration limits [rad/s^2], one or one per joint [default: the "
        "profile's, else none]",
    )
    p.add_argument(
        "--no-torque-limits",
        action="store_true",
        help="do not impose the URDF effort limits on the nominal torques",
    )
    p.add_argument(
        "--world",
        default=None,
        metavar="FILE.toml",
        help="obstacles in the base frame: [[plane]] normal/offset, [[box]] size/position/rpy, "
        "[[sphere]] radius/position, [[cylinder]] radius/length/position/rpy [default: none]",
    )
    p.add_argument(
        "--clearance",
        type=float,
        default=0.02,
        metavar="M",
        help="least distance between non-adjacent links and to the world [m] [default 0.02]",
    )
    p.add_argument(
        "--no-self-collision",
        action="store_true",
        help="do not check the robot's links against each other",
    )
    p.add_argument(
        "--rate", type=float, default=1000.0, metavar="HZ",
        help="sampling rate of --out, and of the final check [Hz] [default 1000]",
    )  # fmt: skip
    p.add_argument(
        "--noise",
        type=float,
        default=0.01,
        metavar="REL",
        help="torque noise std per joint relative to its effort limit, the weights of the "
        "criterion and of the predicted std [default 0.01; with --from: the result's]",
    )
    p.add_argument(
        "--from",
        dest="previous",
        default=None,
        metavar="RESULT.json",
        help="design the next experiment for the data behind this identify result: the "
        "criterion counts its information too [default: none]",
    )
    p.add_argument(
        "--sigma",
        type=float,
        default=None,
        metavar="K",
        help="with --from: the torque limits hold for the identified model's torques plus K "
        "standard deviations of their prediction (from the result's covariance) instead of "
        "the nominal model's [default 3]",
    )
    p.add_argument(
        "--starts", type=int, default=8,
        help="random starts of the global search [default 8]",
    )  # fmt: skip
    p.add_argument(
        "--maxiter", type=int, default=60,
        help="SLSQP iterations per refined start [default 60]",
    )  # fmt: skip
    p.add_argument("--seed", type=int, default=0, help="seed of the random starts [default 0]")
    p.add_argument(
        "--json",
        default=None,
        metavar="OUT",
        help="write the design summary as JSON (criterion, limit usage, clearance, predicted "
        "std) [default: none]",
    )
    p.add_argument(
        "--report",
        default=None,
        metavar="DIR",
        help="write a report folder to look at before the run: the motion animated with the "
        "world and the closest approach, limit usage per joint, clearance, predicted std "
        "[default: none]",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace existing --out / --json files and a --report folder manip-id wrote "
        "[default: refuse]",
    )
    p.set_defaults(func=command("manip_id.cli._excite"))
