"""Physically consistent identification of the real Franka Emika Panda log, against plain OLS.

Run from the repository root::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python experiments/panda_consistent.py

The log (/work/shared/data/panda_gaz2019, or the folder given as the first argument)
is split 70 / 30 into training and validation, each part preprocessed alone (the
defaults of ``manip-id identify``). The model has viscous, Coulomb and offset
friction. Printed:

- the validation relative torque error per joint of OLS and of the consistent
  estimate (SDP and log-Cholesky solvers), and which bodies / terms of OLS's
  minimum-norm standard vector are not physical;
- the solve time of each consistent solver (the accumulation is shared and
  done once; each solver works from the same information matrix);
- the standard parameters of the last two bodies beside the nominal (URDF) ones;
- the fit scale ``k`` (the feasibility fit against its expected chi-square) beside
  two independent estimates of how much the OLS variance understates the honest one
  (batch means over contiguous blocks of the training residuals, and the sample rate
  over twice the low-pass cut-off), and the link masses at the default prior weight;
- the validation error, the link masses and the prior's move of the fit for a sweep
  of prior weights (in honest standard deviations, the default among them);
- the solve time against the number of samples (simulated, 10^3 and 10^5): the
  solvers see only the (r, r) information, so it does not grow with N.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from manip_id import identify, load_robot, regressor
from manip_id.datasets import load_dataset
from manip_id.estimators.consistent import DEFAULT_PRIOR_WEIGHT
from manip_id.identification import ConsistentOptions
from manip_id.signals import preprocess

DATA = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("/work/shared/data/panda_gaz2019")


def _batch_means(Y: np.ndarray, tau: np.ndarray, nv: int, blocks: int) -> float:
    """OLS variance inflation by batch means: ``sum_b g_b^T (s A)^-1 g_b / r * B/(B-1)``.

    ``g_b = Y_b^T e_b``, the score of contiguous block b at the OLS fit (about 1 for
    white residuals; the honest-to-OLS variance ratio when blocks outlast the
    residuals' correlation).
    """
    A = Y.T @ Y
    beta = np.linalg.solve(A, Y.T @ tau)
    e = tau - Y @ beta  # [N m]
    s = float(e @ e) / (e.size - A.shape[0])  # [(N m)^2]
    edges = np.linspace(0, e.size // nv, blocks + 1).astype(int) * nv
    total = sum(
        float(g @ np.linalg.solve(A, g))
        for g in (Y[i:j].T @ e[i:j] for i, j in zip(edges[:-1], edges[1:], strict=True))
    )
    return total / (s * A.shape[0]) * blocks / (blocks - 1)


def main() -> None:
    robot = load_robot("panda", friction="viscous,coulomb,offset")
    data = load_dataset(DATA)
    train, valid = data.split(0.7)
    train, valid = preprocess(train), preprocess(valid)
    args = (robot, (train.q, train.dq, train.ddq, train.tau))
    v = (valid.q, valid.dq, valid.ddq, valid.tau)
    print(f"real Panda log {DATA}: {train.n_samples} training, {valid.n_samples} validation")

    t0 = time.perf_counter()
    ols = identify(*args, validation=v)
    t_ols = time.perf_counter() - t0
    runs = {"OLS": (ols, t_ols)}
    for solver in ("sdp", "logchol"):
        t0 = time.perf_counter()
        res = identify(
            *args, validation=v, consistent=ConsistentOptions(enabled=True, solver=solver)
        )
        runs[f"consistent {solver}"] = (res, time.perf_counter() - t0)

    print("\nvalidation relative torque error [%] per joint")
    w = max(len(k) for k in runs)
    print(f"{'':<{w}}  " + " ".join(f"{d[-6:]:>8}" for d in robot.dof_names) + "     all")
    for label, (res, _) in runs.items():
        per = res.relative_error.validation_per_joint
        print(
            f"{label:<{w}}  "
            + " ".join(f"{100 * e:8.3f}" for e in per)
            + f"  {100 * res.relative_error.validation:6.3f}"
        )
    base = ols.relative_error.validation
    for label, (res, _) in runs.items():
        ratio = res.relative_error.validation / base
        print(
            f"{label:<{w}}  validation / OLS = {ratio:.3f}, physically consistent: "
            f"{res.physically_consistent}"
        )
    print("\nOLS (minimum-norm standard parameters) is not physical at:")
    for m in ols.standard.consistency.messages():
        print(f"  {m}")

    print("\ntimes [s] (whole identify call; the solve of the consistent problem alone)")
    for label, (res, total) in runs.items():
        solve = res.standard.time if res.standard.solver else res.timings.get("solve", 0.0)
        status = res.standard.status if res.standard.solver else ""
        print(f"{label:<{w}}  total {total:6.2f}  solve {solve:6.3f}  {status}")
    sdp_t = runs["consistent sdp"][0].standard.time
    lc_t = runs["consistent logchol"][0].standard.time
    print(f"logchol / sdp solve time: {lc_t / sdp_t:.2f}")
    a, b = runs["consistent sdp"][0], runs["consistent logchol"][0]
    print(
        "sdp vs logchol: relative difference of base parameters "
        f"{np.linalg.norm(a.estimate - b.estimate) / np.linalg.norm(a.estimate):.3g}, "
        f"standard {np.linalg.norm(a.standard.values - b.standard.values) / np.linalg.norm(a.standard.values):.3g}; "  # noqa: E501
        f"fit [std^2] {a.standard.fit:.6g} vs {b.standard.fit:.6g}"
    )

    print("\nstandard parameters of the last two bodies (consistent sdp) beside the nominal ones")
    names = robot.parameter_names
    units = robot.parameter_units
    nominal = robot.nominal_parameters
    theta_s = a.standard.values
    theta_l = b.standard.values
    print(f"{'parameter':<20} {'unit':<9} {'nominal':>11} {'sdp':>11} {'logchol':>11}")
    for j in robot.joint_names[-2:]:
        for k in range(robot.parameter_index(f"{j}.m"), robot.parameter_index(f"{j}.m") + 10):
            print(
                f"{names[k]:<20} {units[k]:<9} {nominal[k]:11.5g} {theta_s[k]:11.5g} "
                f"{theta_l[k]:11.5g}"
            )
        for t in robot.terms.enabled:
            k = robot.parameter_index(f"{j}.{t}")
            print(
                f"{names[k]:<20} {units[k]:<9} {nominal[k]:11.5g} {theta_s[k]:11.5g} "
                f"{theta_l[k]:11.5g}"
            )

    print("\nhow much the OLS covariance understates the honest one (variance ratio)")
    st = a.standard
    print(f"  fit scale k = f_feas / r (used by the solver):      {st.fit_scale:8.1f}")
    Y = regressor(robot, train.q, train.dq, train.ddq)
    Y = Y.reshape(-1, Y.shape[-1])[:, a.base.independent]
    tau = np.asarray(train.tau, dtype=float).reshape(-1)
    for blocks in (8, 16, 32):
        bm = _batch_means(Y, tau, robot.nv, blocks)
        n_blk = train.n_samples // blocks
        print(f"  batch means, {blocks:>2} blocks of {n_blk:>5} samples:         {bm:8.1f}")
    rate = 1.0 / float(np.median(np.diff(np.asarray(load_dataset(DATA).t, dtype=float))))
    print(f"  bandwidth, rate / (2 cut-off) = {rate:.0f} / (2 x 3 Hz):    {rate / 6.0:8.1f}")

    nom_m = nominal[: robot.n_rigid : 10]
    print("\nlink masses [kg] at the default prior weight")
    print(f"{'':<10} " + " ".join(f"{j[-6:]:>7}" for j in robot.joint_names) + "    total")
    print(f"{'nominal':<10} " + " ".join(f"{m:7.3f}" for m in nom_m) + f"  {nom_m.sum():7.2f}")
    for label in ("consistent sdp", "consistent logchol"):
        m = runs[label][0].standard.values[: robot.n_rigid : 10]
        print(f"{label[11:]:<10} " + " ".join(f"{x:7.3f}" for x in m) + f"  {m.sum():7.2f}")

    print(
        f"\nprior weight sweep (sdp; default {DEFAULT_PRIOR_WEIGHT:g}, in honest std, the fit "
        f"scaled by k = {st.fit_scale:.1f}): validation error, how far the prior moved the "
        "fit beyond feasibility [honest std], largest mass ratio to nominal, masses [kg]"
    )
    for weight in (1e-3 / st.fit_scale, 1e-2, 3e-2, DEFAULT_PRIOR_WEIGHT, 0.3, 1.0):
        res = identify(
            *args, validation=v, consistent=ConsistentOptions(enabled=True, prior_weight=weight)
        )
        masses = res.standard.values[: robot.n_rigid : 10]
        worst = float(np.max(np.maximum(masses / nom_m, nom_m / masses)))
        print(
            f"  weight {weight:<8.3g} validation {100 * res.relative_error.validation:.3f} %, "
            f"prior moved {res.standard.prior_shift_std:5.2f} std, "
            f"consistent {res.physically_consistent}, ratio {worst:6.1f}, masses "
            + " ".join(f"{m:7.3f}" for m in masses)
            + f"  total {masses.sum():.2f}"
        )
    print(f"  (weight {1e-3 / st.fit_scale:.3g} is the former default 1e-3 in OLS std)")
    print("\nsolve time [s] against the number of samples (simulated panda, 2 % noise)")
    from manip_id import analyze
    from manip_id.estimators import InformationAccumulator, solve_accumulator
    from manip_id.estimators.consistent import build_problem, solve_consistent

    sim_robot = load_robot("panda", friction="viscous,coulomb")
    base = analyze(sim_robot).base
    truth = sim_robot.nominal_parameters.copy()
    truth[sim_robot.n_rigid :] = 0.2
    rng = np.random.default_rng(0)
    for n in (1_000, 100_000):
        acc = InformationAccumulator(base.n_base, sim_robot.nv)
        t0 = time.perf_counter()
        for start in range(0, n, 5_000):
            q, dq, ddq = sim_robot.random_states(min(5_000, n - start), seed=start + 1)
            Y = regressor(sim_robot, q, dq, ddq)
            tau = Y @ truth
            tau += 0.02 * tau.std(axis=0) * rng.standard_normal(tau.shape)
            acc.add(Y, tau, columns=base.independent)
        t_acc = time.perf_counter() - t0
        ls = solve_accumulator(acc)
        pr = build_problem(
            sim_robot, base, acc.A, acc.b, variance=ls.sigma2, zz=acc.zz, n_rows=acc.n_rows
        )
        times = {s: solve_consistent(sim_robot, pr, solver=s).time for s in ("sdp", "logchol")}
        print(
            f"  N = {n:>7}: accumulate {t_acc:6.2f}, sdp {times['sdp']:6.3f}, "
            f"logchol {times['logchol']:6.3f}"
        )


if __name__ == "__main__":
    main()
