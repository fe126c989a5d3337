"""Every report kind, written by the command line and photographed in headless Chromium.

Writes simulated logs, then the reports of ``identify`` (one run, ``--consistent``),
``identify`` on several files in memory, the fleet (``--per-file``), ``payload``,
``monitor``, ``adapt``, ``rank`` and ``excite`` (panda above a table, a box beside it and
one far away, which the camera must frame) and the
page of ``view --html``; each report's
``index.html`` and ``scene.html`` are photographed at 1400 x 900 px (the scene at the
start, the middle and the end of its animation), so one can look at them::

    PYTHONPATH=. python experiments/screenshot_reports.py --out /tmp/shots

Needs the Debian package ``chromium``. The PNGs and the reports stay in ``--out``.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import time
from pathlib import Path

from manip_id.cli import main as manip_id

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
SIZE = (1400, 900)


def screenshot(page: Path, png: Path, fragment: str = "", size=SIZE) -> None:
    """``page`` (an HTML file) rendered by headless Chromium into ``png``."""
    cmd = [
        str(CHROMIUM),
        "--headless",
        "--no-sandbox",
        "--use-gl=swiftshader",
        "--enable-unsafe-swiftshader",
        "--disable-background-networking",
        "--no-first-run",
        "--hide-scrollbars",
        f"--user-data-dir={png.parent / '.chromium-profile'}",
        f"--window-size={size[0]},{size[1]}",
        f"--screenshot={png}",
        "--virtual-time-budget=5000",
        page.resolve().as_uri() + fragment,
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    if proc.returncode != 0 or not png.is_file():
        raise RuntimeError(f"chromium failed on {page}: {proc.stderr[-1000:]}")


def run(argv: list[str]) -> None:
    t0 = time.perf_counter()
    status = manip_id(argv)
    print(f"  [{time.perf_counter() - t0:5.1f} s] manip-id {' '.join(argv)} -> {status}")
    if status != 0:
        raise SystemExit(f"manip-id {argv[0]} failed ({status})")


def reports(out: Path) -> dict[str, Path]:
    """Write the logs and every report kind into ``out``; name -> report folder."""
    data, pay = out / "data", out / "payload-data"
    run(["simulate", "ur5", "--out", str(data), "--files", "4", "--duration", "6", "--force"])
    files = sorted(str(p) for p in data.glob("run_*.npz"))
    run(
        ["simulate", "ur5", "--out", str(pay), "--files", "1", "--duration", "6"]
        + ["--payload", "1.5", "--force"]
    )
    r = {k: out / k for k in ("identify", "files", "fleet", "payload", "monitor")}
    r |= {k: out / k for k in ("adapt", "rank")}
    run(
        ["identify", "panda", "--simulate", "--duration", "6", "--consistent"] + _rep(r, "identify")
    )
    run(
        ["identify", "ur5", "--data", *files[:3], "--json", str(out / "ur5.json")]
        + _rep(r, "files")
    )
    run(["identify", "ur5", "--data", *files, "--per-file"] + _rep(r, "fleet"))
    run(
        ["payload", "ur5", "--frame", "wrist_3_joint", "--consistent"]
        + ["--unloaded", str(pay / "run_0.npz"), "--loaded", str(pay / "payload_1.5kg_0.npz")]
        + _rep(r, "payload")
    )
    run(
        ["monitor", "ur5", "--model", str(out / "ur5.json"), "--calibrate", files[0]]
        + ["--data", files[3]]
        + _rep(r, "monitor")
    )
    run(["adapt", "panda", "--duration", "2"] + _rep(r, "adapt"))
    run(["rank", "ur5", "--data", files[0]] + _rep(r, "rank"))
    world = out / "world.toml"
    world.write_text(
        "[[plane]]\nnormal = [0, 0, 1]\noffset = -0.01\n"
        "[[box]]\nsize = [0.3, 0.3, 0.3]\nposition = [0.6, 0.0, 0.15]\n"
        "[[box]]\nsize = [0.3, 0.3, 0.3]\nposition = [1.6, 0.9, 0.15]\n"  # far: framed too
    )
    r["excite"] = out / "excite"
    run(
        ["excite", "panda", "--duration", "6", "--harmonics", "3", "--world", str(world)]
        + ["--starts", "3", "--maxiter", "15", "--out", str(out / "excite.mcap")]
        + _rep(r, "excite")
    )
    view = out / "view"
    view.mkdir(exist_ok=True)
    run(["view", "panda", "--simulate", "--html", str(view / "scene.html")])
    r["view"] = view
    return r


def _rep(r: dict, name: str) -> list[str]:
    return ["--report", str(r[name]), "--force"]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, required=True, help="folder of reports and PNGs")
    args = parser.parse_args()
    if CHROMIUM is None:
        print("headless Chromium not found (Debian package 'chromium')", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    shots = args.out / "png"
    shots.mkdir(exist_ok=True)
    for name, folder in reports(args.out).items():
        index = folder / "index.html"
        if index.is_file():
            screenshot(index, shots / f"{name}-index.png")
        scene = folder / "scene.html"
        if scene.is_file():
            for label, fragment in (("start", "#t=0"), ("middle", "#t=1"), ("late", "#t=3")):
                screenshot(scene, shots / f"{name}-scene-{label}.png", fragment)
    for png in sorted(shots.glob("*.png")):
        print(png)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
