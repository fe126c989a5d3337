"""Chunked and parallel identification give the serial result (to round-off)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import get_robot

from manip_id import InputError
from manip_id.identification import RunOptions, identify
from manip_id.simulation import inverse_dynamics


@pytest.fixture(scope="module")
def ur10_data():
    robot = get_robot("ur10", friction=("viscous", "coulomb"))
    q, dq, ddq = robot.random_states(3000, seed=11)
    theta = robot.nominal_parameters.copy()
    theta[robot.n_rigid :] = np.linspace(0.2, 1.0, robot.n_parameters - robot.n_rigid)
    tau = inverse_dynamics(robot, theta, q, dq, ddq)
    tau += 0.05 * np.random.default_rng(3).standard_normal(tau.shape)
    return robot, q, dq, ddq, tau


def _close(a, b, rtol=1e-9):
    scale = np.abs(a).max()
    assert np.abs(a - b).max() <= rtol * scale, np.abs(a - b).max() / scale


@pytest.fixture(scope="module")
def serial(ur10_data):
    robot, q, dq, ddq, tau = ur10_data
    return identify(robot, (q, dq, ddq, tau), run=RunOptions(chunk=1024))


@pytest.mark.parametrize("chunk", [1, 7, 500, 5000])
def test_chunk_size_does_not_change_the_result(ur10_data, serial, chunk):
    robot, q, dq, ddq, tau = ur10_data
    res = identify(robot, (q, dq, ddq, tau), base=serial.base, run=RunOptions(chunk=chunk))
    _close(serial.estimate, res.estimate)
    _close(serial.std, res.std)
    assert res.relative_error.train == pytest.approx(serial.relative_error.train, rel=1e-9)


@pytest.mark.parametrize("method", ["ols", "wls"])
@pytest.mark.parametrize("workers", [2, 3])
def test_workers_give_the_serial_result(ur10_data, method, workers):
    robot, q, dq, ddq, tau = ur10_data
    ref = identify(robot, (q, dq, ddq, tau), method=method)
    res = identify(
        robot, (q, dq, ddq, tau), method=method, base=ref.base, run=RunOptions(workers=workers)
    )
    _close(ref.estimate, res.estimate)
    # WLS weights come from residual sums (see below), which carry more round-off
    _close(ref.std, res.std, rtol=1e-8 if method == "wls" else 1e-9)
    # the training error comes from the sums (zz - 2 b.theta + theta.A.theta), a difference
    # of large numbers: it carries about 1e-8 of the torque energy as round-off
    np.testing.assert_allclose(
        res.relative_error.train_per_joint, ref.relative_error.train_per_joint, rtol=1e-6
    )


def _blocks(arrays, edges):
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        yield tuple(x[a:b] for x in arrays)


def test_blocks_from_a_stream_and_parts_in_processes(ur10_data, serial):
    robot, q, dq, ddq, tau = ur10_data
    arrays = (q, dq, ddq, tau)
    res = identify(
        robot,
        _blocks(arrays, [0, 100, 101, 1700, 3000]),
        base=serial.base,
        validation=_blocks(arrays, [0, 3000]),
        run=RunOptions(chunk=256),
    )
    _close(serial.estimate, res.estimate)
    assert res.n_samples == 3000
    # validation on the training data equals the training error computed from the sums
    assert res.relative_error.validation == pytest.approx(res.relative_error.train, rel=1e-6)
    parts = [(_blocks, (arrays, [0, 1000, 1500])), (_blocks, (arrays, [1500, 3000]))]
    par = identify(robot, parts, base=serial.base, run=RunOptions(workers=2))
    _close(serial.estimate, par.estimate)


def test_bad_sources(ur10_data):
    robot, q, dq, ddq, tau = ur10_data
    with pytest.raises(InputError, match="parts"):
        identify(robot, [(q, dq, ddq, tau)], run=RunOptions(workers=2))
    with pytest.raises(InputError, match="list of ndarray"):
        identify(robot, [q])
    with pytest.raises(InputError, match="workers"):
        identify(robot, (q, dq, ddq, tau), run=RunOptions(workers=0))
    with pytest.raises(InputError, match="ols, wls"):
        identify(robot, [(q, dq, ddq, tau)], method="rls")


@pytest.mark.parametrize("name", ["ur10", "baxter", "kinova", "msd"])
def test_row_supports_give_the_full_information_sums(name):
    """Accumulating each row on its non-zero columns equals the dense per-joint sums."""
    from manip_id.estimators import InformationAccumulator
    from manip_id.identification import accumulate_blocks, row_supports
    from manip_id.robot.regressor import regressor

    robot = get_robot(name, friction=("viscous", "coulomb"))
    q, dq, ddq = robot.random_states(300, seed=5)
    tau = np.random.default_rng(1).normal(size=(300, robot.nv))
    ind = np.arange(0, robot.n_parameters, 2)  # any sorted column subset
    supports = row_supports(robot, ind)
    Y = regressor(robot, q, dq, ddq)[:, :, ind]
    for j, sj in enumerate(supports):  # the dropped entries are exact zeros
        mask = np.ones(ind.size, bool)
        mask[sj] = False
        assert not np.any(Y[:, j, mask])
    dense = InformationAccumulator(ind.size, robot.nv).add(Y, tau)
    sparse, _ = accumulate_blocks(robot, [(q, dq, ddq, tau)], ind, chunk=64)
    np.testing.assert_allclose(sparse.A_joint, dense.A_joint, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sparse.b_joint, dense.b_joint, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sparse.zz_joint, dense.zz_joint, rtol=1e-12)
    assert sparse.n == dense.n == 300
