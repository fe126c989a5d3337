"""``manip-id view`` once it runs: the robot scene written as HTML or served live (the
options are declared in :mod:`.view`).
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from ..datasets import load_dataset
from ..errors import InputError
from ..simulation import check_simulation_memory
from ..trajectories import random_trajectory, trajectory_to_configuration
from ..viz.meshcat_scene import RobotScene, check_trajectory
from ..viz.meshcat_server import check_host, is_loopback
from ._common import reserve_outputs, warn
from ._runtime import robot_from_args


def _motion(robot, args):
    """``(t, q, what)`` to animate along, or None for a still robot."""
    if args.data is not None:
        ds = load_dataset(args.data)
        return ds.t, ds.q, f"data {args.data} ({ds.n_samples} samples)"
    if args.simulate:  # kinematics only: no torques, so no inertias needed
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
