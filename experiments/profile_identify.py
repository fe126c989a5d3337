"""Where the time and the memory of a simulated identification go, phase by phase.

    python experiments/profile_identify.py [--sizes 100000 1000000] [--json OUT]

The work of ``manip-id identify ur10 --simulate --friction viscous,coulomb
--rate 200 --duration D`` (D = (N - 1) / 200 s, so N samples; least squares,
streamed), done step by step in a fresh process per size with a thread
sampling the resident memory every 2 ms:

    imports      manip_id's CLI, identification, simulation (and so pinocchio, scipy.linalg)
    robot        load_robot (URDF and SRDF, no geometry)
    simulate     random excitation, noise-free torques of the record (rnea, per sample)
    identify     identify: base columns, then per block the trajectory and noise
                 regenerated ("blocks"), the regressor ("regressor"), the rank-k updates
                 ("accumulate"); rank analysis and solve
    floor        the same samples through pinocchio.computeJointTorqueRegressor alone,
                 one Python-level call per sample (the issue's floor), for reference

Each row gives the phase's wall time, its share of the whole, the resident
memory at its end and its peak. The sampler costs a little time; the
benchmarks (bench_*.py) run without it.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

from manip_id.identification import RunOptions

RATE = 200.0  # [Hz]


class Sampler:
    """Resident memory [MiB] sampled in a thread; ``mark`` closes a phase."""

    def __init__(self, period: float = 0.002):
        import psutil

        self._proc = psutil.Process()
        self._period = period
        self._peak = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    def rss(self) -> float:
        return self._proc.memory_info().rss / 2**20

    def _loop(self) -> None:
        while not self._stop.is_set():
            self._peak = max(self._peak, self.rss())
            time.sleep(self._period)

    def mark(self) -> tuple[float, float]:
        """(resident now, peak since the last mark) [MiB]."""
        now = self.rss()
        peak, self._peak = max(self._peak, now), now
        return now, peak

    def close(self) -> None:
        self._stop.set()
        self._thread.join()


def profile_one(n: int) -> dict:
    """Profile one size in this process (module docstring)."""
    t_process = time.perf_counter()
    sampler = Sampler()
    rows: list[dict] = []

    def phase(name: str, seconds: float, note: str = "") -> None:
        rss, peak = sampler.mark()
        rows.append({"phase": name, "seconds": seconds, "rss": rss, "peak": peak, "note": note})

    t0 = time.perf_counter()
    import numpy as np
    import pinocchio as pin

    from manip_id.cli import identify as _cli_identify  # noqa: F401 (the CLI's own imports)
    from manip_id.identification import identify
    from manip_id.robot.model import load_robot
    from manip_id.simulation import MeasurementNoise, SimulationStream
    from manip_id.trajectories import random_trajectory

    phase("imports", time.perf_counter() - t0)

    t0 = time.perf_counter()
    robot = load_robot("ur10", friction="viscous,coulomb")
    phase("robot", time.perf_counter() - t0)

    t0 = time.perf_counter()
    traj = random_trajectory(robot, harmonics=5, seed=0)
    stream = SimulationStream(
        robot, traj, duration=(n - 1) / RATE, rate=RATE, noise=MeasurementNoise(tau=0.01)
    )
    stream.tau_true  # noqa: B018
    mib = stream.nbytes / 2**20
    phase("simulate", time.perf_counter() - t0, f"tau_true {mib:.0f} MiB")

    t0 = time.perf_counter()
    result = identify(robot, stream.blocks(), method="ols", run=RunOptions(chunk=1024))
    wall = time.perf_counter() - t0
    tm = dict(result.timings)
    inner = ("structural_analysis", "regressor", "accumulate", "rank_analysis", "solve")
    for key in inner:
        rows.append({"phase": f"  {key}", "seconds": float(tm.get(key, 0.0)), "sub": True})
    blocks = wall - sum(float(tm.get(k, 0.0)) for k in inner)
    rows.append({"phase": "  blocks (trajectory, noise, checks)", "seconds": blocks, "sub": True})
    phase("identify", wall, f"{result.n_base if hasattr(result, 'n_base') else ''}")
    total = time.perf_counter() - t_process

    # the floor: one Python-level call per sample, nothing else
    f, m, d = pin.computeJointTorqueRegressor, robot.model, robot.model.createData()
    t_floor = 0.0
    for q, dq, ddq, _ in stream.blocks():
        t1 = time.perf_counter()
        for k in range(q.shape[0]):
            f(m, d, q[k], dq[k], ddq[k])
        t_floor += time.perf_counter() - t1
    phase("floor (reference, not in total)", t_floor)
    sampler.close()
    del np
    return {
        "n": n,
        "total_seconds": total,
        "rows": rows,
        "estimate_size": int(len(result.estimate)),
        "floor_us_per_sample": 1e6 * t_floor / n,
        "pinocchio": pin.__version__,
    }


def print_table(res: dict) -> None:
    n, total = res["n"], res["total_seconds"]
    print(f"\nN = {n:,} samples (ur10, viscous + Coulomb friction, streamed least squares)")
    print(f"{'phase':38s} {'time [s]':>9s} {'share':>7s} {'RSS end':>8s} {'peak':>8s}  note")
    for r in res["rows"]:
        share = "" if r["phase"].startswith("floor") else f"{100 * r['seconds'] / total:6.1f}%"
        if r.get("sub"):
            print(f"{r['phase']:38s} {r['seconds']:9.3f} {share:>7s}")
        else:
            print(
                f"{r['phase']:38s} {r['seconds']:9.3f} {share:>7s} {r['rss']:7.0f}M "
                f"{r['peak']:7.0f}M  {r['note']}"
            )
    print(f"{'total (in process)':38s} {total:9.3f}")
    print(f"floor: {res['floor_us_per_sample']:.2f} us per sample")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[100000, 1000000])
    parser.add_argument("--json", type=Path, help="write the profiles as JSON")
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)  # internal: one size here
    args = parser.parse_args(argv)
    if args.one:
        print(json.dumps(profile_one(args.one)))
        return 0
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    results = []
    for n in args.sizes:
        out = subprocess.run(
            [sys.executable, __file__, "--one", str(n)],
            capture_output=True,
            text=True,
            env=env,
            check=True,
        )
        res = json.loads(out.stdout.strip().splitlines()[-1])
        print_table(res)
        results.append(res)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
