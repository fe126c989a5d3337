"""Whole-process measurements for the benchmarks: wall time and peak resident memory.

Each command runs in its own child process; ``os.wait4`` returns that child's
resource usage alone, so ``ru_maxrss`` is its own peak resident set [KiB on Linux].
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Run:
    """One child process: wall time [s], peak resident memory [MiB], exit status."""

    seconds: float
    peak_mib: float
    status: int
    stderr: str = ""


def run(cmd: list[str], env: dict | None = None, cwd: str | None = None) -> Run:
    """Run ``cmd`` (stdout discarded) and measure it."""
    full_env = dict(os.environ if env is None else env)
    full_env.setdefault("OPENBLAS_NUM_THREADS", "1")
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        env=full_env,
        cwd=cwd,
    )
    # read stderr while waiting, so a chatty child never blocks on a full pipe
    err = proc.stderr.read().decode(errors="replace") if proc.stderr is not None else ""
    _, status, usage = os.wait4(proc.pid, 0)
    seconds = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    return Run(seconds, usage.ru_maxrss / 1024.0, proc.returncode, err)


def median_runs(cmd: list[str], repeat: int, env: dict | None = None) -> tuple[Run, list[Run]]:
    """``repeat`` runs of ``cmd``; the run of median time and all runs."""
    runs = [run(cmd, env) for _ in range(repeat)]
    for r in runs:
        if r.status != 0:
            raise RuntimeError(f"{' '.join(cmd)} exited {r.status}: {r.stderr.strip()[-400:]}")
    med = statistics.median(r.seconds for r in runs)
    return min(runs, key=lambda r: abs(r.seconds - med)), runs


def byte_compile() -> str:
    """Byte-compile the ``manip_id`` this interpreter imports, as ``pip install`` does.

    An environment with ``PYTHONDONTWRITEBYTECODE=1`` (or a read-only checkout) never
    writes ``__pycache__/*.pyc`` for a source tree on ``PYTHONPATH``, so every process
    would compile the package's ~190 modules from source (about 0.2 s of start-up that
    an installed package does not pay). Python reads existing ``.pyc`` files whatever
    that variable says; ``compileall`` writes them. Returns a line saying what was done.
    """
    import compileall
    import importlib.util

    spec = importlib.util.find_spec("manip_id")
    if spec is None or not spec.submodule_search_locations:
        return "manip_id not found: nothing byte-compiled"
    folder = list(spec.submodule_search_locations)[0]
    ok = compileall.compile_dir(folder, quiet=1)
    return f"byte-compiled {folder} ({'ok' if ok else 'with errors'}), as pip install does"


def manip_id_command() -> list[str]:
    """The ``manip-id`` console script of this interpreter (``python -m manip_id`` if absent)."""
    script = Path(sys.executable).with_name("manip-id")
    return [str(script)] if script.exists() else [sys.executable, "-m", "manip_id"]


def machine() -> str:
    """A one-line description of the machine (CPU model, cores, memory, Python)."""
    import platform

    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = ""
    try:
        kib = int(Path("/proc/meminfo").read_text().split()[1])
        mem = f", {kib / 2**20:.0f} GiB RAM"
    except (OSError, ValueError, IndexError):
        pass
    return f"{cpu}, {os.cpu_count()} cores{mem}, Python {platform.python_version()}"


def local_cluster(workers: int) -> tuple:
    """``(client, cluster, start-up [s])`` of ``manip_id.execution.connect("local:N")``
    for ``workers`` > 0; ``(None, None, None)`` for 0 (the local case, no Dask)."""
    if workers <= 0:
        return None, None, None
    from manip_id.execution import connect  # the benchmark's own import, timed apart

    t0 = time.perf_counter()
    client, cluster = connect(f"local:{workers}")
    return client, cluster, time.perf_counter() - t0
