"""The simulated path through the CLI at scale: time and peak memory against the floor.

    python experiments/bench_simulated.py [--sizes 100000 1000000]

Per size N, two whole processes side by side:

- floor: ``python -c`` loading ur10 and calling ``pinocchio.computeJointTorqueRegressor``
  once per sample on N states, nothing else (the floor of issue 16);
- manip_id: ``manip-id identify ur10 --simulate --friction viscous,coulomb --rate 200
  --duration (N - 1)/200 --json OUT``: simulation in blocks, streamed least squares.

Prints wall time, peak resident memory, the time ratio to the floor and the
memory target (under 400 MB at 10^6 samples).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _measure import machine, manip_id_command, run  # noqa: E402

RATE = 200.0  # [Hz]
MEMORY_TARGET = 400.0  # [MB] at 10^6 samples

FLOOR = """
import sys
import pinocchio as pin
from manip_id.robot.model import load_robot
n = int(sys.argv[1])
robot = load_robot("ur10")
m, d = robot.model, robot.model.createData()
f = pin.computeJointTorqueRegressor
for start in range(0, n, 65536):
    q, dq, ddq = robot.random_states(min(65536, n - start), seed=start)
    for k in range(q.shape[0]):
        f(m, d, q[k], dq[k], ddq[k])
"""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[100000, 1000000])
    parser.add_argument("--json", type=Path, help="write the figures as JSON")
    args = parser.parse_args(argv)
    print(f"machine: {machine()}")
    print("ur10, viscous + Coulomb friction, simulated at 200 Hz, whole processes")
    print(
        f"{'N':>9s} {'floor [s]':>10s} {'manip_id [s]':>13s} {'ratio':>6s} "
        f"{'floor [MB]':>11s} {'manip_id [MB]':>14s}"
    )
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.sizes:
            floor = run([sys.executable, "-c", FLOOR, str(n)])
            report = Path(tmp) / f"r{n}.json"
            cmd = [*manip_id_command(), "identify", "ur10", "--simulate"]
            cmd += ["--friction", "viscous,coulomb", "--rate", repr(RATE)]
            cmd += ["--duration", repr((n - 1) / RATE), "--json", str(report)]
            ours = run(cmd)
            for name, r in (("floor", floor), ("manip-id", ours)):
                if r.status != 0:
                    print(f"{name} failed ({r.status}): {r.stderr.strip()[-400:]}", file=sys.stderr)
                    return 1
            mem_mb = ours.peak_mib * 2**20 / 1e6
            note = ""
            if n >= 1000000:
                verdict = "ok" if mem_mb < MEMORY_TARGET else "MISSED"
                note = f"  (target < {MEMORY_TARGET:g} MB: {verdict})"
            print(
                f"{n:9,d} {floor.seconds:10.2f} {ours.seconds:13.2f} "
                f"{ours.seconds / floor.seconds:6.2f} {floor.peak_mib * 2**20 / 1e6:11.0f} "
                f"{mem_mb:14.0f}{note}"
            )
            timings = json.loads(report.read_text())["timings"]
            out.append(
                {"n": n, "floor": floor.__dict__, "manip_id": ours.__dict__, "timings": timings}
            )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
