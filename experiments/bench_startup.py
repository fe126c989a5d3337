"""Start-up of the package and the CLI against ``import pinocchio``, whole processes.

    python experiments/bench_startup.py [--repeat 7] [--json OUT]

Four commands run side by side in one run, interleaved (round-robin, so a
change in the machine's load hits all of them alike), each ``--repeat`` times
in a fresh process; the table gives the median wall time, the peak resident
memory of that run and the ratio of time to the baseline ``python -c "import
pinocchio"``, with the target of issue 16:

    python -c "import manip_id"    within 1.5x
    manip-id --help                within 2x
    manip-id robots                within 4x (robot metadata without geometry)
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _measure import machine, manip_id_command, run  # noqa: E402

CASES = [
    ("python -c 'import pinocchio'", [sys.executable, "-c", "import pinocchio"], None),
    ("python -c 'import manip_id'", [sys.executable, "-c", "import manip_id"], 1.5),
    ("manip-id --help", [*manip_id_command(), "--help"], 2.0),
    ("manip-id robots", [*manip_id_command(), "robots"], 4.0),
]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7, help="runs of each command")
    parser.add_argument("--json", type=Path, help="write the figures as JSON")
    args = parser.parse_args(argv)

    runs: dict[str, list] = {name: [] for name, _, _ in CASES}
    for _ in range(args.repeat):
        for name, cmd, _ in CASES:
            r = run(cmd)
            if r.status != 0:
                print(f"{name} exited {r.status}: {r.stderr.strip()[-400:]}", file=sys.stderr)
                return 1
            runs[name].append(r)
    base = statistics.median(r.seconds for r in runs[CASES[0][0]])
    print(f"machine: {machine()}")
    print(f"start-up, median of {args.repeat} fresh processes each, interleaved")
    print(f"{'command':32s} {'time [s]':>9s} {'peak [MiB]':>11s} {'ratio':>7s} {'target':>8s}")
    out = []
    missed = 0
    for name, _, target in CASES:
        med = statistics.median(r.seconds for r in runs[name])
        peak = statistics.median(r.peak_mib for r in runs[name])
        ratio = med / base
        verdict = "" if target is None else ("ok" if ratio <= target else "MISSED")
        missed += verdict == "MISSED"
        goal = "baseline" if target is None else f"<= {target:g}x"
        print(f"{name:32s} {med:9.3f} {peak:11.1f} {ratio:6.2f}x {goal:>8s} {verdict}")
        out.append(
            {"command": name, "seconds": med, "peak_mib": peak, "ratio": ratio, "target": target}
        )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"machine": machine(), "cases": out}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
