"""Payload identification on Dask: 1 against 2 local workers, and against this process.

    python experiments/bench_payload_dask.py [--runs 4] [--samples 100000] [--repeat 3]
                                             [--workers 1 2] [--regressor auto]
                                             [--cache DIR] [--json OUT]

Robot: ur5, payload at ``tool0`` (1.3 kg). Data: ``--runs`` unloaded and ``--runs``
loaded NPZ logs of ``--samples`` samples each (random states within the limits,
torques from ``pinocchio.rnea`` of the unloaded model and of the model whose wrist
carries the payload, plus white noise; ``ddq`` included), written once under ``--cache``.

Each case runs in its own process, ``--repeat`` rounds, the cases interleaved in every
round (the machine is shared: compare cases of one round only):

1. local: :func:`manip_id.payload.identify_payload` in this process (no Dask);
2. dask N: ``manip_id.execution.connect("local:N")`` (N single-threaded worker
   processes on 127.0.0.1), started before the clock (its start-up is printed apart),
   then the timed call on the files (``--scheduler`` semantics: the runs read their
   files on the workers).

Before the clock, every case loads the compiled kernel (in this process and on every
worker) and makes one call on the first rows of every file, 2 10^5 samples in all (the
``auto`` threshold: the kernel's first call too): imports and first-call costs, which a
long-lived process or cluster pays once. The whole command (``--cli``) pays them all.
3. with ``--cli``, also the whole command ``manip-id payload ... --scheduler local:N``
   (cluster start-up, reading and the solve inside the clock).

Printed: the median over the rounds of the wall time [s], of the ratio to the local
run and of the scaling efficiency ``T(1 worker) / (N T(N workers))`` (each ratio taken
within a round), and the largest relative difference of the payload (mass, CoM,
inertia) and base estimates to the local run's. For the library calls also the CPU
time [s] of the client process and of each worker process over the timed call, and
the same efficiency from the CPU-bound wall time ``client CPU + max(worker CPU)``: what
the wall time would be if no other work held the cores (on a shared machine the wall
time mostly measures the others' load).
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

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _measure import local_cluster  # noqa: E402

ROBOT, FRAME = "ur5", "tool0"


def make_files(cache: Path, n_runs: int, n: int) -> tuple[list[str], list[str]]:
    """(unloaded, loaded) NPZ logs of ``n`` samples (written once; reused when present)."""
    import pinocchio as pin

    from manip_id import load_robot

    folder = cache / f"{ROBOT}_{n_runs}x{n}"
    folder.mkdir(parents=True, exist_ok=True)
    kinds = {k: [folder / f"{k}{i:02d}.npz" for i in range(n_runs)] for k in ("u", "l")}
    out = tuple([str(p) for p in kinds[k]] for k in ("u", "l"))
    if all(p.is_file() for ps in kinds.values() for p in ps):
        return out  # type: ignore[return-value]
    robot = load_robot(ROBOT)
    model = robot.model.copy()
    model.armature[:] = 0.0
    loaded = model.copy()
    f = model.frames[model.getFrameId(FRAME)]
    payload = pin.Inertia(1.3, np.array([0.02, -0.03, 0.08]), np.diag([0.010, 0.012, 0.006]))
    loaded.inertias[f.parentJoint] = loaded.inertias[f.parentJoint] + f.placement.act(payload)
    for kind, m in (("u", model), ("l", loaded)):
        data = m.createData()
        for i, path in enumerate(kinds[kind]):
            seed = 2 * i + (kind == "l")
            q, dq, ddq = robot.random_states(n, seed=seed)
            tau = np.array([pin.rnea(m, data, q[k], dq[k], ddq[k]) for k in range(n)])
            tau += 0.02 * np.random.default_rng(100 + seed).standard_normal(tau.shape)  # [N m]
            tmp = path.with_suffix(".tmp.npz")
            np.savez(tmp, t=np.arange(n) * 1e-3, q=q, dq=dq, ddq=ddq, tau=tau)
            os.replace(tmp, path)
    return out  # type: ignore[return-value]


def _runs(robot, paths: list[str], distributed: bool) -> list:
    """The runs as the CLI makes them (``scan=False`` on Dask: the tasks read the files)."""
    from manip_id.cli._payload import StreamedRun
    from manip_id.datasets import parse_file_spec
    from manip_id.identification import PreprocessOptions

    opts = PreprocessOptions()
    return [StreamedRun(robot, parse_file_spec(p), opts, scan=not distributed) for p in paths]


def _summary(res) -> dict:
    p = res.payload
    return {
        "payload": [float(p.mass), *map(float, p.com), *map(float, np.ravel(p.inertia))],
        "base": [float(x) for x in res.base_estimate],
        "n_samples": dict(res.n_samples),
    }


def _warm() -> None:
    """Imports and the compiled kernel of this process (what a long-lived one has paid)."""
    import manip_id.payload  # noqa: F401
    from manip_id.robot import compiled_regressor as cr

    with cr.planned_samples(cr.AUTO_SAMPLES):  # loads the kernel unless mode pinocchio
        pass


def run_case(unloaded: list[str], loaded: list[str], workers: int) -> dict:
    """One case in this process: 0 workers = local (no Dask)."""
    from manip_id import load_robot
    from manip_id.execution import portable_robot
    from manip_id.payload import identify_payload
    from manip_id.robot.compiled_regressor import AUTO_SAMPLES

    robot = load_robot(ROBOT)
    out: dict = {"workers": workers}
    client, cluster, startup = local_cluster(workers)
    if client is not None:
        out["startup_s"] = startup
    try:
        light = portable_robot(robot) if client is not None else robot
        dist = client is not None
        # warm-up: imports, first calls and the kernel on every worker, out of the clock
        t0 = time.perf_counter()
        _warm()
        if client is not None:
            client.run(_warm)
        # the first rows of every file, announced as large as the kernel's threshold: the
        # kernel's first call on every worker too
        rows = -(-AUTO_SAMPLES // (len(unloaded) + len(loaded)))
        small = [f"{p}@#0:{rows}" for p in unloaded], [f"{p}@#0:{rows}" for p in loaded]
        identify_payload(
            robot, _runs(light, small[0], dist), _runs(light, small[1], dist), FRAME,
            scheduler=client,
        )  # fmt: skip
        out["warmup_s"] = time.perf_counter() - t0
        cpu0 = client.run(time.process_time) if client is not None else {}
        t0, c0 = time.perf_counter(), time.process_time()
        res = identify_payload(
            robot, _runs(light, unloaded, dist), _runs(light, loaded, dist), FRAME,
            scheduler=client,
        )  # fmt: skip
        out["wall_s"] = time.perf_counter() - t0
        out["client_cpu_s"] = time.process_time() - c0
        if client is not None:
            cpu1 = client.run(time.process_time)
            out["worker_cpu_s"] = sorted(cpu1[w] - cpu0[w] for w in cpu1)
        out["task_s"] = float(res.timings.get("accumulate", float("nan")))
        if client is not None:
            out["worker_samples"] = client.run(_worker_samples)
    finally:
        if client is not None:
            client.close()
            cluster.close()
    out.update(_summary(res))
    return out


def _worker_samples() -> int:
    """Samples a worker process evaluated in blocks."""
    from manip_id.robot import compiled_regressor as cr

    return cr.count_samples(0)


def run_cli(unloaded: list[str], loaded: list[str], workers: int, out: Path) -> dict:
    """The whole command ``manip-id payload`` (0 workers: no scheduler) as a child process."""
    cmd = [sys.executable, "-m", "manip_id", "payload", ROBOT, "--frame", FRAME,
           "--unloaded", *unloaded, "--loaded", *loaded, "--json", str(out), "--force"]  # fmt: skip
    if workers:
        cmd += ["--scheduler", f"local:{workers}"]
    out.unlink(missing_ok=True)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(proc.stderr[-2000:])
    doc = json.loads(out.read_text())
    p = doc["payload"]
    return {
        "workers": workers,
        "wall_s": wall,
        "payload": [p["mass"], *p["com"], *np.ravel(p["inertia"])],
        "base": [],
    }


def _diff(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.abs(a - b).max() / np.abs(b).max()) if b.size else 0.0


def _bound(case: dict) -> float:
    """The wall time of a case were every process given a core when it asks [s]: the
    client's own CPU time (its serial part: set-up, submission, the solve) plus the
    busiest worker's. On a machine shared with other work, a steadier figure than the
    wall time, which waits for the cores the other work holds."""
    return case["client_cpu_s"] + max(case["worker_cpu_s"])


def _table(title: str, rounds: list[list[dict]], workers: list[int]) -> None:
    print(title)
    print(
        "| case | start-up s | wall s (median) | vs local | efficiency | client CPU s "
        "| worker CPU s | CPU-bound wall s | CPU-bound efficiency | max rel diff |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for c, w in enumerate([0, *workers]):
        walls = [r[c]["wall_s"] for r in rounds]
        vs = [r[0]["wall_s"] / r[c]["wall_s"] for r in rounds]
        eff = ""
        if w > 0 and 1 in workers:
            one = [0, *workers].index(1)
            effs = [r[one]["wall_s"] / (w * r[c]["wall_s"]) for r in rounds]
            eff = f"{statistics.median(effs):.2f}"
        start = [r[c]["startup_s"] for r in rounds if "startup_s" in r[c]]
        diff = max(
            max(_diff(r[c]["payload"], r[0]["payload"]), _diff(r[c]["base"], r[0]["base"]))
            for r in rounds
        )
        name = "local (no Dask)" if w == 0 else f"Dask, {w} worker{'s' * (w > 1)}"
        s = f"{statistics.median(start):.2f}" if start else ""
        cpu = ["", "", "", ""]
        if "client_cpu_s" in rounds[0][c]:
            med = statistics.median
            cpu[0] = f"{med(r[c]['client_cpu_s'] for r in rounds):.2f}"
            if w > 0:
                cpu[1] = " / ".join(
                    f"{med(r[c]['worker_cpu_s'][k] for r in rounds):.2f}" for k in range(w)
                )
                cpu[2] = f"{med(_bound(r[c]) for r in rounds):.2f}"
                if 1 in workers:
                    one = [0, *workers].index(1)
                    e = med(_bound(r[one]) / (w * _bound(r[c])) for r in rounds)
                    cpu[3] = f"{e:.2f}"
        print(
            f"| {name} | {s} | {statistics.median(walls):.2f} "
            f"({min(walls):.2f}-{max(walls):.2f}) | {statistics.median(vs):.2f} | {eff} "
            f"| {' | '.join(cpu)} | {diff:.1e} |"
        )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=4, help="unloaded runs (and as many loaded)")
    ap.add_argument("--samples", type=int, default=100_000, help="samples per run")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--regressor", choices=("auto", "compiled", "pinocchio"), default="auto")
    ap.add_argument("--cli", action="store_true", help="also time the whole manip-id command")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/manip_id_bench_payload"))
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--case", type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ["MANIP_ID_REGRESSOR"] = args.regressor
    unloaded, loaded = make_files(args.cache, args.runs, args.samples)
    if args.case is not None:  # a child process: one case, JSON on stdout
        print(json.dumps(run_case(unloaded, loaded, args.case)))
        return 0
    cases = [0, *args.workers]
    api: list[list[dict]] = []
    cli: list[list[dict]] = []
    for _ in range(args.repeat):
        row = []
        for w in cases:
            cmd = [sys.executable, __file__, "--runs", str(args.runs), "--samples",
                   str(args.samples), "--cache", str(args.cache), "--regressor",
                   args.regressor, "--case", str(w)]  # fmt: skip
            proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
            if proc.returncode != 0:
                print(proc.stderr, file=sys.stderr)
                return 1
            row.append(json.loads(proc.stdout.strip().splitlines()[-1]))
        api.append(row)
        if args.cli:
            cli.append([run_cli(unloaded, loaded, w, args.cache / f"cli{w}.json") for w in cases])
    load = os.getloadavg()
    print(
        f"{ROBOT} payload at {FRAME}: {args.runs}+{args.runs} runs x {args.samples} samples, "
        f"regressor {args.regressor}, {args.repeat} rounds; load average {load[0]:.1f} / "
        f"{load[1]:.1f} / {load[2]:.1f} on {os.cpu_count()} cores"
    )
    _table("identify_payload, cluster started before the clock:", api, args.workers)
    for r in api[-1]:
        if "worker_samples" in r:
            print(f"  last round, {r['workers']} worker(s): {r['worker_samples']}")
    if cli:
        _table("whole command manip-id payload [--scheduler local:N]:", cli, args.workers)
    if args.json is not None:
        args.json.write_text(json.dumps({"api": api, "cli": cli}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
