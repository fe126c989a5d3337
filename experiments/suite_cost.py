"""What a command costs as a whole process tree: wall time and peak memory.

Runs one command (by default the test suite as ``make test`` runs it) and samples its
whole process tree (the command, its children, their children: pytest workers, CLI
subprocesses, browsers) every ``--every`` seconds. Two sums are kept per sample:

- ``rss``: the resident sets added up. Pages shared between processes (the libraries
  each worker maps: numpy, Pinocchio, LLVM) are counted once per process, so this
  overstates what the tree holds;
- ``pss``: the proportional set sizes added up (``/proc/PID/smaps_rollup``): a page
  shared by n processes counts 1/n in each, so the sum is the memory the tree holds.

Also reported: the largest single process's peak (what ``/usr/bin/time -v`` calls the
maximum resident set). A sample every 0.2 s can miss a peak shorter than that.

    python experiments/suite_cost.py                      # .venv/bin/python -m pytest -q -n 2 ...
    python experiments/suite_cost.py -- make test-serial  # any command after --
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = [str(ROOT / ".venv" / "bin" / "python"), "-m", "pytest", "-q", "-p", "no:cacheprovider"]


def _children() -> dict[int, list[int]]:
    tree: dict[int, list[int]] = {}
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            with open(f"/proc/{entry.name}/stat", encoding="ascii", errors="replace") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        tree.setdefault(int(fields[1]), []).append(int(entry.name))
    return tree


def _tree(root: int) -> list[int]:
    tree = _children()
    out, todo = [], [root]
    while todo:
        pid = todo.pop()
        out.append(pid)
        todo.extend(tree.get(pid, []))
    return out


def _name(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            words = f.read().split(b"\0")
    except OSError:
        return "?"
    text = " ".join(w.decode(errors="replace") for w in words[:6] if w)
    return text[:90]


def _memory(pid: int) -> tuple[float, float]:
    """(rss, pss) of one process [MiB]; zeros when it is gone."""
    rss = pss = 0.0
    try:
        with open(f"/proc/{pid}/smaps_rollup", encoding="ascii") as f:
            for line in f:
                if line.startswith("Rss:"):
                    rss = int(line.split()[1]) / 1024
                elif line.startswith("Pss:"):
                    pss = int(line.split()[1]) / 1024
    except OSError:
        pass
    return rss, pss


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--every", type=float, default=0.2, help="sampling period [s]")
    parser.add_argument("command", nargs="*", help="the command (after --)")
    args = parser.parse_args(argv)
    cmd = args.command or DEFAULT
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env)
    peak_rss = peak_pss = largest = 0.0
    at = 0.0
    holders: list[tuple[float, str]] = []
    while proc.poll() is None:
        pids = _tree(proc.pid)
        sample = [_memory(p) for p in pids]
        rss = sum(r for r, _ in sample)
        pss = sum(p for _, p in sample)
        largest = max([largest, *(r for r, _ in sample)])
        if pss > peak_pss:
            peak_pss, at = pss, time.perf_counter() - t0
            holders = sorted(
                ((p, _name(pid)) for pid, (_, p) in zip(pids, sample, strict=True)), reverse=True
            )
        peak_rss = max(peak_rss, rss)
        time.sleep(args.every)
    wall = time.perf_counter() - t0
    print(
        f"\nsuite_cost: {' '.join(cmd)}\n"
        f"  exit {proc.returncode}, wall {wall:.1f} s\n"
        f"  process tree peak: {peak_pss:.0f} MiB proportional (at {at:.0f} s), "
        f"{peak_rss:.0f} MiB resident summed\n"
        f"  largest single process: {largest:.0f} MiB resident\n"
        "  at the tree's peak, by proportional set [MiB]:\n"
        + "\n".join(f"    {p:6.0f}  {name}" for p, name in holders[:8] if p >= 1),
        file=sys.stderr,
    )
    return proc.returncode


if __name__ == "__main__":
    raise SystemExit(main())
