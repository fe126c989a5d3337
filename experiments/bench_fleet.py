"""Fleet identification on Dask: throughput and scaling with 1 and 2 workers.

    python experiments/bench_fleet.py [--files 100] [--samples 100000] [--workers 1 2]
                                      [--repeat R] [--block B] [--cache DIR] [--json OUT]

Robot: ur10 with viscous and Coulomb friction (48 base parameters). Data:
``--files`` NPZ logs of ``--samples`` samples each (random states within the
limits, torques from ``pinocchio.rnea`` plus friction and noise, ``ddq``
included so that every task reads, checks and accumulates), written once
under ``--cache``. The paper case is 100 files of 10^5 samples; the default is
scaled down to fit a shared 2-core machine (16 files of 2 10^4 samples).

Each case runs in its own process:

1. serial: :func:`manip_id.identification.fleet.identify` without a scheduler (no Dask);
2. dask N: ``manip_id.execution.connect("local:N")`` (N single-threaded worker
   processes on 127.0.0.1), started before the clock runs (its start-up is printed apart).

Before the clock, every case loads the compiled kernel (in this process and on every
worker) and runs two files per worker (imports and first-call costs, which a
long-lived cluster pays once). ``--repeat R`` runs R rounds, the cases interleaved in
each (the machine is shared); the figures are medians over the rounds, every ratio
taken within a round.

Printed per case: wall time of ``identify`` [s], throughput [samples/s],
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
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from manip_id.identification import FileOptions, PartitionOptions, RunOptions

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _measure import local_cluster  # noqa: E402

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
    """Import what a task needs and load the compiled kernel (before the clock)."""
    import manip_id.identification  # noqa: F401
    import manip_id.identification.fleet  # noqa: F401
    from manip_id.robot import compiled_regressor as cr

    with cr.planned_samples(cr.AUTO_SAMPLES):  # loads the kernel unless mode pinocchio
        pass


def run_case(paths: list[str], workers: int, block: int | None) -> dict:
    """One case in this process: 0 workers = serial (no Dask)."""
    from manip_id import load_robot
    from manip_id.identification import identify

    robot = load_robot(ROBOT, friction=FRICTION)
    out: dict = {"workers": workers}
    client, cluster, startup = local_cluster(workers)
    if client is not None:
        out["startup_s"] = startup
    try:
        # the structural analysis is the same in every case: out of the clock
        from manip_id.identifiability import analyze

        base = analyze(robot).base
        # warm-up on one file: imports and first-call costs on every worker, out of the clock
        t0 = time.perf_counter()
        _warm_worker()
        if client is not None:
            client.run(_warm_worker)
        identify(
            robot,
            paths[: 2 * max(workers, 1)],
            base=base,
            run=RunOptions(scheduler=client),
            files=FileOptions(audit=False),
        )
        out["warmup_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        res = identify(
            robot,
            paths,
            base=base,
            run=RunOptions(scheduler=client),
            files=FileOptions(audit=False, partition=PartitionOptions(block=block)),
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


def _print_table(args, rounds: list[list[dict]]) -> None:
    """Medians over the rounds (ratios within each round), checked against serial."""
    med = statistics.median
    cases = [r["workers"] for r in rounds[0]]
    one = cases.index(1) if 1 in cases else None
    total = rounds[0][0]["n_samples"]
    load = os.getloadavg()
    print(
        f"{ROBOT}, {args.files} files x {args.samples} samples = {total} samples, "
        f"task = {'a file' if args.block is None else f'{args.block} samples'}, "
        f"{len(rounds)} round(s); load average {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} "
        f"on {os.cpu_count()} cores"
    )
    print(
        "| case | start-up s | wall s (median, range) | samples/s | vs serial | efficiency "
        "| task s (sum) | busy | max rel diff |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for c, w in enumerate(cases):
        rs = [r[c] for r in rounds]
        walls = [r["wall_s"] for r in rs]
        diff = max(
            float(np.abs(np.asarray(r[c]["estimate"]) - np.asarray(r[0]["estimate"])).max())
            / float(np.abs(np.asarray(r[0]["estimate"])).max())
            for r in rounds
        )
        eff = ""
        if w > 0 and one is not None:
            eff = f"{med(r[one]['wall_s'] / (w * r[c]['wall_s']) for r in rounds):.2f}"
        name = "serial (no Dask)" if w == 0 else f"Dask, {w} worker{'s' * (w > 1)}"
        start = f"{med(r['startup_s'] for r in rs):.2f}" if "startup_s" in rs[0] else ""
        busy = [
            r["task_seconds"].get("scan", 0.0) + r["task_seconds"].get("accumulate_total", 0.0)
            for r in rs
        ]  # summed over tasks
        vs = med(r[0]["wall_s"] / r[c]["wall_s"] for r in rounds)
        print(
            f"| {name} | {start} | {med(walls):.2f} ({min(walls):.2f}-{max(walls):.2f}) | "
            f"{total / med(walls):,.0f} | {vs:.2f} | {eff} | {med(busy):.2f} | "
            f"{med(b / (max(w, 1) * r['wall_s']) for b, r in zip(busy, rs, strict=True)):.2f} "
            f"| {diff:.1e} |"
        )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--files", type=int, default=16)
    ap.add_argument("--samples", type=int, default=20000, help="samples per file")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--block", type=int, default=None, help="samples per task (default a file)")
    ap.add_argument("--repeat", type=int, default=1, help="rounds, the cases interleaved")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/manip_id_bench_fleet"))
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--case", type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    paths = make_files(args.cache, args.files, args.samples)
    if args.case is not None:  # a child process: one case, JSON on stdout
        print(json.dumps(run_case(paths, args.case, args.block)))
        return 0

    rounds = []
    for _ in range(args.repeat):
        rows = []
        for workers in [0, *args.workers]:
            cmd = [sys.executable, __file__, "--files", str(args.files), "--samples",
                   str(args.samples), "--cache", str(args.cache),
                   "--case", str(workers)]  # fmt: skip
            if args.block is not None:
                cmd += ["--block", str(args.block)]
            proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
            if proc.returncode != 0:
                print(proc.stderr, file=sys.stderr)
                return 1
            rows.append(json.loads(proc.stdout.strip().splitlines()[-1]))
        rounds.append(rows)
    _print_table(args, rounds)
    if args.json is not None:
        args.json.write_text(json.dumps(rounds, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
