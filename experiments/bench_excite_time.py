"""Design time of ``manip-id excite``: this tree against a baseline revision, whole processes.

For each robot, ``manip-id excite ROBOT --duration 20 --harmonics 5 --world table.toml``
(a table plane 1 cm under the base; self-collision and torque limits on, the defaults)
runs as a whole CLI process from the baseline revision's sources (``git archive REV``,
default eb43808: before the working-set refinement) and from this tree, alternately
(baseline, this, baseline, this, ...: both see the same machine load); the figures are the
process wall time, the design time the JSON reports, and the criterion reached (lower is
better: the speed is not bought with a worse design). The ratio this / baseline is taken
per robot over the medians of ``--repeat`` runs of each.

``--profile DIR`` runs this tree's command once more under ``cProfile`` (``DIR/ROBOT.prof``)
and prints the functions with the most own time: what bounds the design time.

Run: ``PYTHONPATH=. python experiments/bench_excite_time.py [--robots ur5,panda]
[--repeat 1] [--baseline eb43808] [--profile DIR] [--json OUT]``
"""

from __future__ import annotations

import argparse
import io
import json
import os
import pstats
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STARTS = {"ur5": "0,-1.57,1.2,-1.2,-1.57,0"}  # the UR5's elbow-up pose (neutral is stretched)
TABLE = "[[plane]]\nnormal = [0, 0, 1]\noffset = -0.01\n"


def command(robot: str, work: Path, tag: str) -> list[str]:
    cmd = ["excite", robot, "--duration", "20", "--harmonics", "5"]
    cmd += ["--world", str(work / "table.toml"), "--out", str(work / f"{tag}.csv")]
    cmd += ["--json", str(work / f"{tag}.json"), "--force"]
    if robot in STARTS:
        cmd += ["--start", STARTS[robot]]
    return cmd


def run(tree: Path, args: list[str], work: Path, tag: str, profile: Path | None = None) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree), "OPENBLAS_NUM_THREADS": "1",
           "OMP_NUM_THREADS": "1"}  # fmt: skip
    pre = [sys.executable] + (["-m", "cProfile", "-o", str(profile)] if profile else [])
    t0 = time.perf_counter()
    proc = subprocess.run(pre + ["-m", "manip_id", *args], env=env, cwd=work,
                          capture_output=True, text=True)  # fmt: skip
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{tree}: manip-id {' '.join(args)} failed:\n{proc.stderr[-2000:]}")
    doc = json.loads((work / f"{tag}.json").read_text())["excitation"]
    return {"wall": wall, "design_time": doc["design_time"], "criterion": doc["criterion"]}


def baseline_tree(rev: str, where: Path) -> Path:
    """The package sources of ``rev`` extracted under ``where``."""
    where.mkdir(parents=True, exist_ok=True)
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "manip_id", "robots"],
                             capture_output=True, check=True)  # fmt: skip
    subprocess.run(["tar", "-x", "-C", str(where)], input=archive.stdout, check=True)
    return where


def _median(values: list[float]) -> float:
    v = sorted(values)
    n = len(v)
    return v[n // 2] if n % 2 else 0.5 * (v[n // 2 - 1] + v[n // 2])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="ur5,panda")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--baseline", default="eb43808")
    parser.add_argument("--profile", default=None, metavar="DIR")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    report = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        (work / "table.toml").write_text(TABLE)
        base = baseline_tree(args.baseline, work / "baseline")
        for robot in args.robots.split(","):
            runs: dict[str, list[dict]] = {"baseline": [], "this": []}
            for _ in range(args.repeat):
                for label, tree in (("baseline", base), ("this", ROOT)):
                    runs[label].append(run(tree, command(robot, work, label), work, label))
            row: dict = {"robot": robot, "runs": runs}
            for label in runs:
                row[label] = {k: _median([r[k] for r in runs[label]]) for k in runs[label][0]}
            row["wall_ratio"] = row["this"]["wall"] / row["baseline"]["wall"]
            row["design_time_ratio"] = row["this"]["design_time"] / row["baseline"]["design_time"]
            report.append(row)
            b, t = row["baseline"], row["this"]
            print(f"{robot}: baseline {args.baseline} {b['wall']:.1f} s wall "
                  f"({b['design_time']:.1f} s design, criterion {b['criterion']:.1f}); "
                  f"this tree {t['wall']:.1f} s wall "
                  f"({t['design_time']:.1f} s design, criterion {t['criterion']:.1f}); ratio "
                  f"{row['wall_ratio']:.2f} (wall), {row['design_time_ratio']:.2f} (design)",
                  flush=True)  # fmt: skip
            if args.profile:
                out = Path(args.profile)
                out.mkdir(parents=True, exist_ok=True)
                prof = out / f"{robot}.prof"
                run(ROOT, command(robot, work, "profile"), work, "profile", profile=prof)
                text = io.StringIO()
                pstats.Stats(str(prof), stream=text).sort_stats("tottime").print_stats(8)
                print(text.getvalue().split("ncalls", 1)[-1][:3000], flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
