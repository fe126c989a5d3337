"""Standstill and Coulomb friction: plain sign(dq), a velocity deadband, or a smooth tanh(dq/eps)?

    python experiments/standstill_coulomb.py [--seed 0] [--noise-dq 0.005] [--json OUT]

A stop-and-go excitation of the ur5 (viscous and Coulomb friction on every
joint): 4 s of motion (a 4-harmonic Fourier series under a smooth envelope),
then 3 s at rest, repeated, 200 Hz. At rest the drive holds the robot against
gravity and the friction torque sits anywhere in its stiction band: each rest
interval draws a preload ``f_s = r fc`` with ``r ~ U(-1, 1)``. Measured dq
carries white noise (``--noise-dq`` [rad/s], encoder differentiation), tau 1 %
noise; ddq is given (the comparison is about the friction column, not the
filter). Torques come from ``pinocchio.rnea`` plus friction, independent of
manip_id's regressor. Training and validation runs differ by their seeds.

Three models of the Coulomb column, all fitted by ordinary least squares on the
same base columns:

- sign: ``fc sign(dq_meas)`` on every row (what a fit does by default);
- deadband EPS: the same column, the rows of joint j with ``|dq_j| < EPS``
  left out of the fit (``--velocity-deadband``; the pipeline's own path is
  checked to give the same estimate);
- tanh eps: ``fc tanh(dq_meas / eps)`` on every row (smooth, no row left out).

On all rows the deadband model predicts no Coulomb torque at rest (its column
zeroed where ``|dq_j| < EPS``).

Printed: the validation torque error on the moving rows (|dq| >= EPS, where
every model predicts) and on all rows, and the error of the friction
estimates against the truth (fv, fc, relative, over all joints).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin

from manip_id.identification import FileOptions

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from _logs import FC, FV, fourier, truth  # noqa: E402

from manip_id import load_robot  # noqa: E402
from manip_id.estimators import InformationAccumulator, solve_accumulator  # noqa: E402
from manip_id.identifiability import analyze  # noqa: E402
from manip_id.robot.regressor import regressor  # noqa: E402

RATE = 200.0
MOVE, REST = 4.0, 3.0  # [s]


def envelope(t):
    """1 while moving, 0 at rest, smooth (C2) ramps of 0.5 s; and its two derivatives."""
    period = MOVE + REST
    u = np.mod(t, period)
    ramp = 0.5
    e, de, dde = np.zeros_like(t), np.zeros_like(t), np.zeros_like(t)
    up = u < ramp
    mid = (u >= ramp) & (u < MOVE - ramp)
    down = (u >= MOVE - ramp) & (u < MOVE)
    e[mid] = 1.0
    for mask, x, sign in ((up, u / ramp, 1.0), (down, (MOVE - u) / ramp, -1.0)):
        s = x[mask]
        e[mask] = s**3 * (10 - 15 * s + 6 * s**2)  # smoothstep, C2
        de[mask] = sign * 30 * s**2 * (1 - s) ** 2 / ramp
        dde[mask] = 60 * s * (1 - s) * (1 - 2 * s) / ramp**2
    return e, de, dde


def run(robot, seed, duration, noise_dq):
    rng = np.random.default_rng(seed)
    t = np.arange(int(duration * RATE)) / RATE
    f, df, ddf = fourier(t, robot.nv, seed, amp=0.8)
    e, de, dde = envelope(t)
    q0 = rng.uniform(-0.5, 0.5, robot.nv)
    q = q0 + e[:, None] * f
    dq = de[:, None] * f + e[:, None] * df
    ddq = dde[:, None] * f + 2 * de[:, None] * df + e[:, None] * ddf
    model, data = robot.model, robot.model.createData()
    tau = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(t.size)])
    moving = np.abs(dq) > 1e-9
    fric = FV[: robot.nv] * dq + FC[: robot.nv] * np.sign(dq)
    interval = np.floor(t / (MOVE + REST)).astype(int)
    preload = rng.uniform(-1, 1, (interval.max() + 1, robot.nv)) * FC[: robot.nv]
    fric = np.where(moving, fric, preload[interval])
    tau = tau + fric
    tau += 0.01 * tau.std(axis=0) * rng.standard_normal(tau.shape)
    dq_meas = dq + noise_dq * rng.standard_normal(dq.shape)
    return t, q, dq_meas, ddq, tau


def columns(robot, q, dq, ddq, base, smooth=None, dead=None):
    """Base-column regressor (N, nv, r); the Coulomb columns as tanh(dq/smooth) if given,
    or zero where |dq| < dead (a deadband model predicting no Coulomb torque at rest)."""
    Y = regressor(robot, q, dq, ddq)
    names = list(robot.parameter_names)
    for j, dof in enumerate(robot.dof_names):
        c = names.index(f"{dof}.fc")
        if smooth is not None:
            Y[:, j, c] = np.tanh(dq[:, j] / smooth)
        if dead is not None:
            Y[np.abs(dq[:, j]) < dead, j, c] = 0.0
    return np.ascontiguousarray(Y[:, :, base.independent])


def fit(Yb, tau, keep=None):
    acc = InformationAccumulator(Yb.shape[2], Yb.shape[1])
    if keep is None:
        acc.add(Yb, tau)
    else:  # per-joint rows: a joint's left-out rows contribute nothing
        for j in range(Yb.shape[1]):
            Yj = np.zeros_like(Yb)
            tj = np.zeros_like(tau)
            Yj[keep[:, j], j] = Yb[keep[:, j], j]
            tj[keep[:, j], j] = tau[keep[:, j], j]
            acc.add(Yj, tj)
    return solve_accumulator(acc).estimate


def error(Yb, tau, est, rows):
    r = (Yb @ est - tau)[rows]
    return float(np.linalg.norm(r) / np.linalg.norm(tau[rows]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--duration", type=float, default=70.0)
    parser.add_argument("--noise-dq", type=float, default=0.005)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    robot = load_robot("ur5", friction=("viscous", "coulomb"))
    base = analyze(robot).base
    train = run(robot, args.seed, args.duration, args.noise_dq)
    valid = run(robot, args.seed + 100, args.duration, args.noise_dq)
    beta = base.to_base(truth(robot))
    names = list(base.base_names)
    fric = [i for i, n in enumerate(names) if n.endswith((".fv", ".fc"))]
    eps_db = 3 * args.noise_dq
    _, qv, dqv, ddqv, tauv = valid
    moving_v = np.abs(dqv) >= eps_db
    rows_all = np.ones_like(moving_v)
    still_share = float(np.mean(np.abs(dqv) < eps_db))
    models = [("sign", None, None), (f"deadband {eps_db:g}", None, eps_db)]
    models += [(f"tanh {e:g}", e, None) for e in (0.5 * eps_db, eps_db, 2 * eps_db, 4 * eps_db)]
    _, q, dq, ddq, tau = train
    print(
        f"ur5 stop-and-go: {args.duration:g} s at {RATE:g} Hz, {100 * still_share:.0f} % of the "
        f"rows at |dq| < {eps_db:g} rad/s; dq noise {args.noise_dq:g} rad/s"
    )
    print(f"{'model':16s} {'val. moving':>12s} {'val. all':>10s} {'friction err':>13s}")
    rows = {}
    for label, smooth, deadband in models:
        Yb = columns(robot, q, dq, ddq, base, smooth)
        keep = None if deadband is None else np.abs(dq) >= deadband
        est = fit(Yb, tau, keep)
        Yv = columns(robot, qv, dqv, ddqv, base, smooth)
        e_mov = error(Yv, tauv, est, moving_v)
        if deadband is not None:  # at rest the deadband model predicts no Coulomb torque
            Yv = columns(robot, qv, dqv, ddqv, base, dead=deadband)
        e_all = error(Yv, tauv, est, rows_all)
        f_err = float(np.linalg.norm(est[fric] - beta[fric]) / np.linalg.norm(beta[fric]))
        rows[label] = {"validation_moving": e_mov, "validation_all": e_all, "friction_error": f_err}
        print(f"{label:16s} {100 * e_mov:11.2f}% {100 * e_all:9.2f}% {100 * f_err:12.2f}%")
        if deadband is not None:  # the pipeline's own deadband path gives the same estimate
            import tempfile

            from manip_id.datasets import Dataset, save_dataset
            from manip_id.identification import PreprocessOptions, identify

            with tempfile.TemporaryDirectory() as tmp:
                path = save_dataset(
                    Dataset(t=train[0], q=q, dq=dq, tau=tau, ddq=ddq, joint_names=robot.dof_names),
                    Path(tmp) / "train.npz",
                )
                res = identify(
                    robot,
                    [path],
                    base=base,
                    files=FileOptions(
                        preprocess=PreprocessOptions(velocity_deadband=deadband), audit=False
                    ),
                )
            gap = float(np.abs(res.estimate - est).max() / np.abs(est).max())
            rows[label]["pipeline_difference"] = gap
            print(f"{'':16s} (manip_id pipeline estimate differs by {gap:.1e})")
    if args.json:
        Path(args.json).write_text(
            json.dumps({"still_share": still_share, "models": rows}, indent=2)
        )


if __name__ == "__main__":
    main()
