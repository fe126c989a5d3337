"""The block-wise simulation (SimulationStream) and the CLI's streamed --simulate path."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest

from manip_id import identify, load_robot, regressor
from manip_id import simulation as sim_mod
from manip_id.cli import main
from manip_id.errors import DataWarning, InputError
from manip_id.identification import RunOptions
from manip_id.simulation import MeasurementNoise, SimulationStream, simulate
from manip_id.trajectories import random_trajectory


@pytest.fixture(scope="module")
def ur10():
    return load_robot("ur10", friction="viscous,coulomb")


def _stream(robot, **kw):
    traj = random_trajectory(robot, harmonics=5, seed=4)
    opts = dict(duration=2.0, rate=50.0, noise=MeasurementNoise(0.02, 1e-3, 1e-2), seed=9)
    opts.update(kw)
    return SimulationStream(robot, traj, **opts)


def test_any_range_regenerates_the_same_samples(ur10, monkeypatch):
    monkeypatch.setattr(sim_mod, "NOISE_BLOCK", 7)  # many blocks in a short record
    stream = _stream(ur10)
    whole = stream.dataset()
    assert whole.n_samples == stream.n_samples == 101
    for start, stop in [(0, 101), (3, 40), (6, 8), (7, 14), (50, 101), (100, 101), (20, 20)]:
        got = list(stream.measurements(start, stop))
        assert all(b[0].shape[0] <= 7 for b in got)
        if stop == start:
            assert got == []
            continue
        for i, name in enumerate(("t", "q", "dq", "ddq", "tau")):
            part = np.concatenate([b[i] for b in got])
            # equal up to the rounding of the trajectory's matrix products (BLAS, block size)
            ref = getattr(whole, name)[start:stop]
            np.testing.assert_allclose(part, ref, rtol=1e-13, atol=1e-13, err_msg=name)
    # a part seen alone (as a worker process would) equals the same rows of the whole
    (func, args), *_ = stream.parts(3, 10, 90)
    q, dq, ddq, tau = (np.concatenate(x) for x in zip(*func(*args), strict=True))
    np.testing.assert_allclose(tau, whole.tau[args[0] : args[1]], rtol=1e-13, atol=1e-12)
    with pytest.raises(InputError, match="sample range"):
        list(stream.blocks(5, 200))


def test_simulate_is_the_materialized_stream(ur10):
    traj = random_trajectory(ur10, harmonics=5, seed=4)
    kw = dict(duration=3.0, rate=40.0, noise=MeasurementNoise(0.05, 1e-3, 1e-2), seed=2)
    a = simulate(ur10, traj, **kw)
    b = SimulationStream(ur10, traj, **kw)
    np.testing.assert_array_equal(a.theta_true, b.theta_true)
    np.testing.assert_array_equal(a.tau_true, b.tau_true)
    for name in ("t", "q", "dq", "ddq", "tau"):
        np.testing.assert_array_equal(getattr(a.dataset, name), getattr(b.dataset(), name))


def test_noise_free_torques_are_the_dynamics(ur10, monkeypatch):
    monkeypatch.setattr(sim_mod, "NOISE_BLOCK", 16)
    stream = _stream(ur10, noise=MeasurementNoise(), perturb=0.2)
    (t, q, dq, ddq, tau), *_ = stream.measurements(16, 40)
    # Pinocchio's rnea on the true rigid bodies, plus friction written here
    model = ur10.with_parameters(stream.theta_true)
    data = model.createData()
    names = ur10.parameter_names
    fv = np.array([stream.theta_true[names.index(f"{j}.fv")] for j in ur10.joint_names])
    fc = np.array([stream.theta_true[names.index(f"{j}.fc")] for j in ur10.joint_names])
    expected = np.stack([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(q.shape[0])]) + (
        fv * dq + fc * np.sign(dq)
    )
    np.testing.assert_allclose(tau, expected, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(
        np.einsum("nvp,p->nv", regressor(ur10, q, dq, ddq), stream.theta_true),
        tau,
        rtol=1e-10,
        atol=1e-8,
    )
    np.testing.assert_allclose(t, np.arange(16, 32) / 50.0, rtol=0, atol=0)  # one block


def test_torque_noise_scale_and_independence(ur10, monkeypatch):
    monkeypatch.setattr(sim_mod, "NOISE_BLOCK", 500)
    traj = random_trajectory(ur10, harmonics=5, seed=1)
    stream = SimulationStream(
        ur10, traj, duration=40.0, rate=100.0, noise=MeasurementNoise(tau=0.1), seed=3
    )
    ds = stream.dataset()
    e = (ds.tau - stream.tau_true) / (0.1 * np.sqrt(np.mean(stream.tau_true**2, axis=0)))
    assert e.shape == (4001, 6)
    np.testing.assert_allclose(e.std(axis=0), 1.0, atol=0.05)
    np.testing.assert_allclose(e.mean(axis=0), 0.0, atol=0.05)
    # blocks draw from different generators: neighbouring blocks are uncorrelated
    c = np.corrcoef(e[:500].ravel(), e[500:1000].ravel())[0, 1]
    assert abs(c) < 0.05


def test_streamed_least_squares_equal_whole_arrays(ur10):
    stream = _stream(ur10, duration=20.0, rate=50.0)
    ds = stream.dataset()
    whole = identify(ur10, (ds.q, ds.dq, ds.ddq, ds.tau), method="ols")
    blocks = identify(ur10, stream.blocks(), method="ols", run=RunOptions(chunk=100))
    np.testing.assert_allclose(blocks.estimate, whole.estimate, rtol=1e-9, atol=1e-12)
    parallel = identify(ur10, stream.parts(2), method="ols", run=RunOptions(chunk=100, workers=2))
    np.testing.assert_allclose(parallel.estimate, whole.estimate, rtol=1e-9, atol=1e-12)


def test_noise_free_stream_recovers_the_truth(ur10):
    stream = _stream(ur10, duration=20.0, noise=MeasurementNoise(), perturb=0.3)
    res = identify(ur10, stream.blocks(), method="ols")
    beta = res.base.to_base(stream.theta_true)
    np.testing.assert_allclose(res.estimate, beta, rtol=1e-7, atol=1e-9)


@pytest.mark.parametrize("method", ["ols", "wls"])
def test_cli_streamed_simulation_equals_whole_array_identification(ur10, tmp_path, method):
    out = tmp_path / "r.json"
    argv = ["identify", "ur10", "--simulate", "--friction", "viscous,coulomb", "--duration", "30"]
    argv += ["--rate", "40", "--seed", "5", "--split", "0.7", "--method", method]
    assert main([*argv, "--json", str(out)]) == 0
    got = json.loads(out.read_text())
    # the same record, made whole with the API, split as Dataset.split does
    traj = random_trajectory(ur10, harmonics=5, seed=5)
    data = simulate(
        ur10, traj, duration=30.0, rate=40.0, noise=MeasurementNoise(tau=0.01), seed=5
    ).dataset
    with pytest.warns(DataWarning, match="repeats the training motion"):  # as the CLI says
        train, valid = data.split(0.7)
    assert any("repeat the training motion" in w for w in got["warnings"])
    ref = identify(
        ur10,
        (train.q, train.dq, train.ddq, train.tau),
        method=method,
        validation=(valid.q, valid.dq, valid.ddq, valid.tau),
    )
    assert got["n_samples"] == train.n_samples and got["n_validation_samples"] == valid.n_samples
    values = [p["value"] for p in got["base_parameters"]]
    np.testing.assert_allclose(values, ref.estimate, rtol=1e-8, atol=1e-10)
    assert got["relative_error"]["validation"] == pytest.approx(
        ref.relative_error.validation, rel=1e-8
    )


def test_cli_streamed_simulation_with_workers(tmp_path):
    outs = []
    for workers in ("1", "2"):
        out = tmp_path / f"w{workers}.json"
        argv = ["identify", "ur10", "--simulate", "--friction", "viscous", "--duration", "20"]
        argv += ["--rate", "40", "--split", "0.6", "--workers", workers, "--json", str(out)]
        assert main(argv) == 0
        outs.append(json.loads(out.read_text()))
    a, b = ([p["value"] for p in o["base_parameters"]] for o in outs)
    np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-12)
    assert outs[0]["n_samples"] == outs[1]["n_samples"] == 481
