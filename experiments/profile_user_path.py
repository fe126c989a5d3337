"""Where the wall time of the user's NPZ command goes, phase by phase, in whole processes.

    python experiments/profile_user_path.py [--data FILE] [--workers 1 2] [--repeat 3]
        [--simulate N]

The command is ``manip-id identify ur10 --friction viscous,coulomb --data FILE --json
OUT`` (default FILE: the 10^6-sample ``user.npz`` that ``bench_identify.py --user``
writes under /tmp/manip_id_bench). Each run is a fresh process that records clock
stamps around the steps (the parent stamps the spawn and the exit) and reads the
command's own phase timings from its JSON:

    start          interpreter start-up and ``site`` (spawn -> first line of the child)
    imports        numpy, pinocchio, scipy.linalg, the CLI and its identify run modules
    numba          numba imported and the compiled kernels (regressor, filter) loaded from
                   the cache (the command does it on its first block; done first here, so
                   that the audit's figure is work, not loading; not with --simulate, which
                   at 10^5 samples keeps Pinocchio and never loads numba)
    robot+options  argument parsing, the robot, the outputs reserved (main() up to the run,
                   whose ``total`` timing ends where its result document begins)
    audit          the pre-fit audit of the file (reading it once, the central 50k rows
                   preprocessed, nominal torque, delay search)
    read           the file scanned (row count, statistics of the stamps)
    accumulate     the blocked preprocessing, regressor and Gram sums (forked workers)
    solve          structural and rank analysis, least squares with uncertainty
    output         the result document, the printed summary, the JSON written
    exit           the child's exit (atexit, interpreter teardown)

With ``--simulate N`` the FIGAROH-comparison command runs instead (``--simulate --rate
200 --duration (N-1)/200``, no --data): its phases are simulate and accumulate. Each
figure is the median over ``--repeat`` runs; the machine is shared, so compare figures
of one invocation. Whole-process CPU (user + system, workers included) from ``wait4``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _measure import byte_compile  # noqa: E402

DEFAULT_DATA = Path("/tmp/manip_id_bench/ur10_1000000/user.npz")
ROBOT, FRICTION = "ur10", "viscous,coulomb"


def child(argv: list[str], stamps_path: str, spawn: float) -> None:
    """The command in this process, with clock stamps (written to ``stamps_path``)."""
    stamps = {"spawn": spawn, "first": time.time()}
    import numpy  # noqa: F401
    import pinocchio  # noqa: F401
    import scipy.linalg  # noqa: F401

    import manip_id.cli._identify  # noqa: F401
    from manip_id.cli import _files, _simulated, main

    stamps["imported"] = time.time()
    for module in (_files, _simulated):  # the run's end: its result is printed
        module.print_result = _stamped(module.print_result, stamps)
    if "--simulate" not in argv:  # a simulation of 10^5 samples loads no numba kernel
        _load_kernels()
    stamps["kernels"] = time.time()
    try:
        status = main(argv)
    except SystemExit as exc:
        status = exc.code
    stamps["main_done"] = time.time()
    stamps["status"] = status
    Path(stamps_path).write_text(json.dumps(stamps))


def _stamped(fn, stamps: dict):
    """``fn`` that stamps ``stamps["document"]`` when it is called."""

    def wrapper(*args, **kwargs):
        stamps["document"] = time.time()
        return fn(*args, **kwargs)

    return wrapper


def _load_kernels() -> None:
    """numba imported and the kernels the command uses loaded (from numba's cache)."""
    from manip_id import load_robot
    from manip_id.robot import compiled_regressor as cr
    from manip_id.signals import Lowpass

    if not cr.numba_available():
        return
    robot = load_robot(ROBOT, friction=tuple(FRICTION.split(",")))
    desc = cr.describe_model(robot.model)
    q = np.zeros((2, robot.nq))
    cr.rigid_block(desc, q, q, q, np.zeros((2, robot.nv, desc.n_rigid)))
    Lowpass(3.0, 1000.0)(np.zeros((64, 2)))
    Lowpass(3.0, 1000.0).transient_samples()


def command(data: Path | None, simulate: int | None, workers: int, out: Path) -> list[str]:
    argv = ["identify", ROBOT, "--friction", FRICTION, "--json", str(out), "--force"]
    if simulate:
        argv += ["--simulate", "--rate", "200", "--duration", repr((simulate - 1) / 200.0)]
    else:
        argv += ["--data", str(data)]
    if workers:
        argv += ["--workers", str(workers)]
    return argv


def run_once(argv: list[str], out: Path) -> dict:
    """One child process: its stamps, its JSON timings, wall and CPU time."""
    with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as fh:
        stamps_path = fh.name
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    spawn = time.time()
    cmd = [sys.executable, __file__, "--child", stamps_path, repr(spawn), "--", *argv]
    with open(os.devnull, "wb") as null:
        proc = subprocess.Popen(cmd, stdout=null, stderr=subprocess.PIPE, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
    end = time.time()
    stderr = proc.stderr.read().decode() if proc.stderr else ""
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"the command failed: {stderr.strip().splitlines()[-1:]}")
    s = json.loads(Path(stamps_path).read_text())
    os.unlink(stamps_path)
    t = json.loads(out.read_text())["timings"]
    run = t["total"]
    phases = {
        "start": s["first"] - s["spawn"],
        "imports": s["imported"] - s["first"],
        "numba": s["kernels"] - s["imported"],
    }
    # the run's ``total`` ends where its result document begins
    phases["robot+options"] = s["document"] - s["kernels"] - run
    phases["simulate"] = t.get("simulate", 0.0)
    phases["audit"] = t.get("audit", 0.0)
    phases["read"] = t.get("scan", 0.0)
    serial = t.get("regressor", 0.0) + t.get("accumulate", 0.0)  # one process: no wall figure
    phases["accumulate"] = t.get("accumulate_wall", serial)
    phases["solve"] = sum(t.get(k, 0.0) for k in ("structural_analysis", "rank_analysis", "solve"))
    named = sum(phases[k] for k in ("simulate", "audit", "read", "accumulate", "solve"))
    phases["other run"] = run - named
    phases["output"] = s["main_done"] - s["document"]
    phases["exit"] = end - s["main_done"]
    return {
        "phases": phases,
        "wall": end - spawn,
        "cpu": usage.ru_utime + usage.ru_stime,
        "peak_mb": usage.ru_maxrss / 1024.0,
        "run_cpu": {k: t[k] for k in ("regressor", "accumulate", "accumulate_total") if k in t},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--simulate", type=int, default=None, help="samples of --simulate")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 0], help="0: default")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    if not args.simulate and not args.data.exists():
        raise SystemExit(f"{args.data} is missing: run experiments/bench_identify.py --user first")
    print(byte_compile())  # the package's .pyc, as an installed one has them
    what = f"--simulate {args.simulate} samples" if args.simulate else str(args.data)
    print(f"manip-id identify {ROBOT} --friction {FRICTION} on {what}, median of {args.repeat}")
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.json"
        for w in args.workers:
            argv = command(args.data, args.simulate, w, out)
            results[w] = [run_once(argv, out) for _ in range(args.repeat)]
    _print(results)
    if args.json:
        Path(args.json).write_text(json.dumps({str(k): v for k, v in results.items()}, indent=1))


def _print(results: dict) -> None:
    names = list(next(iter(results.values()))[0]["phases"])
    cols = [f"workers {w or 'default'}" for w in results]
    print(f"{'phase':16s}" + "".join(f"{c:>20s}" for c in cols))
    med = {
        w: {k: np.median([r["phases"][k] for r in runs]) for k in names}
        for w, runs in results.items()
    }
    for k in names:
        if all(abs(med[w][k]) < 5e-4 for w in results):
            continue
        row = "".join(
            f"{med[w][k]:10.3f} s {100 * med[w][k] / _wall(results[w]):5.1f} %" for w in results
        )
        print(f"{k:16s}" + row)
    print(f"{'wall':16s}" + "".join(f"{_wall(results[w]):10.3f} s {'':7s}" for w in results))
    for key, label in (("cpu", "CPU (all procs)"), ("peak_mb", "peak MB")):
        vals = [np.median([r[key] for r in results[w]]) for w in results]
        print(f"{label:16s}" + "".join(f"{v:10.2f} {'':9s}" for v in vals))
    for w, runs in results.items():
        cpu = {
            k: np.median([r["run_cpu"].get(k, np.nan) for r in runs]) for k in runs[0]["run_cpu"]
        }
        print(
            f"workers {w or 'default'}: in-run CPU "
            + ", ".join(f"{k} {v:.3f} s" for k, v in cpu.items())
        )


def _wall(runs: list[dict]) -> float:
    return float(np.median([r["wall"] for r in runs]))


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(sys.argv[5:], sys.argv[2], float(sys.argv[3]))
    else:
        main()
