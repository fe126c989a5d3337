"""Identification at 10^4 .. 10^6 samples: time and peak memory against the floor.

    python experiments/bench_identify.py [--sizes 10000 100000 1000000] [--json OUT]

Robot: ur10 with viscous and Coulomb friction; data: a 5-harmonic Fourier
trajectory sampled at 1 kHz, torques from ``pinocchio.rnea`` plus friction and
1 % noise, written once per size to raw little-endian float64 files (a log on
disk) under ``--cache``. Every case reads the log chunk by chunk with plain
file reads (no memory map, so resident memory reflects the method, not the
file) and runs in its own process, so that its peak resident memory
(``ru_maxrss``) is its own:

1. floor: only ``pinocchio.computeJointTorqueRegressor`` on each sample;
2. manip_id: regressor with joint terms, streaming accumulation, base-parameter
   solve with uncertainty (``manip_id.identification.identify_chunks``), on one
   core and with every core (worker processes, accumulators merged by addition);
3. dense: the full stacked regressor in memory, column-pivoted QR for the base
   columns and least squares on them (what the known tools do); skipped when
   its matrices would not fit in the available memory.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROBOT = "ur10"
FRICTION = ("viscous", "coulomb")
RATE = 1000.0
CHUNK = 2048
FIELDS = ("q", "dq", "ddq", "tau")


# ----------------------------------------------------------------------------- data
def log_dir(cache: Path, n: int) -> Path:
    return cache / f"{ROBOT}_{n}"


def make_log(cache: Path, n: int) -> Path:
    """Write the log of ``n`` samples once (q, dq, ddq, tau as raw float64, sample-major)."""
    import pinocchio as pin

    from manip_id import load_robot
    from manip_id.regressor import joint_torques
    from manip_id.trajectories import FourierTrajectory

    folder = log_dir(cache, n)
    if (folder / "done").exists():
        return folder
    folder.mkdir(parents=True, exist_ok=True)
    robot = load_robot(ROBOT, friction=FRICTION)
    rng = np.random.default_rng(0)
    harmonics, wf = 5, 2 * np.pi / 10.0
    amp = 0.5 * np.minimum(robot.velocity_bounds(), 1.0)
    a = rng.uniform(-1, 1, (robot.nv, harmonics)) * amp[:, None] / harmonics
    b = rng.uniform(-1, 1, (robot.nv, harmonics)) * amp[:, None] / harmonics
    traj = FourierTrajectory(np.zeros(robot.nv), a, b, wf)
    theta = robot.nominal_parameters.copy()
    theta[robot.n_rigid :] = rng.uniform(0.5, 2.0, robot.n_parameters - robot.n_rigid)
    model = robot.with_parameters(theta)
    data = model.createData()
    files = {f: open(folder / f"{f}.f64", "wb") for f in FIELDS}  # noqa: SIM115
    try:
        for start in range(0, n, 65536):
            t = np.arange(start, min(start + 65536, n)) / RATE
            q, dq, ddq = traj.sample(t)
            tau = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(len(t))])
            tau += joint_torques(robot, theta, q, dq)
            tau += 0.01 * np.std(tau, axis=0) * rng.standard_normal(tau.shape)
            for f, arr in zip(FIELDS, (q, dq, ddq, tau), strict=True):
                files[f].write(np.ascontiguousarray(arr, dtype="<f8").tobytes())
    finally:
        for fh in files.values():
            fh.close()
    (folder / "done").write_text(json.dumps({"n": n, "nv": robot.nv}))
    return folder


def read_chunks(folder: Path, nv: int, start: int = 0, stop: int | None = None, chunk: int = CHUNK):
    """Yield (q, dq, ddq, tau) blocks of samples start:stop with plain reads."""
    n = json.loads((folder / "done").read_text())["n"]
    stop = n if stop is None else stop
    handles = {f: open(folder / f"{f}.f64", "rb") for f in FIELDS}  # noqa: SIM115
    try:
        for fh in handles.values():
            fh.seek(start * nv * 8)
        for s in range(start, stop, chunk):
            m = min(chunk, stop - s)
            yield tuple(
                np.fromfile(handles[f], dtype="<f8", count=m * nv).reshape(m, nv) for f in FIELDS
            )
    finally:
        for fh in handles.values():
            fh.close()


# ---------------------------------------------------------------------------- cases
def case_floor(folder: Path) -> dict:
    import pinocchio as pin

    from manip_id import load_robot

    robot = load_robot(ROBOT, friction=FRICTION)
    model, data = robot.model, robot.model.createData()
    f = pin.computeJointTorqueRegressor
    t0 = time.perf_counter()
    for q, dq, ddq, _ in read_chunks(folder, robot.nv):
        for k in range(q.shape[0]):
            f(model, data, q[k], dq[k], ddq[k])
    return {"seconds": time.perf_counter() - t0}


def case_manip_id(folder: Path, workers: int) -> dict:
    from manip_id import load_robot
    from manip_id.identifiability import analyze
    from manip_id.identification import identify_chunks

    robot = load_robot(ROBOT, friction=FRICTION)
    base = analyze(robot).base  # structural, once per robot (not part of the timing)
    n = json.loads((folder / "done").read_text())["n"]
    t0 = time.perf_counter()
    if workers == 1:
        source = read_chunks(folder, robot.nv)
    else:
        bounds = np.linspace(0, n, workers + 1).astype(int)
        source = [
            (read_chunks, (folder, robot.nv, int(a), int(b)))
            for a, b in zip(bounds[:-1], bounds[1:], strict=True)
        ]
    result = identify_chunks(robot, source, base=base, workers=workers)
    seconds = time.perf_counter() - t0
    return {
        "seconds": seconds,
        "n_base": int(result.base.n_base),
        "estimate_head": [float(x) for x in result.estimate[:3]],
        "relative_error": float(result.relative_error.train),
    }


def case_dense(folder: Path) -> dict:
    import scipy.linalg

    from manip_id import load_robot
    from manip_id.regressor import iter_regressor

    robot = load_robot(ROBOT, friction=FRICTION)
    n = json.loads((folder / "done").read_text())["n"]
    t0 = time.perf_counter()
    Y = np.empty((n, robot.nv, robot.n_parameters))
    tau = np.empty((n, robot.nv))
    s = 0
    for q, dq, ddq, tq in read_chunks(folder, robot.nv):
        m = q.shape[0]
        for c in iter_regressor(robot, q, dq, ddq, chunk=m):
            Y[s : s + m] = c.Y
        tau[s : s + m] = tq
        s += m
    W = Y.reshape(-1, robot.n_parameters)
    _, R, piv = scipy.linalg.qr(W, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > d[0] * 1e-10 * max(W.shape)))
    cols = np.sort(piv[:rank])
    Wb = W[:, cols]
    theta, *_ = np.linalg.lstsq(Wb, tau.reshape(-1), rcond=None)
    return {
        "seconds": time.perf_counter() - t0,
        "n_base": rank,
        "estimate_head": theta[:3].tolist(),
    }


def run_case(args) -> None:
    folder = Path(args.folder)
    if args.case == "floor":
        out = case_floor(folder)
    elif args.case == "manip_id":
        out = case_manip_id(folder, args.workers)
    else:
        out = case_dense(folder)
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(json.dumps(out))


# ----------------------------------------------------------------------------- main
def available_memory_bytes() -> int:
    with open("/proc/meminfo") as fh:
        for line in fh:
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    return 0


def child(case: str, folder: Path, workers: int = 1) -> dict:
    cmd = [
        sys.executable,
        __file__,
        "--case",
        case,
        "--folder",
        str(folder),
        "--workers",
        str(workers),
    ]
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    if proc.returncode != 0:
        return {"error": proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else "failed"}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    parser.add_argument("--cache", default="/tmp/manip_id_bench")
    parser.add_argument("--json", default=None)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--case", choices=["floor", "manip_id", "dense"], help=argparse.SUPPRESS)
    parser.add_argument("--folder", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.case:
        run_case(args)
        return

    cache = Path(args.cache)
    rows = []
    print(f"{ROBOT} with {'+'.join(FRICTION)} friction, {os.cpu_count()} cores")
    cols = [
        ("N", 9),
        ("floor s", 8),
        ("floor MB", 8),
        ("manip_id s", 10),
        ("MB", 5),
        ("ratio 2/1", 9),
        (f"{args.workers} workers s", 11),
        ("dense s", 8),
        ("dense MB", 8),
        ("ratio 3/2", 9),
    ]
    print(" ".join(f"{name:>{w}s}" for name, w in cols))
    for n in args.sizes:
        folder = make_log(cache, n)
        floor = child("floor", folder)
        serial = child("manip_id", folder, 1)
        parallel = child("manip_id", folder, args.workers)
        # dense: the stacked regressor, a copy inside QR and Q itself
        need = 3.2 * n * 6 * 72 * 8
        if need < 0.8 * available_memory_bytes():
            dense = child("dense", folder)
        else:
            dense = {"skipped": f"needs about {need / 2**30:.1f} GiB, more than fits in memory"}
        row = {
            "n": n,
            "floor": floor,
            "manip_id": serial,
            "manip_id_parallel": parallel,
            "dense": dense,
        }
        rows.append(row)

        def g(res, key="seconds"):
            return res.get(key, np.nan)

        values = [
            n,
            g(floor),
            g(floor, "peak_rss_mb"),
            g(serial),
            g(serial, "peak_rss_mb"),
            g(serial) / g(floor),
            g(parallel),
            g(dense),
            g(dense, "peak_rss_mb"),
            g(dense) / g(serial),
        ]
        fmts = ["d", ".2f", ".0f", ".2f", ".0f", ".2f", ".2f", ".2f", ".0f", ".2f"]
        print(" ".join(f"{v:{w}{f}}" for v, (_, w), f in zip(values, cols, fmts, strict=True)))
        for label, res in (("manip_id", serial), ("parallel", parallel), ("dense", dense)):
            if "error" in res or "skipped" in res:
                print(f"          {label}: {res.get('error') or res.get('skipped')}")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(
            json.dumps({"robot": ROBOT, "friction": FRICTION, "rows": rows}, indent=2)
        )


if __name__ == "__main__":
    main()
