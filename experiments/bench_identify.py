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
   solve with uncertainty (``manip_id.identification.identify``), on one
   core and with every core (worker processes, accumulators merged by addition);
3. dense: the full stacked regressor in memory, column-pivoted QR for the base
   columns and least squares on them (what the known tools do); skipped when
   its matrices would not fit in the available memory.

The user's path (``--user``, one size, default 10^6): the same log as a user
has it, t, q, dq, tau without accelerations, written once as NPZ (plain and
compressed), CSV and a ROS 2 bag (MCAP, one JointState message per sample),
then ``manip-id identify ur10 --friction viscous,coulomb --data FILE --json OUT``
run as a whole process per format (reading in chunks, blocked filtering,
accumulation), its wall time against the floor measured in the same run and its
peak resident memory from ``os.wait4``; and, for comparison, the whole-array
path of the previous CLI (``load_dataset`` + ``preprocess`` + ``identify``) on the NPZ.

    python experiments/bench_identify.py --user [--user-size 1000000] [--repeat 3]
        [--formats npz csv ...] [--no-inmem]

With ``--repeat R`` the floor and the formats run in R interleaved rounds, each
ratio against the floor of its own round, and the table prints the medians.
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

from manip_id.identification import RunOptions

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _measure import byte_compile  # noqa: E402

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
    from manip_id.robot.regressor import joint_torques
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
    t0, c0 = time.perf_counter(), time.process_time()
    for q, dq, ddq, _ in read_chunks(folder, robot.nv):
        for k in range(q.shape[0]):
            f(model, data, q[k], dq[k], ddq[k])
    return {"seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - c0}


def case_manip_id(folder: Path, workers: int) -> dict:
    from manip_id import load_robot
    from manip_id.identifiability import analyze
    from manip_id.identification import identify

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
    result = identify(robot, source, base=base, run=RunOptions(workers=workers))
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
    from manip_id.robot.regressor import iter_regressor

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


# ------------------------------------------------------------------ the user's path
USER_FORMATS = ("npz", "npz_compressed", "csv", "mcap")


def user_files(cache: Path, n: int) -> dict[str, Path]:
    """The log of ``n`` samples without ddq, as the files a user has (written once, streamed)."""
    from manip_id import load_robot
    from manip_id.datasets import Layout, write_rows

    folder = make_log(cache, n)
    robot = load_robot(ROBOT, friction=FRICTION)
    nv = robot.nv
    lay = Layout(nv, nv, False)
    names = list(robot.dof_names)

    def blocks():
        start = 0
        for q, dq, _ddq, tau in read_chunks(folder, nv, chunk=32768):
            t = np.arange(start, start + q.shape[0]) / RATE
            start += q.shape[0]
            yield lay.pack(t, q, dq, tau)

    out = {}
    for fmt in USER_FORMATS:
        suffix = {"npz": ".npz", "npz_compressed": ".z.npz", "csv": ".csv", "mcap": ".mcap"}[fmt]
        path = folder / f"user{suffix}"
        out[fmt] = path
        if path.exists():
            continue
        if (
            fmt == "npz_compressed"
        ):  # the NPZ members compressed (zip deflate), as np.savez_compressed
            import zipfile

            with (
                zipfile.ZipFile(out["npz"]) as zin,
                zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, allowZip64=True) as zout,
            ):
                for info in zin.infolist():
                    with (
                        zin.open(info) as src,
                        zout.open(info.filename, "w", force_zip64=True) as dst,
                    ):
                        while chunk := src.read(1 << 22):
                            dst.write(chunk)
            continue
        t0 = time.perf_counter()
        write_rows(blocks, n, lay, names, path, "mcap" if fmt == "mcap" else fmt)
        print(f"  wrote {path.name} in {time.perf_counter() - t0:.0f} s", flush=True)
    return out


def run_cli(path: Path, out_json: Path) -> dict:
    """``manip-id identify`` on ``path`` as a whole process: wall time, peak RSS (wait4)."""
    cmd = [
        sys.executable,
        "-m",
        "manip_id",
        "identify",
        ROBOT,
        "--friction",
        ",".join(FRICTION),
        "--data",
        str(path),
        "--json",
        str(out_json),
    ]
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    err_path = out_json.with_suffix(".stderr")
    with open(err_path, "wb") as err, open(os.devnull, "wb") as null:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=null, stderr=err, env=env)
        _, status, usage = os.wait4(proc.pid, 0)  # this child's own rusage
        seconds = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        lines = err_path.read_text().strip().splitlines()
        return {"error": lines[-1] if lines else f"exit {proc.returncode}"}
    rep = json.loads(out_json.read_text())
    return {
        "seconds": seconds,
        "cpu_seconds": usage.ru_utime + usage.ru_stime,  # the whole process, start-up included
        "peak_rss_mb": usage.ru_maxrss / 1024.0,
        "n_samples": rep["n_samples"],
        "relative_error": rep["relative_error"]["train"],
        "estimate": [p["value"] for p in rep["base_parameters"]],
    }


def case_inmem(path: Path) -> dict:
    """The previous CLI path: whole arrays loaded, preprocessed and identified."""
    from manip_id import load_robot
    from manip_id.datasets import load_dataset
    from manip_id.identification import identify
    from manip_id.signals import preprocess

    robot = load_robot(ROBOT, friction=FRICTION)
    t0 = time.perf_counter()
    ds = preprocess(load_dataset(path))
    res = identify(robot, (ds.q, ds.dq, ds.ddq, ds.tau))
    return {"seconds": time.perf_counter() - t0, "n_samples": res.n_samples}


def _median(values: list[float]) -> float:
    return float(np.median(values)) if values else float("nan")


def user_main(
    cache: Path,
    n: int,
    json_out: str | None,
    formats: tuple[str, ...] = USER_FORMATS,
    repeat: int = 1,
    inmem: bool = True,
) -> None:
    """The user's path: per round, the floor then each format's CLI run, interleaved.

    The machine is shared: each of ``repeat`` rounds measures the floor and every
    format back to back, each format's ratio is taken against the floor of its own
    round, and the table gives the medians over the rounds (time, ratio, peak).
    """
    print(f"user's path: {n} samples of {ROBOT} ({'+'.join(FRICTION)} friction) without ddq")
    files = user_files(cache, n)
    folder = log_dir(cache, n)
    runs: dict[str, list[dict]] = {"floor": []}
    ref = None
    for r in range(int(repeat)):
        floor = child("floor", folder)
        runs["floor"].append(floor)
        for fmt in formats:
            res = run_cli(files[fmt], folder / f"out_{fmt}.json")
            if "error" not in res:
                est = np.asarray(res.pop("estimate"))
                ref = est if ref is None else ref
                res["max_estimate_difference_vs_first"] = float(
                    np.abs(est - ref).max() / np.abs(ref).max()
                )
                if "seconds" in floor:
                    res["x_floor"] = res["seconds"] / floor["seconds"]
                    res["cpu_x_floor"] = res["cpu_seconds"] / floor["cpu_seconds"]
            runs.setdefault(fmt, []).append(res)
        print(
            f"  round {r + 1}/{repeat}: floor {floor.get('seconds', float('nan')):.1f} s; "
            + ", ".join(
                f"{fmt} {runs[fmt][-1].get('x_floor', float('nan')):.2f}x wall, "
                f"{runs[fmt][-1].get('cpu_x_floor', float('nan')):.2f}x CPU"
                for fmt in formats
            ),
            flush=True,
        )
    rows: dict = {"runs": runs}
    fl = [x["seconds"] for x in runs["floor"] if "seconds" in x]
    fl_cpu = [x["cpu_seconds"] for x in runs["floor"] if "cpu_seconds" in x]
    fl_mb = [x["peak_rss_mb"] for x in runs["floor"] if "peak_rss_mb" in x]
    print(f"medians over {repeat} interleaved round(s); wall and CPU (user + system) time")
    print(
        f"{'case':28s} {'wall s':>8s} {'x floor':>8s} {'CPU s':>8s} {'x floor':>8s} {'peak MB':>8s}"
    )
    print(
        f"{'floor (regressor only)':28s} {_median(fl):8.2f} {1.0:8.2f} {_median(fl_cpu):8.2f} "
        f"{1.0:8.2f} {_median(fl_mb):8.0f}"
    )
    rows["floor"] = {
        "seconds": _median(fl),
        "cpu_seconds": _median(fl_cpu),
        "peak_rss_mb": _median(fl_mb),
    }
    for fmt in formats:
        ok = [x for x in runs[fmt] if "error" not in x]
        if not ok:
            print(f"{'manip-id identify ' + fmt:28s} error: {runs[fmt][-1]['error']}")
            continue
        med = {
            key: _median([x[key] for x in ok if key in x])
            for key in ("seconds", "x_floor", "cpu_seconds", "cpu_x_floor", "peak_rss_mb")
        }
        med["max_peak_rss_mb"] = max(x["peak_rss_mb"] for x in ok)
        med["max_estimate_difference_vs_first"] = max(
            x["max_estimate_difference_vs_first"] for x in ok
        )
        rows[fmt] = med
        print(
            f"{'manip-id identify ' + fmt:28s} {med['seconds']:8.2f} {med['x_floor']:8.2f} "
            f"{med['cpu_seconds']:8.2f} {med['cpu_x_floor']:8.2f} "
            f"{med['peak_rss_mb']:8.0f}   (max peak {med['max_peak_rss_mb']:.0f} MB; "
            f"estimate vs first run {med['max_estimate_difference_vs_first']:.1e})"
        )
    if inmem:
        whole = child("inmem", files["npz"])
        rows["whole_arrays_npz"] = whole
        if "error" not in whole:
            print(
                f"{'whole arrays (previous CLI)':28s} {whole['seconds']:8.2f} "
                f"{whole['seconds'] / _median(fl):8.2f} {'':8s} {'':8s} "
                f"{whole['peak_rss_mb']:8.0f}   (loading and preprocessing timed, no start-up)"
            )
    if json_out:
        Path(json_out).parent.mkdir(parents=True, exist_ok=True)
        Path(json_out).write_text(json.dumps({"n": n, "rows": rows}, indent=2))


def run_case(args) -> None:
    folder = Path(args.folder)
    if args.case == "inmem":
        out = case_inmem(folder)
    elif args.case == "floor":
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
    parser.add_argument("--user", action="store_true", help="the user's path (see the docstring)")
    parser.add_argument("--user-size", type=int, default=1_000_000)
    parser.add_argument(
        "--formats", nargs="+", choices=USER_FORMATS, default=list(USER_FORMATS),
        help="the user's path: the file formats to run",
    )  # fmt: skip
    parser.add_argument(
        "--repeat", type=int, default=1, help="the user's path: interleaved rounds (medians)"
    )
    parser.add_argument(
        "--no-inmem", action="store_true", help="the user's path: skip the whole-array case"
    )
    parser.add_argument(
        "--case", choices=["floor", "manip_id", "dense", "inmem"], help=argparse.SUPPRESS
    )
    parser.add_argument("--folder", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.case:
        run_case(args)
        return
    print(byte_compile())  # the package's .pyc, as an installed one has them
    if args.user:
        user_main(
            Path(args.cache),
            args.user_size,
            args.json,
            tuple(args.formats),
            args.repeat,
            not args.no_inmem,
        )
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
