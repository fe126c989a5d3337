"""Fleet identification on Dask: throughput and scaling with 1 and 2 workers.

    python experiments/bench_fleet.py [--files 100] [--samples 100000] [--workers 1 2]
                                      [--block B] [--cache DIR] [--json OUT]

Robot: ur10 with viscous and Coulomb friction (48 base parameters). Data:
``--files`` NPZ logs of ``--samples`` samples each (random states within the
limits, torques from ``pinocchio.rnea`` plus friction and noise, ``ddq``
included so that every task reads, checks and accumulates), written once
under ``--cache``. The paper case is 100 files of 10^5 samples; the default is
scaled down to fit a shared 2-core machine (16 files of 2 10^4 samples).

Each case runs in its own process:

1. serial: :func:`manip_id.fleet.identify_files` without a scheduler (no Dask);
2. dask N: a ``LocalCluster`` of N single-threaded worker processes on
   127.0.0.1, started before the clock runs (its start-up is printed apart).

Before the clock, every case runs one file once per worker (imports and
first-call costs, which a long-lived cluster pays once).

Printed per case: wall time of ``identify_files`` [s], throughput [samples/s],
the ratio to the serial run, the scaling efficiency
``T(1 worker) / (N T(N workers))``, the tasks' own time summed over the tasks
(scan and accumulation) and ``busy`` = that sum / (N wall): the share of the
workers' wall time spent in tasks (what is left is Dask, transfers, and other
processes on a loaded machine); every estimate is checked against the serial
one (max relative difference). The load average is printed with the table:
on a shared machine, compare cases of one run only.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from manip_id.identification import PartitionOptions, RunOptions

ROBOT = "ur10"
FRICTION = ("viscous", "coulomb")


def make_files(cache: Path, n_files: int, n: int) -> list[str]:
    """``n_files`` NPZ logs of ``n`` samples (written once; reused when present)."""
    from manip_id import load_robot
    from manip_id.simulation import inverse_dynamics

    folder = cache / f"{ROBOT}_{n_files}x{n}"
    folder.mkdir(parents=True, exist_ok=True)
    paths = [folder / f"arm{f:03d}.npz" for f in range(n_files)]
    if all(p.is_file() for p in paths):
        return [str(p) for p in paths]
    robot = load_robot(ROBOT, friction=FRICTION)
    theta = robot.nominal_parameters.copy()
    theta[robot.n_rigid :] = 0.3  # [N m s/rad], [N m]
    for f, path in enumerate(paths):
        q, dq, ddq = robot.random_states(n, seed=f)
        tau = inverse_dynamics(robot, theta, q, dq, ddq)
        tau += 0.05 * np.random.default_rng(1000 + f).standard_normal(tau.shape)  # [N m]
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, t=np.arange(n) * 1e-3, q=q, dq=dq, ddq=ddq, tau=tau)
        os.replace(tmp, path)
    return [str(p) for p in paths]


def _warm_worker() -> None:
    """Import what a task needs (run on every worker before the clock)."""
    import manip_id.fleet  # noqa: F401
    import manip_id.identification  # noqa: F401


def run_case(paths: list[str], workers: int, block: int | None) -> dict:
    """One case in this process: 0 workers = serial (no Dask)."""
    from manip_id import load_robot
    from manip_id.fleet import WORKER_ENV, identify_files

    robot = load_robot(ROBOT, friction=FRICTION)
    out: dict = {"workers": workers}
    client = cluster = None
    if workers > 0:
        from distributed import Client, LocalCluster

        t0 = time.perf_counter()
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            host="127.0.0.1",
            scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
            env=WORKER_ENV,
        )
        client = Client(cluster)
        out["startup_s"] = time.perf_counter() - t0
    try:
        # the structural analysis is the same in every case: out of the clock
        from manip_id.identifiability import analyze

        base = analyze(robot).base
        # warm-up on one file: imports and first-call costs on every worker, out of the clock
        t0 = time.perf_counter()
        if client is not None:
            client.run(_warm_worker)
        identify_files(
            robot, paths[: 2 * max(workers, 1)], base=base, run=RunOptions(scheduler=client)
        )
        out["warmup_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        res = identify_files(
            robot,
            paths,
            base=base,
            run=RunOptions(scheduler=client),
            partition=PartitionOptions(block=block),
        )
        out["wall_s"] = time.perf_counter() - t0
    finally:
        if client is not None:
            client.close()
            cluster.close()
    out["n_samples"] = int(res.n_samples)
    out["estimate"] = res.estimate.tolist()
    out["task_seconds"] = {k: round(float(v), 3) for k, v in res.timings.items()}
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--files", type=int, default=16)
    ap.add_argument("--samples", type=int, default=20000, help="samples per file")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--block", type=int, default=None, help="samples per task (default a file)")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/manip_id_bench_fleet"))
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--case", type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    paths = make_files(args.cache, args.files, args.samples)
    if args.case is not None:  # a child process: one case, JSON on stdout
        print(json.dumps(run_case(paths, args.case, args.block)))
        return 0

    rows = []
    for workers in [0, *args.workers]:
        cmd = [sys.executable, __file__, "--files", str(args.files), "--samples",
               str(args.samples), "--cache", str(args.cache), "--case", str(workers)]  # fmt: skip
        if args.block is not None:
            cmd += ["--block", str(args.block)]
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            print(proc.stderr, file=sys.stderr)
            return 1
        rows.append(json.loads(proc.stdout.strip().splitlines()[-1]))
    serial = rows[0]
    ref = np.asarray(serial["estimate"])
    t1 = next((r["wall_s"] for r in rows if r["workers"] == 1), None)
    total = serial["n_samples"]
    load = os.getloadavg()
    print(
        f"{ROBOT}, {args.files} files x {args.samples} samples = {total} samples, "
        f"task = {'a file' if args.block is None else f'{args.block} samples'}; "
        f"load average {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} on {os.cpu_count()} cores"
    )
    print(
        "| case | start-up s | wall s | samples/s | vs serial | efficiency | task s (sum) "
        "| busy | max rel diff |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        w = r["workers"]
        diff = float(np.abs(np.asarray(r["estimate"]) - ref).max() / np.abs(ref).max())
        eff = "" if w == 0 or t1 is None else f"{t1 / (w * r['wall_s']):.2f}"
        name = "serial (no Dask)" if w == 0 else f"Dask, {w} worker{'s' * (w > 1)}"
        start = f"{r['startup_s']:.2f}" if "startup_s" in r else ""
        ts = r["task_seconds"]
        busy = ts.get("scan", 0.0) + ts.get("accumulate_total", 0.0)  # summed over tasks
        print(
            f"| {name} | {start} | {r['wall_s']:.2f} | {total / r['wall_s']:,.0f} | "
            f"{serial['wall_s'] / r['wall_s']:.2f} | {eff} | {busy:.2f} | "
            f"{busy / (max(w, 1) * r['wall_s']):.2f} | {diff:.1e} |"
        )
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
