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

import argparse
import math
import sys
import time

from ..datasets import load_dataset
from ..errors import InputError
from ..viz.meshcat_server import check_host, is_loopback
from ._common import add_robot_arguments, reserve_outputs, robot_from_args, warn


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
    p.set_defaults(func=run)


def _motion(robot, args):
    """``(t, q, what)`` to animate along, or None for a still robot."""
    if args.data is not None:
        ds = load_dataset(args.data)
        return ds.t, ds.q, f"data {args.data} ({ds.n_samples} samples)"
    if args.simulate:  # kinematics only: no torques, so no inertias needed
        import numpy as np

        from ..simulation import check_simulation_memory  # pinocchio: heavy, not for --help
        from ..trajectories import random_trajectory, trajectory_to_configuration

        traj = random_trajectory(robot, harmonics=5, seed=args.seed)
        rate = max(2 * args.fps, 50.0)
        n = int(round(args.duration * rate))
        check_simulation_memory(robot, n)  # before allocating: a clear error, not a crash
        t = np.arange(n) / rate
        q = trajectory_to_configuration(robot, traj.sample(t)[0])
        return t, q, f"random excitation (seed {args.seed}, {args.duration:g} s)"
    return None


def run(args: argparse.Namespace) -> int:
    if not args.html and not args.serve:
        raise InputError("nothing to do: give --html OUT and/or --serve")
    if args.simulate and not (math.isfinite(args.duration) and args.duration > 0):
        raise InputError(f"--duration must be positive, got {args.duration}")
    if not (math.isfinite(args.fps) and args.fps > 0):
        raise InputError(f"--fps must be positive, got {args.fps}")
    if args.host is not None and not args.serve:
        raise InputError("--host applies to --serve only")
    host = "127.0.0.1"
    if args.host is not None:
        host = check_host(args.host)
        if not is_loopback(host):
            warn(f"--host {host}: the viewer is reachable from the network, without authentication")
    outputs = reserve_outputs(args)  # --html checked before the work
    from ..viz.meshcat_scene import RobotScene, check_trajectory  # meshcat: heavy, optional

    robot = robot_from_args(args)
    motion = _motion(robot, args)
    title = f"manip-id view {robot.name}"
    if motion is not None:
        t, q, what = motion
        t, q = check_trajectory(robot, t, q)  # width and limits: an error, not a warning
        title += f": {what}"
    scene = RobotScene(robot, title=title)
    if motion is not None:
        scene.animate(t, q, fps=args.fps)
    if not args.no_inertia:
        scene.add_inertia(robot.nominal_parameters, label="nominal")
    for note in scene.notes:
        print(f"note: {note}", file=sys.stderr)
    if args.html:
        outputs.write_text(args.html, scene.html())
        outputs.publish()
        print(f"wrote {args.html}")
    if args.serve:
        with scene.serve(host=host) as view:  # the server stops on leaving, signal or not
            print(f"meshcat viewer at {view.url} (Ctrl-C ends)", flush=True)
            try:
                while view.server.process.poll() is None:
                    time.sleep(0.5)
            except KeyboardInterrupt:
                return 0
            raise InputError(
                f"the meshcat server stopped (exit status {view.server.process.returncode})"
            )
    return 0
