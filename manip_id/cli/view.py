"""``manip-id view``: the robot in meshcat, animated along data or a simulated excitation.

The scene (visual meshes, a time slider, the nominal inertia ellipsoids) is
written as a standalone HTML file (``--html``, checked before the work, written to a
temporary and renamed at the end) and/or replayed into a live meshcat viewer
(``--serve``, until Ctrl-C or SIGTERM). The viewer's server is ours
(:mod:`manip_id.viz.meshcat_server`): it listens on 127.0.0.1 unless ``--host`` is
given (a non-loopback host is reachable from the network: a warning says so) and
stops when the command ends, whatever the signal. A trajectory that does not fit
the robot (number of positions, position limits) is an error.
"""

from __future__ import annotations

from ._common import add_robot_arguments, command


def register(sub) -> None:
    p = sub.add_parser(
        "view",
        help="show the robot in meshcat, animated along data or a simulated excitation",
        description="Build a meshcat scene of ROBOT (visual meshes and the nominal inertia "
        "ellipsoids), animated along the positions of a dataset (--data) or of a random "
        "Fourier excitation (--simulate), with a time slider. Write it as a standalone HTML "
        "file (--html) and/or serve it live on 127.0.0.1 (--serve).",
    )
    add_robot_arguments(p)
    src = p.add_mutually_exclusive_group()
    src.add_argument(
        "--data", metavar="FILE", help="dataset whose q to follow (.npz, .csv or a Panda log)"
    )
    src.add_argument("--simulate", action="store_true", help="follow a random Fourier excitation")
    p.add_argument(
        "--duration", type=float, default=10.0, help="seconds of --simulate motion [default 10]"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the --simulate excitation")
    p.add_argument(
        "--fps", type=float, default=30.0, help="animation frames per second [default 30]"
    )
    p.add_argument(
        "--no-inertia", action="store_true", help="do not draw the nominal inertia ellipsoids"
    )
    p.add_argument("--html", metavar="OUT", help="write the scene as a standalone HTML file")
    p.add_argument(
        "--serve",
        action="store_true",
        help="open a live meshcat viewer on 127.0.0.1 and wait (Ctrl-C ends)",
    )
    p.add_argument(
        "--host",
        default=None,
        help="address the --serve web server listens on [default 127.0.0.1]; any other "
        "than a loopback address makes the viewer reachable from the network",
    )
    p.set_defaults(func=command("manip_id.cli._view"))
