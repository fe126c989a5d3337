"""The collision monitor: observer against the physics, detection, false alarms, bad input.

Simulated ur5 runs (:mod:`manip_id.simulation`, torques from ``pinocchio.rnea`` plus
friction) with a known external torque: the motors supply ``tau = ID(q, dq, ddq) - tau_ext``
for the same motion, so the observer's residual must follow ``tau_ext`` through its
filter, whose step response is known in closed form (independent of the observer's code).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import get_robot

from manip_id.datasets import Dataset
from manip_id.errors import DataError, InputError, ManipIdError, ModelMismatchError
from manip_id.identification import identify
from manip_id.monitor import (
    CollisionMonitor,
    MonitorModel,
    Thresholds,
    calibrate_thresholds,
    load_model,
    model_from_result,
)
from manip_id.simulation import simulate
from manip_id.trajectories import random_trajectory

FV = np.array([2.0, 2.0, 1.5, 0.5, 0.5, 0.5])  # [N m s/rad]
FC = np.array([3.0, 3.0, 2.0, 1.0, 1.0, 1.0])  # [N m]
NOISE = np.array([0.3, 0.5, 0.3, 0.05, 0.05, 0.05])  # torque noise std [N m]
NOISE_DQ = 1e-3  # velocity noise std [rad/s]


@pytest.fixture(scope="module")
def robot():
    return get_robot("ur5", friction=("viscous", "coulomb"))


@pytest.fixture(scope="module")
def theta(robot):
    th = robot.nominal_parameters.copy()
    th[robot.layout.joint_columns("fv")] = FV
    th[robot.layout.joint_columns("fc")] = FC
    return th


def _run(robot, theta, seed, *, duration=6.0, rate=1000.0, noise=False):
    """A simulated run; ``noise``: white torque noise of :data:`NOISE` (the same in every run,
    unlike ``simulate``'s, which is relative to each run's torque RMS) and velocity noise."""
    traj = random_trajectory(robot, seed=seed)
    ds = simulate(robot, traj, duration=duration, rate=rate, theta=theta).dataset
    if not noise:
        return ds
    rng = np.random.default_rng(1000 + seed)
    tau = ds.tau + NOISE * rng.standard_normal(ds.tau.shape)
    dq = ds.dq + NOISE_DQ * rng.standard_normal(ds.dq.shape)
    return Dataset(t=ds.t, q=ds.q, dq=dq, tau=tau, ddq=ds.ddq)


def _step(t, joint, start, stop, size, nv):
    ext = np.zeros((t.size, nv))
    ext[(t >= start) & (t < stop), joint] = size  # [N m]
    return ext


def _first_order(t, start, stop, size, K):
    """Exact response of dr/dt = K (tau_ext - r) to a pulse of tau_ext."""
    on = np.clip(t - start, 0.0, None)
    r = size * (1.0 - np.exp(-K * on))
    after = t >= stop
    r[after] = size * (1.0 - np.exp(-K * (stop - start))) * np.exp(-K * (t[after] - stop))
    return r


def test_momentum_and_input_against_crba_and_finite_differences(robot, theta):
    """p = crba(q) dq; C^T dq = 1/2 dq^T dM/dq_i dq by central differences of crba;
    g = rnea(q, 0, 0); friction written here: independent of the observer's calls."""
    import pinocchio as pin

    model = robot.with_parameters(theta)
    data = model.createData()
    rng = np.random.default_rng(7)
    mon = CollisionMonitor(robot, theta)

    def mass(q):
        M = pin.crba(model, data, q).copy()
        return np.triu(M) + np.triu(M, 1).T

    for _ in range(5):
        q, dq, _ = robot.random_states(1, seed=int(rng.integers(1000)))
        q, dq = q[0], dq[0]
        tau = rng.standard_normal(robot.nv)
        p, u = mon.momentum_and_input(q, dq, tau)
        np.testing.assert_allclose(p, mass(q) @ dq, rtol=1e-10, atol=1e-10)
        h = 1e-6
        ctdq = np.array(
            [
                0.5 * dq @ ((mass(q + h * e) - mass(q - h * e)) / (2 * h)) @ dq
                for e in np.eye(robot.nv)
            ]
        )
        g = pin.rnea(model, data, q, np.zeros(robot.nv), np.zeros(robot.nv))
        f = FV * dq + FC * np.sign(dq)
        np.testing.assert_allclose(u, tau + ctdq - g - f, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("rate, tol", [(1000.0, 0.02), (10000.0, 0.002)])
def test_first_order_residual_follows_the_external_torque(robot, theta, rate, tol):
    ds = _run(robot, theta, seed=3, duration=3.0, rate=rate)
    K, size = 40.0, 5.0
    ext = _step(ds.t, 2, 1.0, 1.6, size, robot.nv)
    mon = CollisionMonitor(robot, theta, gain=K, filter_gain=None)
    run = mon.run(ds.t, ds.q, ds.dq, ds.tau - ext)
    expected = _first_order(ds.t, 1.0, 1.6, size, K)
    # the discrete form holds tau_ext constant over a step: the switching samples differ by
    # one step, so compare away from them; the error is the discretization's, O(dt)
    away = (np.abs(ds.t - 1.0) > 2.0 / rate) & (np.abs(ds.t - 1.6) > 2.0 / rate)
    err = np.abs(run.residual[away, 2] - expected[away])
    assert err.max() <= tol * size, err.max()
    others = np.delete(run.residual, 2, axis=1)
    assert np.abs(others).max() <= tol * size


def test_second_low_pass_has_the_double_pole_response(robot, theta):
    ds = _run(robot, theta, seed=4, duration=2.0, rate=5000.0)
    K, size = 30.0, -4.0
    ext = _step(ds.t, 4, 0.5, 2.5, size, robot.nv)
    run = CollisionMonitor(robot, theta, gain=K, filter_gain=K).run(ds.t, ds.q, ds.dq, ds.tau - ext)
    s = np.clip(ds.t - 0.5, 0.0, None)
    expected = size * (1.0 - np.exp(-K * s) * (1.0 + K * s))  # K^2 / (s + K)^2, step
    assert np.abs(run.residual[:, 4] - expected).max() <= 0.01 * abs(size)


def test_discrete_form_converges_to_the_fine_step_integration(robot, theta):
    """The same motion sampled at 250 Hz and at 20 kHz: residuals agree to O(dt)."""
    K = 25.0
    fine = _run(robot, theta, seed=5, duration=2.0, rate=20000.0)
    coarse = _run(robot, theta, seed=5, duration=2.0, rate=250.0)
    size = 3.0
    rf = CollisionMonitor(robot, theta, gain=K, filter_gain=None).run(
        fine.t, fine.q, fine.dq, fine.tau - _step(fine.t, 1, 0.7, 5.0, size, robot.nv)
    )
    rc = CollisionMonitor(robot, theta, gain=K, filter_gain=None).run(
        coarse.t, coarse.q, coarse.dq, coarse.tau - _step(coarse.t, 1, 0.7, 5.0, size, robot.nv)
    )
    idx = np.searchsorted(fine.t, coarse.t - 1e-9)
    diff = np.abs(rc.residual - rf.residual[idx])
    assert diff.max() <= 0.05 * size, diff.max()  # dt = 4 ms, K dt = 0.1
    assert diff[coarse.t > 1.0].max() <= 0.01 * size  # after the switch, round-off of the rule


def test_euler_unstable_gain_stays_stable(robot, theta):
    """K dt = 5: the exact discretization stays bounded and still estimates the torque."""
    ds = _run(robot, theta, seed=6, duration=2.0, rate=100.0)
    ext = _step(ds.t, 0, 0.5, 2.5, 2.0, robot.nv)
    run = CollisionMonitor(robot, theta, gain=500.0, filter_gain=None).run(
        ds.t, ds.q, ds.dq, ds.tau - ext
    )
    assert np.all(np.isfinite(run.residual))
    late = ds.t > 0.6
    assert np.abs(run.residual[late, 0] - 2.0).max() <= 0.2  # trapezoid error at 100 Hz


@pytest.fixture(scope="module")
def identified(robot, theta):
    """An identification (the default, WLS) from two noisy collision-free runs, and two
    other collision-free runs to calibrate on: bounds from the fit's own runs are in-sample,
    too tight on new runs (1.9 % false alarms for the asked 1 % with this WLS fit)."""
    runs = [_run(robot, theta, seed=s, duration=8.0, rate=500.0, noise=True) for s in (11, 12)]
    q = np.vstack([d.q for d in runs])
    dq = np.vstack([d.dq for d in runs])
    ddq = np.vstack([d.ddq for d in runs])
    tau = np.vstack([d.tau for d in runs])
    calib = [_run(robot, theta, seed=s, duration=8.0, rate=500.0, noise=True) for s in (13, 14)]
    return identify(robot, (q, dq, ddq, tau)), calib


def test_false_alarm_rate_on_new_collision_free_runs(robot, theta, identified):
    result, calib = identified
    alpha = 0.01
    th = calibrate_thresholds(robot, result, calib, false_alarm=alpha)
    assert th.rate <= alpha and th.n_samples == sum(d.t.size for d in calib)
    assert np.all(th.model_bound > 0)  # the result's covariance adds its part
    assert th.covariance_kind == "honest (hac std, white-noise correlations)"
    mon = CollisionMonitor(robot, result_model(robot, result), th)
    n = alarms = 0
    for seed in range(20, 26):  # 6 new runs, 6 x 4001 samples
        ds = _run(robot, theta, seed=seed, duration=8.0, rate=500.0, noise=True)
        run = mon.run(ds.t, ds.q, ds.dq, ds.tau)
        n += ds.t.size
        alarms += int(run.detected.any(axis=1).sum())
    assert n >= 20000
    assert alarms / n <= alpha, alarms / n


def test_thresholds_round_trip_through_json(robot, identified):
    result, calib = identified
    th = calibrate_thresholds(robot, result, calib[:1], gain=30.0, filter_gain=None)
    back = Thresholds.from_dict(json.loads(json.dumps(th.to_dict())))
    np.testing.assert_array_equal(back.bound, th.bound)
    np.testing.assert_array_equal(back.gain, th.gain)
    assert back.filter_gain is None and back.dof_names == th.dof_names
    assert back.rate == th.rate and back.methods == th.methods
    with pytest.raises(DataError, match="not monitor thresholds"):
        Thresholds.from_dict({"joints": [{"name": "x"}]})


def result_model(robot, result) -> MonitorModel:
    return model_from_result(robot, result)


def test_detects_each_interval_and_estimates_the_torque(robot, theta, identified):
    result, calib = identified
    th = calibrate_thresholds(robot, result, calib, false_alarm=1e-3)
    mon = CollisionMonitor(robot, model_from_result(robot, result), th)
    ds = _run(robot, theta, seed=30, duration=8.0, rate=500.0, noise=True)
    events = [(0, 1.0, 1.5, 8.0), (3, 3.0, 3.4, -3.0), (1, 5.0, 6.0, 10.0)]
    ext = sum(_step(ds.t, j, a, b, s, robot.nv) for j, a, b, s in events)
    run = mon.run(ds.t, ds.q, ds.dq, ds.tau - ext)
    dets = run.detections()
    assert len(dets) == len(events), [d.to_dict() for d in dets]
    for det, (j, a, b, s) in zip(dets, events, strict=True):
        name = robot.dof_names[j]
        assert name in det.joints
        assert a <= det.start <= a + 0.15  # stated delay: 150 ms (K = K2 = 25 /s)
        assert b <= det.stop <= b + 0.3
        k = np.searchsorted(ds.t, b) - 1  # end of the interval: the filter has settled
        assert abs(run.residual[k, j] - s) <= 0.1 * abs(s) + th.bound[j]


def test_bad_input_is_a_clear_error(robot, theta, identified, tmp_path):
    result, calib = identified
    panda = get_robot("panda", friction=("viscous", "coulomb"))
    with pytest.raises(ModelMismatchError, match="ur5"):
        model_from_result(panda, result)
    ur10 = get_robot("ur10", friction=("viscous", "coulomb"))
    with pytest.raises(ModelMismatchError, match="ur5"):
        model_from_result(ur10, result)
    plain = get_robot("ur5")
    with pytest.raises(ModelMismatchError):
        model_from_result(plain, result)  # other joint terms
    with pytest.raises(ModelMismatchError):
        CollisionMonitor(panda, theta)
    th = calibrate_thresholds(robot, theta, calib[:1])
    with pytest.raises(ModelMismatchError, match="joints"):
        CollisionMonitor(panda, panda.nominal_parameters, th)
    with pytest.raises(ModelMismatchError):
        CollisionMonitor(robot, theta, np.ones(4))
    with pytest.raises(InputError, match="calibrated with gain"):
        CollisionMonitor(robot, theta, th, gain=10.0)
    with pytest.raises(InputError, match="calibrated with gain"):
        CollisionMonitor(robot, theta, th, filter_gain=None)
    with pytest.raises(InputError):
        CollisionMonitor(robot, theta, -1.0)
    with pytest.raises(InputError):
        calibrate_thresholds(robot, theta, calib[:1], false_alarm=1.5)
    bad = tmp_path / "not_a_result.json"
    bad.write_text(json.dumps({"robot": "ur5", "hello": 1}))
    with pytest.raises(DataError, match="not an identification result"):
        load_model(robot, bad)
    with pytest.raises(DataError):
        load_model(robot, tmp_path / "missing.json")
    mon = CollisionMonitor(robot, theta)
    with pytest.raises(InputError):
        mon.step(np.zeros(3), np.zeros(6), np.zeros(6), 1e-3)
    with pytest.raises(InputError, match="increase"):
        d = calib[0]
        mon.run(d.t[::-1], d.q, d.dq, d.tau)
    assert issubclass(ModelMismatchError, ManipIdError)


def test_saved_result_gives_the_same_model(robot, identified, tmp_path):
    result, _ = identified
    path = tmp_path / "res.json"
    path.write_text(json.dumps(result.to_dict()))
    a = load_model(robot, path)
    b = model_from_result(robot, result)
    np.testing.assert_allclose(a.theta, b.theta, rtol=1e-12, atol=1e-12)
    # the standard vector has exactly the identified base parameters
    np.testing.assert_allclose(result.base.to_base(a.theta), result.estimate, atol=1e-9)
