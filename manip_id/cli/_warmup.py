"""``manip-id warmup`` once it runs: identify on small simulated logs, every kernel
compiled (the options are declared in :mod:`.warmup`).

The runs are those of a real ``identify`` (the same parser, the same paths) with
``--regressor compiled`` so that the regressor kernel is used whatever the size: an NPZ
log without accelerations (the low-pass filter and the batched regressor, on the
least-squares path), validated on a CSV log (the compiled CSV reader, numba being
loaded), and the momentum model (its kernel). Their results are discarded.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import os
import tempfile
import time
import warnings
from pathlib import Path

from .._io import OutputSet
from .._numba import numba_available
from ..datasets import save_dataset
from ..robot.model import load_robot
from ..simulation import simulate
from . import build_parser  # the command line's own parser
from ._simulated import excitation

#: The robot and the log the kernels are compiled on (their types do not depend on it).
ROBOT, DURATION, RATE = "panda", 3.0, 200.0  # [s], [Hz]


def _logs(folder: Path) -> tuple[Path, Path]:
    """A simulated NPZ and CSV log of :data:`ROBOT`, without accelerations."""
    robot = load_robot(ROBOT)
    paths = []
    for seed, name in ((0, "warmup.npz"), (1, "warmup.csv")):
        sim = simulate(robot, excitation(robot, seed), duration=DURATION, rate=RATE, seed=seed)
        data = dataclasses.replace(sim.dataset, ddq=None)  # filtered and differentiated
        paths.append(save_dataset(data, folder / name))
    return paths[0], paths[1]


def _identify(argv: list[str]) -> None:
    """``manip-id identify ARGV`` in this process, its output and warnings discarded (the
    compile note, on the ``manip_id`` logger, is said)."""
    args = build_parser().parse_args(["identify", *argv])
    args.outputs = OutputSet()
    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        args.func(args)


def run(args: argparse.Namespace) -> int:
    if not numba_available():
        print("numba is not installed: nothing to compile (pip install 'manip_id[fast]')")
        return 0
    t0 = time.perf_counter()
    previous = os.environ.get("MANIP_ID_REGRESSOR")
    try:
        with tempfile.TemporaryDirectory(prefix="manip-id-warmup-") as tmp:
            npz, csv = _logs(Path(tmp))
            common = ["--regressor", "compiled", "--workers", "1", "--quiet"]
            _identify([ROBOT, "--data", str(npz), "--validate", str(csv), *common])
            _identify([ROBOT, "--data", str(npz), "--model", "momentum", *common])
    finally:  # --regressor set it for this process
        if previous is None:
            os.environ.pop("MANIP_ID_REGRESSOR", None)
        else:
            os.environ["MANIP_ID_REGRESSOR"] = previous
    if not args.quiet:
        print(
            f"warmup: the numba kernels are compiled and cached ({time.perf_counter() - t0:.1f} s);"
            " later runs load them"
        )
    return 0
