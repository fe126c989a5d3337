"""identify's back-ends (serial, forked, online) and the online options.

Independent references: the online estimate against the estimator stepped here over
rows of Pinocchio's regressor (computeJointTorqueRegressor through robot.evaluator);
the forked sums against the serial ones.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import get_robot

import manip_id.execution as execution
import manip_id.identification as identification
from manip_id.errors import InputError
from manip_id.estimators import GradientEstimator, RLSEstimator
from manip_id.identification import OnlineOptions, RunOptions, identify
from manip_id.simulation import inverse_dynamics


@pytest.fixture(scope="module")
def ur5_data():
    robot = get_robot("ur5", friction=("viscous",))
    q, dq, ddq = robot.random_states(400, seed=21)
    theta = robot.nominal_parameters.copy()
    theta[robot.n_rigid :] = 0.4
    tau = inverse_dynamics(robot, theta, q, dq, ddq)
    tau += 0.02 * np.random.default_rng(22).standard_normal(tau.shape)
    return robot, q, dq, ddq, tau


def _rows(robot, q, dq, ddq, ind):
    ev = robot.evaluator
    return [ev.regressor(q[k], dq[k], ddq[k])[:, ind] for k in range(q.shape[0])]


@pytest.mark.parametrize("as_dict", [True, False])
def test_rls_options_match_the_estimator_stepped_by_hand(ur5_data, as_dict):
    robot, q, dq, ddq, tau = ur5_data
    opts = {"P0": 1e3, "forgetting": 0.999, "record_every": 10, "dt": 0.01}
    res = identify(
        robot, (q, dq, ddq, tau), method="rls", online=opts if as_dict else OnlineOptions(**opts)
    )
    ind = res.base.independent
    est = RLSEstimator(np.zeros(len(ind)), 1e3, forgetting=0.999, record_every=10)
    for k, Yk in enumerate(_rows(robot, q, dq, ddq, ind)):
        est.step(Yk, tau[k], 0.01)
    np.testing.assert_allclose(res.estimate, est.theta, rtol=1e-9, atol=1e-12)
    assert res.history is not None and len(res.history.t) == len(est.history.t)


def test_gradient_defaults_are_the_normalized_law_with_unit_gain(ur5_data):
    robot, q, dq, ddq, tau = ur5_data
    res = identify(robot, (q, dq, ddq, tau), method="gradient")
    ind = res.base.independent
    est = GradientEstimator(np.zeros(len(ind)), 1.0, normalized=True)
    for k, Yk in enumerate(_rows(robot, q, dq, ddq, ind)):
        est.step(Yk, tau[k], 1.0)
    np.testing.assert_allclose(res.estimate, est.theta, rtol=1e-9, atol=1e-12)
    # default record: every max(1, N // 1000) = 1 sample
    assert res.history is not None and len(res.history.t) == q.shape[0] + 1


@pytest.mark.parametrize(
    ("method", "online", "match"),
    [
        ("rls", {"P_0": 1.0}, r"unknown online option\(s\) \['P_0'\]"),
        ("ols", {"gama": 1.0}, "unknown online option"),
        ("rls", {"gamma": 2.0}, r"\['gamma'\] do not apply to RLS"),
        ("gradient", OnlineOptions(forgetting=0.9), r"\['forgetting'\] do not apply to the grad"),
        ("rls", [("P0", 1.0)], "online must be OnlineOptions"),
    ],
)
def test_bad_online_options_are_input_errors(ur5_data, method, online, match):
    robot, q, dq, ddq, tau = ur5_data
    with pytest.raises(InputError, match=match):
        identify(robot, (q, dq, ddq, tau), method=method, online=online)


def test_forked_back_end_equals_serial_and_leaves_no_state(ur5_data):
    robot, q, dq, ddq, tau = ur5_data
    serial = identify(robot, (q, dq, ddq, tau))
    forked = identify(robot, (q, dq, ddq, tau), base=serial.base, run=RunOptions(workers=2))
    scale = np.abs(serial.estimate).max()
    assert np.abs(forked.estimate - serial.estimate).max() <= 1e-9 * scale
    assert "accumulate_wall" in forked.timings and "accumulate_wall" not in serial.timings
    assert execution._forked_job is None  # set in the workers only
    assert not hasattr(identification, "_WORK")
