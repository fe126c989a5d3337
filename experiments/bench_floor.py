"""The floor: can one native call per block of samples beat one Python-level call per sample?

    python experiments/bench_floor.py [--samples 100000] [--build]

On the same ur10 states, measured in one run:

1. python loop: ``pinocchio.computeJointTorqueRegressor`` (and ``pinocchio.rnea``) once per
   sample from Python: the floor of issue 16;
2. pinocchio.rneaInParallel: RNEA of the whole block in one native call (one thread),
   available in the ``pin`` wheel; there is no batched regressor in its bindings;
3. pinocchio.casadi / pinocchio.cppadcg: code-generation paths; reported as unavailable
   when the installed wheel lacks them (the PyPI ``pin`` wheel is built without them);
4. native loop: ``experiments/native/regressor_floor.cpp``, a C++ loop over the block
   calling the same Pinocchio functions on the model saved from Python
   (``Model.saveToText``): what a small compiled extension would at best reach. Built
   with ``--build`` (or when a cached build exists) from the registry's packages only:
   g++ (Debian), the ``pin`` wheel's headers and libraries, Eigen's headers from the
   ``cmeel-eigen`` wheel (found in this environment, under ``$EIGEN_INCLUDE``, or
   fetched with ``pip download cmeel-eigen`` into the cache). Cache:
   ``~/.cache/manip_id/floor``.

Prints microseconds per sample and the ratio of each path to the Python loop.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "manip_id" / "floor"
DEFINES = [
    "-DNDEBUG",
    "-DPINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION",
    "-DBOOST_MPL_LIMIT_LIST_SIZE=30",
    "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30",
    "-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS",
    "-DBOOST_FUSION_INVOKE_MAX_ARITY=12",
]


def _prefix() -> Path:
    """The cmeel prefix of the installed pin wheel (headers and libraries)."""
    import pinocchio

    for parent in Path(pinocchio.__file__).resolve().parents:
        if parent.name == "cmeel.prefix":
            return parent
    raise FileNotFoundError("pinocchio is not installed from the cmeel 'pin' wheel")


def _eigen_include() -> Path | None:
    """Eigen's headers: $EIGEN_INCLUDE, this environment, or the cached cmeel-eigen wheel."""
    candidates = [os.environ.get("EIGEN_INCLUDE")]
    candidates += [str(_prefix() / "include" / "eigen3"), str(CACHE / "eigen" / "eigen3")]
    for c in candidates:
        if c and (Path(c) / "Eigen" / "Core").exists():
            return Path(c)
    return None


def _fetch_eigen() -> Path:
    """``pip download cmeel-eigen`` (a registry package) and unpack its headers into the cache."""
    dl = CACHE / "download"
    dl.mkdir(parents=True, exist_ok=True)
    subprocess.run(
        [sys.executable, "-m", "pip", "download", "--no-deps", "-q", "-d", str(dl), "cmeel-eigen"],
        check=True,
    )
    wheel = sorted(dl.glob("cmeel_eigen-*.whl"))[-1]
    with zipfile.ZipFile(wheel) as z:
        members = [m for m in z.namelist() if "/include/eigen3/" in m]
        z.extractall(dl / "x", members)
    src = next((dl / "x").rglob("include/eigen3"))
    target = CACHE / "eigen" / "eigen3"
    shutil.rmtree(target, ignore_errors=True)
    shutil.copytree(src, target)
    return target


def native_binary(build: bool) -> tuple[Path | None, str]:
    """The compiled native loop, built when asked (and possible); or None and why not."""
    exe = CACHE / "regressor_floor"
    source = HERE / "native" / "regressor_floor.cpp"
    if exe.exists() and exe.stat().st_mtime >= source.stat().st_mtime:
        return exe, "cached build"
    if not build:
        return None, "not built (run with --build: about 1 CPU-minute of g++)"
    cxx = shutil.which("g++") or shutil.which("c++")
    if cxx is None:
        return None, "no C++ compiler (Debian: apt-get install g++)"
    eigen = _eigen_include() or _fetch_eigen()
    prefix = _prefix()
    CACHE.mkdir(parents=True, exist_ok=True)
    cmd = [cxx, "-O3", "-std=c++17", *DEFINES, f"-I{prefix / 'include'}", f"-I{eigen}"]
    cmd += [str(source), "-o", str(exe), f"-L{prefix / 'lib'}", "-lpinocchio_default"]
    cmd += ["-lboost_serialization", f"-Wl,-rpath,{prefix / 'lib'}"]
    t0 = time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, text=True)
    if out.returncode != 0:
        return None, f"build failed: {out.stderr.strip().splitlines()[-1:]}"
    return exe, f"built in {time.perf_counter() - t0:.0f} s"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=100000)
    parser.add_argument("--build", action="store_true", help="build the native loop if needed")
    parser.add_argument("--repeat", type=int, default=3, help="alternating runs; best kept")
    parser.add_argument("--json", type=Path, help="write the figures as JSON")
    args = parser.parse_args(argv)
    n = args.samples

    import numpy as np
    import pinocchio as pin

    from manip_id.robot.model import load_robot

    robot = load_robot("ur10")
    model = robot.model
    data = model.createData()
    q, dq, ddq = robot.random_states(n, seed=1)
    rows: list[tuple[str, float | None, float | None, str]] = []

    def loop(f) -> float:
        t0 = time.perf_counter()
        for k in range(n):
            f(model, data, q[k], dq[k], ddq[k])
        return 1e6 * (time.perf_counter() - t0) / n

    exe, why = native_binary(args.build)
    model_file = CACHE / "ur10_model.txt"
    if exe is not None:
        model.saveToText(str(model_file))
    has_batch = hasattr(pin, "rneaInParallel")
    pool = pin.ModelPool(model, 1) if has_batch else None
    out = np.empty((model.nv, n), order="F")
    best: dict[str, float] = {}
    native_error = ""

    def keep(key: str, value: float) -> None:
        best[key] = min(best.get(key, float("inf")), value)

    # the paths alternate, best of --repeat each: a change of the machine's load hits all
    for _ in range(args.repeat):
        keep("reg_py", loop(pin.computeJointTorqueRegressor))
        keep("rnea_py", loop(pin.rnea))
        if has_batch:
            t0 = time.perf_counter()
            pin.rneaInParallel(1, pool, q.T, dq.T, ddq.T, out)
            keep("rnea_batch", 1e6 * (time.perf_counter() - t0) / n)
        if exe is not None:
            res = subprocess.run(
                [str(exe), str(model_file), str(n)], capture_output=True, text=True
            )
            if res.returncode == 0:
                nat = json.loads(res.stdout)
                keep("reg_native", nat["regressor_us"])
                keep("rnea_native", nat["rnea_us"])
            else:
                native_error = res.stderr.strip()[-200:]
    reg_py, rnea_py = best["reg_py"], best["rnea_py"]
    rows.append(("python loop (one call per sample)", reg_py, rnea_py, "the floor"))
    if has_batch:
        ref = np.stack([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(min(n, 1000))])
        diff = float(np.abs(out.T[: len(ref)] - ref).max())
        rows.append(
            ("pinocchio.rneaInParallel (1 thread)", None, best["rnea_batch"], f"max diff {diff:g}")
        )
    for mod in ("pinocchio.casadi", "pinocchio.cppadcg"):
        try:
            __import__(mod)
            note = "available (not benchmarked here)"
        except ImportError:
            note = "not in the installed wheel"
        rows.append((mod, None, None, note))
    if "reg_native" in best:
        rows.append(
            ("native C++ loop (one call per block)", best["reg_native"], best["rnea_native"], why)
        )
    else:
        rows.append(("native C++ loop", None, None, native_error or why))

    print(
        f"floor, ur10 (nv = {model.nv}), {n:,} random states, pinocchio {pin.__version__}, "
        f"best of {args.repeat} alternating runs"
    )
    print(
        f"{'path':38s} {'regressor [us]':>15s} {'ratio':>6s} {'rnea [us]':>10s} {'ratio':>6s}  note"
    )

    def cell(x, ref):
        return ("", "") if x is None else (f"{x:.2f}", f"{x / ref:.2f}")

    for name, reg, rn, note in rows:
        a, ra = cell(reg, reg_py)
        b, rb = cell(rn, rnea_py)
        print(f"{name:38s} {a:>15s} {ra:>6s} {b:>10s} {rb:>6s}  {note}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"samples": n, "rows": rows}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
