"""A pytest plugin that records each test's CPU time and peak resident memory.

Load it with ``-p pytest_resources`` and ``experiments`` on ``PYTHONPATH``::

    PYTHONPATH=.:experiments python -m pytest -p pytest_resources \
        --resources-json experiments/results/suite_resources.json

Per test (setup, call and teardown together) it records:

- ``cpu_s``: CPU time [s] of the pytest process (user + system) plus that of the
  children it waited for (CLI subprocesses, forked workers), so a test's cost does
  not depend on how busy the machine is (wall time does);
- ``peak_mib``: the pytest process's peak resident set during the test [MiB]. Linux
  keeps one high-water mark per process (``VmHWM``); writing ``5`` to
  ``/proc/self/clear_refs`` resets it to the current resident set, so each test's
  peak is its own (on other systems the mark is never reset and the column is the
  running peak);
- ``rss_after_mib``: the resident set after the test [MiB], which shows what a test
  leaves behind (caches, leaks) for the tests after it;
- ``child_peak_mib``: the largest peak resident set of any child waited for so far
  [MiB] (``RUSAGE_CHILDREN`` cannot be reset: it is reported when it grew).

At the end the terminal shows the suite's CPU time, its peak resident set and the
15 tests costliest in CPU and in memory; ``--resources-json`` saves every row.
"""

from __future__ import annotations

import json
import os
import resource
import time
from pathlib import Path

import pytest

_CLEAR_REFS = Path("/proc/self/clear_refs")
_STATUS = Path("/proc/self/status")


def _status_kib(field: str) -> float:
    """``VmHWM``/``VmRSS`` of this process [KiB] (0 where /proc is absent)."""
    try:
        for line in _STATUS.read_text().splitlines():
            if line.startswith(field + ":"):
                return float(line.split()[1])
    except OSError:
        pass
    return 0.0


def _reset_peak() -> bool:
    try:
        _CLEAR_REFS.write_text("5")
        return True
    except OSError:
        return False


def _cpu_s() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def _children_peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0


class _Recorder:
    def __init__(self, json_path: str | None) -> None:
        self.json_path = json_path
        self.rows: list[dict] = []
        self.suite_peak_mib = 0.0
        self.t0_cpu = _cpu_s()
        self.t0_wall = time.perf_counter()

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(self, item, nextitem):
        resettable = _reset_peak()
        child_before = _children_peak_mib()
        cpu0 = _cpu_s()
        wall0 = time.perf_counter()
        yield
        peak = _status_kib("VmHWM") / 1024.0
        self.suite_peak_mib = max(self.suite_peak_mib, peak)
        child_after = _children_peak_mib()
        self.rows.append(
            {
                "test": item.nodeid,
                "slow": item.get_closest_marker("slow") is not None,
                "cpu_s": round(_cpu_s() - cpu0, 3),
                "wall_s": round(time.perf_counter() - wall0, 3),
                "peak_mib": round(peak, 1),
                "peak_resettable": resettable,
                "rss_after_mib": round(_status_kib("VmRSS") / 1024.0, 1),
                "child_peak_mib": round(child_after, 1) if child_after > child_before else 0.0,
            }
        )

    def pytest_terminal_summary(self, terminalreporter):
        if not self.rows:
            return
        cpu = _cpu_s() - self.t0_cpu
        wall = time.perf_counter() - self.t0_wall
        slow_cpu = sum(r["cpu_s"] for r in self.rows if r["slow"])
        child = max(r["child_peak_mib"] for r in self.rows)
        tr = terminalreporter
        tr.section("resources (experiments/pytest_resources.py)")
        tr.write_line(
            f"{len(self.rows)} tests: CPU {cpu:.1f} s ({slow_cpu:.1f} s in slow tests), "
            f"wall {wall:.1f} s, peak resident set {self.suite_peak_mib:.0f} MiB "
            f"(largest child {child:.0f} MiB)"
        )
        for key, label in (("cpu_s", "CPU [s]"), ("peak_mib", "peak [MiB]")):
            tr.write_line(f"15 tests with the largest {label}:")
            for r in sorted(self.rows, key=lambda r: -r[key])[:15]:
                tr.write_line(
                    f"  {r['cpu_s']:8.2f} s {r['peak_mib']:8.0f} MiB "
                    f"(after {r['rss_after_mib']:6.0f}) {r['test']}"
                )
        if self.json_path:
            path = Path(self.json_path)
            path.parent.mkdir(parents=True, exist_ok=True)
            summary = {
                "tests": len(self.rows),
                "cpu_s": round(cpu, 1),
                "wall_s": round(wall, 1),
                "peak_mib": round(self.suite_peak_mib, 1),
                "largest_child_peak_mib": round(child, 1),
                "cpus": os.cpu_count(),
            }
            path.write_text(json.dumps({"summary": summary, "rows": self.rows}, indent=1))
            tr.write_line(f"rows saved to {path}")


def pytest_addoption(parser):
    parser.addoption(
        "--resources-json",
        default=None,
        help="save each test's CPU time and peak resident memory to this JSON file",
    )


def pytest_configure(config):
    config.pluginmanager.register(
        _Recorder(config.getoption("--resources-json")), "manip_id_resources"
    )
