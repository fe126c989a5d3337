"""Closed-loop logs with a known PD controller: OLS, WLS, output error, IV and DIDIM.

Whole command-line processes, as a user runs them. Per robot (ur5, panda: viscous friction,
inertias perturbed by about 20 %, the truth of ``manip-id simulate``) and torque noise (1 %
and 5 % of each joint's RMS commanded torque), with position noise (default 1e-3 rad): a
critically damped PD controller per joint (natural frequency ``--wn`` at the neutral pose's
diagonal inertia) tracks a random excitation at 1 kHz (``manip-id simulate --controller``),
two logs, 10 s each. ``manip-id identify`` on the first (accelerations differentiated from
the noisy positions, cut-off ``--cutoff``) with each method; ``manip-id validate`` on the
second, a new motion, for the rollout error (0.25 s horizon). Printed per method:

- base-parameter error against the truth (truth.json): the median over the base parameters
  of ``|theta_hat - theta| / |theta|`` (those with ``|theta| > 1e-6 max |theta|``), and the
  relative norm ``||theta_hat - theta|| / ||theta||``;
- the validation torque error on the second log, and the rollout position error (RMS over
  joints of the per-joint RMS at the horizon) [rad];
- the wall time of the identify process and its ratio to OLS measured in the same run, and
  the in-process time of the fit with its closed-loop or refinement step (the result's
  ``timings``), with its ratio to OLS's.

Usage::

    .venv/bin/python experiments/closed_loop_estimators.py [--robots ur5,panda] [--wn 30]
        [--position-noise 1e-3] [--cutoff 20] [--duration 10]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import pinocchio as pin
from _measure import run as measured

from manip_id import load_robot
from manip_id.identification import load_result

CLI = [sys.executable, "-m", "manip_id"]
METHODS = {
    "ols": ["--method", "ols"],
    "wls": ["--method", "wls"],
    "output-error": ["--method", "ols", "--refine", "output-error"],
    "iv": ["--method", "iv"],
    "didim": ["--method", "didim"],
}


def controller_file(robot, wn: float, path: Path) -> Path:
    """Critically damped PD gains of natural frequency ``wn`` [rad/s] per joint."""
    model = robot.model
    mjj = np.diag(pin.crba(model, model.createData(), pin.neutral(model))).copy()
    kp, kd = mjj * wn**2, 2 * mjj * wn
    path.write_text(f"kp = {kp.tolist()}\nkd = {kd.tolist()}\n")
    return path


def check(cmd: list[str]) -> float:
    r = measured(cmd)
    if r.status != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({r.status}): {r.stderr[-2000:]}")
    return r.seconds


def errors(robot, result_path: Path, truth: dict) -> tuple[float, float]:
    res = load_result(result_path)
    theta = np.array([truth[n] for n in robot.parameter_names])
    tb = res.base.to_base(theta)
    big = np.abs(tb) > 1e-6 * np.abs(tb).max()
    med = float(np.median(np.abs(res.estimate - tb)[big] / np.abs(tb[big])))
    return med, float(np.linalg.norm(res.estimate - tb) / np.linalg.norm(tb))


def one(robot_name: str, tau_noise: float, a, tmp: Path) -> list[dict]:
    rob = ["--friction", "viscous"]  # the robot's profile (panda: fingers locked)
    robot = load_robot(robot_name, friction="viscous")
    ctrl = controller_file(robot, a.wn, tmp / f"{robot_name}.toml")
    sim = tmp / f"{robot_name}_{tau_noise:g}"
    check(
        [*CLI, "simulate", robot_name, *rob, "--out", str(sim), "--files", "2",
         "--duration", str(a.duration), "--rate", "1000", "--noise", str(tau_noise),
         "--position-noise", str(a.position_noise), "--perturb", "0.2",
         "--joint-terms", "fv=0.5", "--controller", str(ctrl), "--quiet"]
    )  # fmt: skip
    truth = json.loads((sim / "truth.json").read_text())["parameters"]
    train, valid = str(sim / "run_0.npz"), str(sim / "run_1.npz")
    rows = []
    for name, extra in METHODS.items():
        out = tmp / f"{sim.name}_{name}.json"
        cmd = [*CLI, "identify", robot_name, *rob, "--data", train, "--validate", valid]
        cmd += ["--cutoff", str(a.cutoff), *extra, "--json", str(out), "--quiet"]
        if name in ("iv", "didim"):
            cmd += ["--controller", str(ctrl)]
        seconds = check(cmd)
        med, norm = errors(robot, out, truth)
        doc = json.loads(out.read_text())
        rv = tmp / f"{sim.name}_{name}_rollout.json"
        check(
            [*CLI, "validate", robot_name, *rob, "--model", str(out), "--data", valid,
             "--horizon", "0.25", "--cutoff", str(a.cutoff), "--json", str(rv)]
        )  # fmt: skip
        roll = json.loads(rv.read_text())["rollout"]["identified"]["position_rms"]
        rows.append(
            {
                "robot": robot_name,
                "tau_noise": tau_noise,
                "method": name,
                "median_rel": med,
                "norm_rel": norm,
                "validation": doc["relative_error"]["validation"],
                "rollout": float(np.sqrt(np.mean(np.square(roll)))),
                "seconds": seconds,
                # in-process: the fit and its closed-loop / refinement step (no start-up)
                "fit_seconds": doc["timings"].get("total", 0.0)
                + doc["timings"].get("closed_loop", doc["timings"].get("refine", 0.0)),
                "iterations": (doc.get("closed_loop") or doc.get("refinement") or {}).get(
                    "iterations"
                ),
            }
        )
    base = next(r for r in rows if r["method"] == "ols")
    for r in rows:
        r["time_ratio"] = r["seconds"] / base["seconds"]
        r["fit_ratio"] = r["fit_seconds"] / base["fit_seconds"]
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="ur5,panda")
    parser.add_argument("--wn", type=float, default=30.0, help="PD natural frequency [rad/s]")
    parser.add_argument("--position-noise", type=float, default=1e-3, help="[rad]")
    parser.add_argument("--cutoff", type=float, default=20.0, help="low-pass cut-off [Hz]")
    parser.add_argument("--duration", type=float, default=10.0, help="per log [s]")
    parser.add_argument("--json", default=None, help="also write the rows as JSON here")
    a = parser.parse_args()
    print(
        f"PD at {a.wn:g} rad/s, 1 kHz, position noise {a.position_noise:g} rad, cut-off "
        f"{a.cutoff:g} Hz, {a.duration:g} s per log"
    )
    print(
        "| robot | torque noise | method | median rel. error | norm rel. error | "
        "validation torque error | rollout 0.25 s [rad] | identify [s] | vs OLS | "
        "fit [s] | vs OLS | iterations |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|", flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for robot_name in a.robots.split(","):
            for tau_noise in (0.01, 0.05):
                new = one(robot_name, tau_noise, a, Path(d))
                for r in new:
                    print(
                        f"| {r['robot']} | {100 * r['tau_noise']:g} % | {r['method']} | "
                        f"{100 * r['median_rel']:.2f} % | {100 * r['norm_rel']:.3f} % | "
                        f"{100 * r['validation']:.2f} % | {r['rollout']:.2e} | "
                        f"{r['seconds']:.1f} | {r['time_ratio']:.2f}x | "
                        f"{r['fit_seconds']:.1f} | {r['fit_ratio']:.2f}x | "
                        f"{r['iterations'] if r['iterations'] else ''} |",
                        flush=True,
                    )
                rows += new
                if a.json:
                    Path(a.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
