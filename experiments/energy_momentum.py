"""Identification without accelerations: the energy and filtered momentum models.

Three parts:

1. simulated Panda (rigid bodies, armature, viscous, Coulomb and offset friction;
   8-harmonic random excitation, one 20.9 s period at 500 Hz, no ddq used):
   base-parameter errors noise-free (discretization only) and with 2 % torque
   noise over ``--seeds`` draws, against each model's predicted std, beside the
   dynamic model on the same samples (which uses the exact ddq);
2. the real Panda log (Gaz et al. 2019; first 70 % to identify, last 30 % to
   validate): the validation torque error of the dynamic model (states, ddq and
   torques filtered at 3 Hz) against the momentum and energy models, which see
   only filtered q and dq and the raw (resampled) torques, for a few state
   cut-offs and window lengths; the validation reference is the dynamic model's;
3. the energy model's base parameters against the dynamic model's on every
   listed robot (:func:`manip_id.models.check_energy_base`).

Run: ``.venv/bin/python experiments/energy_momentum.py [--data FOLDER] [--seeds 3] [--quick]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from manip_id import load_robot  # noqa: E402
from manip_id.identifiability import analyze  # noqa: E402
from manip_id.identification import (
    ModelOptions,
    identify,  # noqa: E402
)
from manip_id.models import check_energy_base  # noqa: E402
from manip_id.robot.model import available_robots  # noqa: E402
from manip_id.simulation import MeasurementNoise, simulate  # noqa: E402
from manip_id.trajectories import random_trajectory  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "panda_gaz2019"
FRICTION = "viscous,coulomb,offset"
RATE, WF, WINDOW = 500.0, 0.3, 0.05


def simulated(seeds: int) -> None:
    robot = load_robot("panda", friction=FRICTION, armature=True)
    theta = robot.nominal_parameters.copy()
    rng = np.random.default_rng(0)
    theta[robot.n_rigid :] = rng.uniform(0.05, 0.5, robot.n_parameters - robot.n_rigid)
    expected = analyze(robot).base.to_base(theta)
    traj = random_trajectory(robot, harmonics=8, wf=WF, seed=1)
    print(
        f"== simulated Panda: {len(expected)} base parameters, {RATE:g} Hz, "
        f"window {WINDOW:g} s (momentum bandwidth {3 / WINDOW:g} rad/s)"
    )
    print(
        f"{'model':9s} {'noise':>6s} {'max rel err':>12s} {'cond':>9s} "
        f"{'rms |err|/std':>14s} {'max |err|/std':>14s} {'time':>7s}"
    )
    for noise, n_seeds in ((0.0, 1), (0.02, seeds)):
        for model in ("dynamic", "energy", "momentum"):
            z, rel, cond, took = [], [], 0.0, 0.0
            for seed in range(n_seeds):
                ds = simulate(
                    robot,
                    traj,
                    duration=2 * np.pi / WF,
                    rate=RATE,
                    theta=theta,
                    noise=MeasurementNoise(tau=noise),
                    seed=seed,
                ).dataset
                t0 = time.perf_counter()
                ddq = ds.ddq if model == "dynamic" else None
                res = identify(
                    robot,
                    (ds.q, ds.dq, ddq, ds.tau),
                    model=ModelOptions(name=model, window_length=WINDOW, dt=1 / RATE),
                )
                took += time.perf_counter() - t0
                err = res.estimate - expected
                rel.append(np.max(np.abs(err) / np.maximum(np.abs(expected), 1e-3)))
                if noise > 0:
                    z.append(err / res.std)
                cond = res.condition_number
            zs = np.concatenate(z) if z else np.array([np.nan])
            print(
                f"{model:9s} {noise:6.0%} {max(rel):12.3e} {cond:9.4g} "
                f"{np.sqrt(np.mean(zs**2)):14.3f} {np.max(np.abs(zs)):14.3f} "
                f"{took / n_seeds:6.2f}s"
            )
    print()


def real(folder: Path, quick: bool) -> None:
    from manip_id.datasets import load_dataset
    from manip_id.signals import preprocess

    robot = load_robot("panda", friction=FRICTION)
    train_raw, valid_raw = load_dataset(folder).split(0.7)
    ref = preprocess(valid_raw)
    validation = (ref.q, ref.dq, ref.ddq, ref.tau)
    dyn = preprocess(train_raw)
    t0 = time.perf_counter()
    res = identify(robot, (dyn.q, dyn.dq, dyn.ddq, dyn.tau), validation=validation)
    print(f"== real Panda log, {len(res.estimate)} base parameters, split 70 % / 30 %")
    print(
        f"{'model':9s} {'states':>7s} {'window':>7s} {'rows':>6s} {'cond':>9s} "
        f"{'train*':>8s} {'validation':>11s} {'time':>7s}"
    )
    print(
        f"{'dynamic':9s} {'3 Hz':>7s} {'-':>7s} {dyn.n_samples:6d} {res.condition_number:9.4g} "
        f"{res.relative_error.train:8.3%} {res.relative_error.validation:11.3%} "
        f"{time.perf_counter() - t0:6.2f}s"
    )
    grid = (
        [("momentum", 3.0, 0.05, False), ("energy", 10.0, 0.01, False)]
        if quick
        else [
            ("momentum", 3.0, 0.02, False),
            ("momentum", 3.0, 0.05, False),
            ("momentum", 3.0, 0.2, False),
            ("momentum", 10.0, 0.05, False),
            ("energy", 3.0, 0.01, False),
            ("energy", 10.0, 0.004, False),
            ("energy", 10.0, 0.01, False),
            ("energy", 20.0, 0.01, False),
            ("energy", 3.0, 0.01, True),
            ("energy", 10.0, 0.01, True),
        ]
    )
    for model, cutoff, window, consistent in grid:
        states = preprocess(train_raw, cutoff=cutoff, filter_torque=False)
        dt = float(np.mean(np.diff(states.t)))
        t0 = time.perf_counter()
        r = identify(
            robot,
            (states.q, states.dq, None, states.tau),
            validation=validation,
            consistent=consistent,
            model=ModelOptions(name=model, window_length=window, dt=dt),
        )
        rows = round(states.n_samples * dt / window)
        label = model + ("+SDP" if consistent else "")
        print(
            f"{label:9s} {cutoff:5.0f}Hz {window:7.3f} {rows:6d} {r.condition_number:9.4g} "
            f"{r.relative_error.train:8.3%} {r.relative_error.validation:11.3%} "
            f"{time.perf_counter() - t0:6.2f}s"
        )
    print("* train: in the model's own equation (energy [J], filtered torque, torque)")
    print("+SDP: physically consistent estimate (SDP, nominal prior) on the same information")
    print()


def bases() -> None:
    print(
        f"== energy model base parameters against the dynamic model's (joint terms Ia, {FRICTION})"
    )
    differ = []
    for name in available_robots():
        c = check_energy_base(load_robot(name, friction=FRICTION, armature=True))
        if not c.same:
            differ.append(name)
        print(
            f"{name:28s} base {c.n_base_dynamic:4d}  energy rank on base columns "
            f"{c.rank_on_base_columns:4d}  regrouping residual {c.regrouping_residual:8.1e}  "
            f"{'same' if c.same else 'DIFFERENT'}"
        )
    print(
        f"{len(available_robots()) - len(differ)} of {len(available_robots())} robots: same "
        f"base parameters" + (f"; differ: {', '.join(differ)}" if differ else "")
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(DATA), help="folder of the Panda log")
    ap.add_argument("--seeds", type=int, default=3, help="noise draws in the simulation")
    ap.add_argument("--quick", action="store_true", help="fewer real-data configurations")
    args = ap.parse_args(argv)
    simulated(args.seeds)
    if (Path(args.data) / "rbt_log_time.txt").is_file():
        real(Path(args.data), args.quick)
    else:
        print(f"(no Panda log at {args.data}: real-data part skipped)\n")
    bases()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
