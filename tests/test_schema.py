"""One result schema: to_dict is the CLI's --json and result.json; load_result reads it back.

The nominal model's errors are checked against torques computed here with Pinocchio's
rnea (the URDF inertias) and numpy friction, the flags against the known non-physical
OLS estimate of the real Panda log (panda_joint6.fv and panda_joint7.Izz negative).
"""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id.cli import main
from manip_id.errors import DataError
from manip_id.identification import (
    identify,
    load_result,
    result_from_dict,
    result_text,
)
from manip_id.identification.document import NON_PHYSICAL, POORLY, single_standard

PANDA_ARGS = ["identify", "panda", "--friction", "viscous,coulomb,offset", "--split", "0.7"]


def _data(robot, seed: int, n: int = 800):
    """Noisy torques of drawn parameters at random states (numpy and Pinocchio only)."""
    rng = np.random.default_rng(seed)
    q, dq, ddq = robot.random_states(n, seed=seed)
    theta = robot.nominal_parameters * (1.0 + 0.2 * rng.standard_normal(robot.n_parameters))
    model = robot.with_parameters(theta)
    data = model.createData()
    tau = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(n)])
    tau += 0.01 * tau.std(axis=0) * rng.standard_normal(tau.shape)
    return q, dq, ddq, tau


@pytest.fixture(scope="module")
def ur5_result():
    robot = get_robot("ur5")
    train, valid = _data(robot, 1), _data(robot, 2, n=300)
    return robot, train, valid, identify(robot, tuple(train), validation=valid)


def _nominal_error(robot, q, dq, ddq, tau) -> tuple[float, np.ndarray]:
    """||tau - tau_nominal|| / ||tau|| with the URDF model's rnea (armature as modelled)."""
    model = robot.model.copy()
    if not robot.terms.armature:
        model.armature = np.zeros(robot.nv)  # the regressor's model has no rotor inertia
    data = model.createData()
    tau_nom = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(len(q))])
    per_joint = np.linalg.norm(tau - tau_nom, axis=0) / np.linalg.norm(tau, axis=0)
    return float(np.linalg.norm(tau - tau_nom) / np.linalg.norm(tau)), per_joint


def test_schema_keys_and_names(ur5_result):
    robot, _, _, res = ur5_result
    d = json.loads(json.dumps(res.to_dict()))
    assert d["robot"] == robot.name and d["n_base"] == len(d["base_parameters"])
    assert d["joints"] == list(robot.dof_names)
    row = d["base_parameters"][0]
    assert set(row) == {
        "name",
        "expression",
        "value",
        "std",
        "std_percent",
        "std_white",
        "unit",
        "nominal",
        "flags",
    }
    # 800 independent samples: 25 blocks of 32, the autocorrelation-consistent std
    assert d["uncertainty"]["method"] == "hac" and d["uncertainty"]["n_blocks"] == 25
    assert set(d["uncertainty"]) == {
        "method",
        "requested",
        "bandwidth",
        "inflation",
        "n_blocks",
        "block_samples",
        "reason",
    }
    for p, i in zip(d["base_parameters"], res.base.independent, strict=True):
        assert p["unit"] == robot.parameter_units[i]
    rel = d["relative_error"]
    for key in ("train", "validation", "nominal_train", "nominal_validation"):
        assert isinstance(rel[key], float)
    for key in ("train_per_joint", "per_joint_validation", "nominal_per_joint_validation"):
        assert len(rel[key]) == robot.nv
    # "unidentifiable": the structural directions, one per regrouped column;
    # "unexcited": what these (full-rank) data fail to excite: nothing
    assert len(d["unidentifiable"]) == robot.n_parameters - res.base.n_base
    assert d["unexcited"] == []
    assert isinstance(d["warnings"], list)
    assert d["thresholds"] == {
        "poorly_identified": 10.0,
        "condition_number": 100.0,
        "convergence": 0.01,
    }


def test_nominal_column_is_the_urdf_combination(ur5_result):
    robot, _, _, res = ur5_result
    d = res.to_dict()
    theta0 = robot.nominal_parameters
    for k, p in enumerate(d["base_parameters"]):
        i = res.base.independent[k]
        # theta_b = theta[i] + sum_j K[k, j] theta[dependent_j], written out here
        want = theta0[i] + sum(
            res.base.K[k, j] * theta0[dj] for j, dj in enumerate(res.base.dependent)
        )
        assert p["nominal"] == pytest.approx(want, rel=1e-12, abs=1e-14)


def test_nominal_errors_against_rnea(ur5_result):
    robot, train, valid, res = ur5_result
    err, per = _nominal_error(robot, *train)
    verr, vper = _nominal_error(robot, *valid)
    re = res.relative_error
    # training: from the sums (zz - 2 b.theta + theta.A.theta); validation: streamed
    assert re.nominal_train == pytest.approx(err, rel=1e-6)
    np.testing.assert_allclose(re.nominal_train_per_joint, per, rtol=1e-6)
    assert re.nominal_validation == pytest.approx(verr, rel=1e-9)
    np.testing.assert_allclose(re.nominal_validation_per_joint, vper, rtol=1e-9)
    assert re.validation < 0.05 < re.nominal_validation  # the 20 % perturbed truth


def test_round_trip(ur5_result, tmp_path):
    robot, train, _, res = ur5_result
    first = json.loads(json.dumps(res.to_dict()))
    path = tmp_path / "r.json"
    path.write_text(json.dumps(first))
    back = load_result(path)
    assert json.loads(json.dumps(back.to_dict())) == first
    np.testing.assert_array_equal(back.estimate, res.estimate)
    np.testing.assert_allclose(back.covariance, res.covariance)
    # the loaded result predicts as the original (its base regrouping came back)
    q, dq, ddq, _ = train
    np.testing.assert_allclose(
        back.predict(robot, q[:20], dq[:20], ddq[:20]),
        res.predict(robot, q[:20], dq[:20], ddq[:20]),
    )


def test_load_result_refuses_foreign_json(tmp_path):
    path = tmp_path / "x.json"
    path.write_text('{"robot": "ur5"}')
    with pytest.raises(DataError, match="missing"):
        load_result(path)
    with pytest.raises(DataError, match="no such result file"):
        load_result(tmp_path / "none.json")
    with pytest.raises(DataError):
        result_from_dict([1, 2])


def test_thresholds_are_configurable(ur5_result):
    _, _, _, res = ur5_result
    d = res.to_dict()
    sp = np.array(
        [np.inf if p["std_percent"] is None else p["std_percent"] for p in d["base_parameters"]]
    )
    limit = float(np.median(sp))
    d2 = res.to_dict(poorly_identified=limit, condition_limit=0.5 * res.condition_number)
    poor = [POORLY in p["flags"] for p in d2["base_parameters"]]
    assert poor == list(~(sp <= limit))
    assert any("condition number" in w for w in d2["warnings"])
    assert not any(
        "condition number" in w
        for w in res.to_dict(condition_limit=2 * res.condition_number)["warnings"]
    )


def test_gradient_not_converged_is_a_warning():
    robot = get_robot("ur5")
    train = _data(robot, 3, n=400)
    res = identify(robot, tuple(train), method="gradient", online={"gamma": 1e-3})
    assert res.history is not None and res.convergence is not None
    d = res.to_dict()
    assert any("has not converged" in w for w in d["warnings"])
    # the check itself: the torque change over the last 10 % of the samples, from Y_b
    ind = res.base.independent
    k0 = d["convergence"]["from_sample"]  # one record per sample here (400 < 1000)
    q, dq, ddq, tau = train
    Y = np.stack([robot.evaluator.regressor(q[i], dq[i], ddq[i]) for i in range(len(q))])
    change = np.linalg.norm(Y[:, :, ind] @ (res.estimate - res.history.theta[k0]))
    change /= np.linalg.norm(tau)
    assert d["convergence"]["prediction_change"] == pytest.approx(change, rel=1e-6)


def test_rls_on_noise_free_data_converges():
    robot = get_robot("double_pendulum")
    q, dq, ddq = robot.random_states(600, seed=5)
    theta = robot.nominal_parameters
    model = robot.with_parameters(theta)
    data = model.createData()
    tau = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(600)])
    res = identify(robot, (q, dq, ddq, tau), method="rls")
    assert res.convergence["prediction_change"] < 1e-6
    assert not any("converged" in w for w in res.to_dict()["warnings"])


def test_periodic_split_warns_that_validation_repeats_training(tmp_path, capsys):
    out = tmp_path / "sim.json"
    args = ["identify", "double_pendulum", "--simulate", "--duration", "20", "--split"]
    assert main([*args, "0.7", "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    assert d["source"]["simulated"]["period"] == pytest.approx(10.0)
    assert any("repeat the training motion" in w for w in d["warnings"])
    assert main([*args, "0.4", "--json", str(out), "--force"]) == 0  # 8 s < one period
    assert not any("repeat" in w for w in json.loads(out.read_text())["warnings"])
    capsys.readouterr()


def test_real_panda_ols_flags_and_show(panda_log, tmp_path, capsys):
    out = tmp_path / "panda.json"
    assert main([*PANDA_ARGS, "--data", str(panda_log), "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    rows = {p["name"]: p for p in d["base_parameters"]}
    for name in ("panda_joint6.fv", "panda_joint7.Izz"):
        assert rows[name]["value"] < 0 and rows[name]["expression"] == name
        assert NON_PHYSICAL in rows[name]["flags"]
    flagged = {n for n, p in rows.items() if NON_PHYSICAL in p["flags"]}
    assert flagged == {"panda_joint6.fv", "panda_joint7.Izz"}
    # every other lone standard parameter that must be positive came out positive
    res = load_result(out)
    for k, n in enumerate(res.names):
        one = single_standard(res.base, k)
        if one and one.rpartition(".")[2] in ("m", "Izz", "Ixx", "Iyy", "fv", "fc", "Ia"):
            assert (res.estimate[k] < 0) == (n in flagged)
    assert any("panda_joint7.Izz" in w and "non-physical" in w for w in d["warnings"])
    assert any("filtered at 3 Hz" in w for w in d["warnings"])
    assert d["reference_torques"].startswith("filtered at 3 Hz")
    # the nominal URDF is far worse than the fit (18 % against 0.74 % on validation)
    rel = d["relative_error"]
    assert rel["validation"] < 0.01 < 0.1 < rel["nominal_validation"]
    capsys.readouterr()
    assert main(["show", str(out)]) == 0
    shown = capsys.readouterr().out
    assert "panda_joint7.Izz" in shown and "non-physical" in shown
    assert "nominal model" in shown and result_text(d) in shown


def test_filtered_reference_torques_are_stated_with_the_raw_errors(tmp_path, capsys):
    """--cutoff filters the simulated torques; the raw (noise-free, exact) torques are
    reproduced by the true model, so its error against them vanishes: the raw torques
    are aligned with the processed samples."""
    out = tmp_path / "f.json"
    argv = ["identify", "double_pendulum", "--simulate", "--noise", "0", "--cutoff", "40"]
    assert main([*argv, "--split", "0.5", "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    assert d["reference_torques"].startswith("filtered at 40 Hz")
    assert "against the raw torques" in d["reference_torques"]
    raw = d["relative_error_raw"]
    assert set(raw) == {"train", "validation", "nominal_train", "nominal_validation"}
    assert raw["nominal_train"] < 1e-4 and raw["nominal_validation"] < 1e-4  # the truth
    assert any("low-pass filtered at 40 Hz" in w for w in d["warnings"])
    capsys.readouterr()


def test_not_excited_flags_the_columns_these_data_leave_zero():
    """At standstill only gravity acts: the base columns that vanish on these states
    (computed here from the regressor) are the ones flagged "not excited by this data"."""
    robot = get_robot("double_pendulum")
    q, _, _ = robot.random_states(200, seed=4)
    dq = ddq = np.zeros((200, robot.nv))
    model = robot.with_parameters(robot.nominal_parameters)
    data = model.createData()
    tau = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(200)])
    res = identify(robot, (q, dq, ddq, tau), minimum_norm=True)
    assert res.rank_analysis.rank < res.base.n_base
    Y = np.stack([robot.evaluator.regressor(q[k], dq[k], ddq[k]) for k in range(200)])
    zero = np.abs(Y[:, :, res.base.independent]).max(axis=(0, 1)) == 0
    d = res.to_dict()
    flagged = np.array(["not excited by this data" in p["flags"] for p in d["base_parameters"]])
    assert zero.any() and np.all(flagged[zero])
    assert d["unexcited"] == list(res.rank_analysis.unidentifiable)
    assert len(d["unexcited"]) == res.base.n_base - res.rank_analysis.rank
