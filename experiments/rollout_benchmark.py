"""Cost of the output-error refinement against least squares on the same 10^5 samples.

Simulates one Panda log (viscous, Coulomb and offset friction, 1 % torque noise) of
``--samples`` samples at 1 kHz with ``manip-id simulate``, then times whole processes:

    baseline   manip-id identify panda --data LOG --json ls.json
    refined    manip-id identify panda --data LOG --refine output-error --json ref.json

and reports the ratio and the refinement record (windows, iterations, its own seconds).
What bounds the refinement: each iteration costs ``windows x horizon`` linearizations
(20 000 by default) whatever the number of samples, plus one regressor pass over the data
for the torque sums; the number of iterations is at most 10.

Usage::

    .venv/bin/python experiments/rollout_benchmark.py [--samples N] [--repeat R]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _measure import byte_compile, manip_id_command, median_runs  # noqa: E402

FRICTION = "viscous,coulomb,offset"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=1)
    a = parser.parse_args()
    print(byte_compile())
    cli = manip_id_command()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "logs"
        sim = [*cli, "simulate", "panda", "--friction", FRICTION, "--out", str(out)]
        sim += ["--files", "1", "--rate", "1000", "--duration", str(a.samples / 1000)]
        median_runs(sim, 1)
        log = str(next(out.glob("*.npz")))
        base = [*cli, "identify", "panda", "--friction", FRICTION, "--data", log, "--quiet"]
        ls, _ = median_runs([*base, "--json", f"{tmp}/ls.json"], a.repeat)
        ref_cmd = [*base, "--refine", "output-error", "--json", f"{tmp}/ref.json"]
        ref, _ = median_runs(ref_cmd, a.repeat)
        doc = json.loads(Path(f"{tmp}/ref.json").read_text())
        rec = doc["refinement"]
        n = json.loads(Path(f"{tmp}/ls.json").read_text())["n_samples"]
    print(f"samples: {n}")
    print(f"least squares (whole process): {ls.seconds:.1f} s, peak {ls.peak_mib:.0f} MiB")
    print(f"with --refine output-error:    {ref.seconds:.1f} s, peak {ref.peak_mib:.0f} MiB")
    print(f"ratio: {ref.seconds / ls.seconds:.2f}x")
    print(
        f"refinement: {rec['seconds']:.1f} s, {rec['windows']} windows x {rec['steps']} steps, "
        f"{rec['iterations']} iterations ({rec['accepted_steps']} accepted), "
        f"{rec['seconds'] / max(rec['iterations'], 1):.2f} s per iteration"
    )


if __name__ == "__main__":
    main()
