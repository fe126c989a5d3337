"""manip_id against FIGAROH 1.0.2 on the same identification: whole processes, one run.

    FIGAROH_PYTHON=/path/to/env/bin/python python experiments/bench_figaroh.py [--samples 100000]

The work: ur10 with viscous and Coulomb friction, ``--samples`` samples at
200 Hz of the CLI's simulated excitation (5-harmonic random Fourier
trajectory, seed 0, torque noise 1 % of each joint's RMS), base parameters
and their least-squares estimate with standard deviations.

- manip_id: ``manip-id identify ur10 --simulate --friction viscous,coulomb
  --duration D --rate 200 --json OUT`` (it simulates the record itself: its
  time includes the inverse dynamics of every sample);
- FIGAROH: ``experiments/figaroh_identify.py`` run by ``$FIGAROH_PYTHON``, an
  interpreter of an environment where ``pip install figaroh==1.0.2`` was
  done (FIGAROH and manip_id need not share one). It reads the very same
  record, written by this script beforehand (not timed) to an NPZ file.

Each process is measured alone (wall time, peak resident memory); the table
prints FIGAROH / manip_id ratios against the targets of issue 16 (15x time,
12x memory) and, as a check that the work is the same, both base parameter
counts and relative torque errors. Without ``FIGAROH_PYTHON`` (or when it
cannot import figaroh) FIGAROH is skipped with a message and manip_id alone
is measured.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from _measure import byte_compile, machine, manip_id_command, run  # noqa: E402

RATE = 200.0  # [Hz]
TARGET_TIME, TARGET_MEMORY = 15.0, 12.0


def figaroh_python() -> tuple[str | None, str]:
    """FIGAROH's interpreter from $FIGAROH_PYTHON and its version, or None and why not."""
    exe = os.environ.get("FIGAROH_PYTHON")
    if not exe:
        return None, "FIGAROH_PYTHON is not set"
    try:
        out = subprocess.run(
            [exe, "-c", "import importlib.metadata as m; print(m.version('figaroh'))"],
            capture_output=True,
            text=True,
            timeout=120,
        )
    except OSError as exc:
        return None, f"cannot run FIGAROH_PYTHON={exe}: {exc}"
    if out.returncode != 0:
        return None, f"{exe} cannot import figaroh: {out.stderr.strip().splitlines()[-1:]}"
    return exe, out.stdout.strip()


def write_record(n: int, folder: Path) -> tuple[Path, str, str]:
    """The CLI's simulated record of ``n`` samples as NPZ; also the URDF and its package dir."""
    import numpy as np

    from manip_id.robot.model import load_robot
    from manip_id.simulation import MeasurementNoise, SimulationStream
    from manip_id.trajectories import random_trajectory

    robot = load_robot("ur10", friction="viscous,coulomb")
    traj = random_trajectory(robot, harmonics=5, seed=0)  # as manip-id --simulate --seed 0
    stream = SimulationStream(
        robot, traj, duration=(n - 1) / RATE, rate=RATE, noise=MeasurementNoise(tau=0.01)
    )
    ds = stream.dataset()
    path = folder / "record.npz"
    np.savez(path, q=ds.q, dq=ds.dq, ddq=ds.ddq, tau=ds.tau)
    return path, str(robot.source), str(robot.package_dirs[0])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=100000, help="samples [default 1e5]")
    parser.add_argument("--workers", type=int, default=1, help="manip-id --workers [default 1]")
    parser.add_argument("--json", type=Path, help="write the figures as JSON")
    args = parser.parse_args(argv)
    n = args.samples
    duration = (n - 1) / RATE  # [s]: floor(duration * rate) + 1 = n samples

    fig_exe, fig_version = figaroh_python()
    print(f"machine: {machine()}")
    print(byte_compile())
    print(f"work: ur10, viscous + Coulomb friction, {n:,} simulated samples at {RATE:g} Hz")
    with tempfile.TemporaryDirectory(prefix="bench_figaroh_") as tmp:
        tmp_path = Path(tmp)
        ours_json = tmp_path / "manip_id.json"
        cmd = [*manip_id_command(), "identify", "ur10", "--simulate"]
        cmd += ["--friction", "viscous,coulomb", "--duration", repr(duration)]
        cmd += ["--rate", repr(RATE), "--workers", str(args.workers), "--json", str(ours_json)]
        ours = run(cmd)
        if ours.status != 0:
            print(f"manip-id failed ({ours.status}): {ours.stderr.strip()[-600:]}", file=sys.stderr)
            return 1
        rep = json.loads(ours_json.read_text())
        rows = [
            (
                f"manip_id (CLI, workers={args.workers})",
                ours,
                rep["n_base"],
                rep["relative_error"]["train"],
            )
        ]
        theirs = None
        phases = {"manip_id": rep["timings"]}
        if fig_exe is None:
            print(f"FIGAROH skipped: {fig_version} (see this script's docstring)")
        else:
            data, urdf, pkg = write_record(n, tmp_path)
            fig_json = tmp_path / "figaroh.json"
            theirs = run(
                [fig_exe, str(HERE / "figaroh_identify.py"), str(data), urdf, pkg, str(fig_json)]
            )
            if theirs.status != 0:
                print(f"FIGAROH failed ({theirs.status}): {theirs.stderr.strip()[-600:]}")
                theirs = None
            else:
                frep = json.loads(fig_json.read_text())
                phases["FIGAROH"] = frep["timings"]
                rows.append(
                    (f"FIGAROH {fig_version}", theirs, frep["n_base"], frep["relative_error"])
                )

    print(f"{'tool':32s} {'time [s]':>9s} {'peak [MiB]':>11s} {'base':>5s} {'rel. error':>11s}")
    for name, r, n_base, rel in rows:
        print(f"{name:32s} {r.seconds:9.2f} {r.peak_mib:11.1f} {n_base:5d} {100 * rel:10.3f}%")
    for tool, tm in phases.items():  # each process's own account of its time [s]
        print(f"  {tool} phases: " + ", ".join(f"{k} {v:.2f}" for k, v in tm.items()))
    out = {"machine": machine(), "samples": n, "manip_id": ours.__dict__, "phases": phases}
    if theirs is not None:
        t_ratio, m_ratio = theirs.seconds / ours.seconds, theirs.peak_mib / ours.peak_mib
        ok_t = "ok" if t_ratio >= TARGET_TIME else "MISSED"
        ok_m = "ok" if m_ratio >= TARGET_MEMORY else "MISSED"
        print(
            f"FIGAROH / manip_id: time {t_ratio:.1f}x (target >= {TARGET_TIME:g}x: {ok_t}), "
            f"peak memory {m_ratio:.1f}x (target >= {TARGET_MEMORY:g}x: {ok_m})"
        )
        out.update({"figaroh": theirs.__dict__, "time_ratio": t_ratio, "memory_ratio": m_ratio})
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=2, default=str) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
