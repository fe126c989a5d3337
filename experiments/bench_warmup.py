"""The compile paid once: a first ``identify`` against the next one, whole processes.

    python experiments/bench_warmup.py [--samples 1000000] [--repeat 2] [--json OUT]

The log of experiments/bench_identify.py (ur10 with viscous and Coulomb friction, a
5-harmonic Fourier trajectory at 1 kHz, rnea torques plus friction and 1 % noise) as
the NPZ a user has (t, q, dq, tau without accelerations: the low-pass filter runs),
written once under ``--cache``. Then, per round, each in a fresh process with its own
numba cache folder (``NUMBA_CACHE_DIR``, a new empty temporary folder for the cold
cases, so nothing compiled earlier is found):

1. cold: ``manip-id identify ur10 --friction viscous,coulomb --data user.npz`` with an
   empty cache: every kernel is compiled (a fresh install's first run);
2. warm: the same command again, the kernels loaded from the cache of run 1;
3. after warmup: ``manip-id warmup`` with another empty cache (timed on its own), then
   the same command: the first real run after ``make demo`` / ``make test``.

The table gives the median wall times and peak resident memory, and the ratios
cold / warm and after-warmup / warm measured in the same rounds (the target of issue
39: after-warmup / warm <= 1.2).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _measure import machine, manip_id_command, run  # noqa: E402
from bench_identify import FRICTION, RATE, ROBOT, make_log, read_chunks  # noqa: E402

TARGET = 1.2  # after-warmup / warm


def user_npz(cache: Path, n: int) -> Path:
    """The log of ``n`` samples as a user's NPZ (t, q, dq, tau), written once."""
    from manip_id import load_robot
    from manip_id.datasets import Layout, write_rows

    folder = make_log(cache, n)
    path = folder / "user.npz"  # the same file as bench_identify.py --user writes
    if path.exists():
        return path
    robot = load_robot(ROBOT, friction=FRICTION)
    lay = Layout(robot.nv, robot.nv, False)

    def blocks():
        start = 0
        for q, dq, _ddq, tau in read_chunks(folder, robot.nv, chunk=32768):
            t = np.arange(start, start + q.shape[0]) / RATE
            start += q.shape[0]
            yield lay.pack(t, q, dq, tau)

    write_rows(blocks, n, lay, list(robot.dof_names), path, "npz")
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=1_000_000, help="samples of the log")
    parser.add_argument("--repeat", type=int, default=2, help="rounds of the three cases")
    parser.add_argument("--cache", default="/tmp/manip_id_bench", help="where the log is kept")
    parser.add_argument("--json", type=Path, help="write the figures as JSON")
    args = parser.parse_args(argv)

    npz = user_npz(Path(args.cache), args.samples)
    cli = manip_id_command()
    runs: dict[str, list] = {"cold": [], "warm": [], "warmup": [], "after warmup": []}
    with tempfile.TemporaryDirectory(prefix="bench-warmup-") as tmp:
        identify = [*cli, "identify", ROBOT, "--friction", ",".join(FRICTION), "--data", str(npz)]
        for r in range(args.repeat):
            env_a = dict(os.environ, NUMBA_CACHE_DIR=str(Path(tmp) / f"cold{r}"))
            env_b = dict(os.environ, NUMBA_CACHE_DIR=str(Path(tmp) / f"warmup{r}"))
            cases = [
                ("cold", [*identify, "--json", f"{tmp}/c{r}.json"], env_a),
                ("warm", [*identify, "--json", f"{tmp}/w{r}.json"], env_a),
                ("warmup", [*cli, "warmup", "--quiet"], env_b),
                ("after warmup", [*identify, "--json", f"{tmp}/a{r}.json"], env_b),
            ]
            for name, cmd, env in cases:
                res = run(cmd, env=env)
                if res.status != 0:
                    print(f"{name} exited {res.status}: {res.stderr.strip()[-400:]}")
                    return 1
                runs[name].append(res)
                print(f"  round {r + 1} {name}: {res.seconds:.1f} s", flush=True)
    med = {k: statistics.median(x.seconds for x in v) for k, v in runs.items()}
    peak = {k: statistics.median(x.peak_mib for x in v) for k, v in runs.items()}
    cold_ratio = statistics.median(
        c.seconds / w.seconds for c, w in zip(runs["cold"], runs["warm"], strict=True)
    )
    after_ratio = statistics.median(
        a.seconds / w.seconds for a, w in zip(runs["after warmup"], runs["warm"], strict=True)
    )
    print(f"machine: {machine()}")
    print(f"identify {ROBOT}, {args.samples} samples (NPZ), median of {args.repeat} rounds")
    print(f"{'case':16s} {'time [s]':>9s} {'peak [MiB]':>11s}")
    for k in runs:
        print(f"{k:16s} {med[k]:9.2f} {peak[k]:11.1f}")
    verdict = "ok" if after_ratio <= TARGET else "MISSED"
    print(f"cold / warm: {cold_ratio:.2f}x; after warmup / warm: {after_ratio:.2f}x "
          f"(target <= {TARGET:g}x: {verdict})")  # fmt: skip
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        out = {
            "machine": machine(),
            "samples": args.samples,
            "seconds": med,
            "peak_mib": peak,
            "cold_over_warm": cold_ratio,
            "after_warmup_over_warm": after_ratio,
            "target": TARGET,
        }
        args.json.write_text(json.dumps(out, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
