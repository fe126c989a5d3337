"""Friction laws: columns against their formulas, recovery from simulated joints, selection.

Independent references: the torques of the simulated joints are Pinocchio's rnea plus
each law written out here in numpy (not through manip_id's columns); the sigmoid is
Gaz et al.'s form 1/(1 + exp(-a (dq + c))) - 1/(1 + exp(-a c)).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from manip_id import load_robot
from manip_id.errors import InputError
from manip_id.identification import RunOptions, identify
from manip_id.identification.selection import SelectionOptions, candidate_terms, select_model
from manip_id.robot.friction import FrictionShapes, parse_friction
from manip_id.robot.model import JointTerms
from manip_id.trajectories import random_trajectory

RATE = 200.0  # [Hz]
NOISE = 0.003  # torque noise, relative to each joint's RMS
VS = np.array([0.06, 0.15])  # true Stribeck velocities [rad/s]
SLOPE = np.array([30.0, 12.0])  # true sigmoid slopes [s/rad]


# ------------------------------------------------------------------ formulas
def _friction(law: str, q, dq, rigid) -> tuple[np.ndarray, dict]:
    """The true joint torque of one law [N m], (N, 2), and its coefficients by name
    (``rigid``: the rigid-body torque of the nominal model, the load of the load law)."""
    fv, fc, fo = np.array([0.3, 0.2]), np.array([0.8, 0.5]), np.array([0.1, -0.2])
    tau = fv * dq + fo
    coef = {"fv": fv, "fo": fo}
    if law == "linear":
        tau = tau + fc * np.sign(dq)
        coef["fc"] = fc
    elif law == "asymmetric":  # with offset: fc and fo carry the Coulomb pair
        fvp, fvn = np.array([0.4, 0.2]), np.array([0.25, 0.35])
        tau = fo + np.where(dq > 0, fvp * dq, fvn * dq) + fc * np.sign(dq)
        coef = {"fvp": fvp, "fvn": fvn, "fc": fc, "fo": fo}
    elif law == "stribeck":
        fs = np.array([1.4, 0.9])  # static friction [N m]
        tau = tau + (fc + (fs - fc) * np.exp(-((dq / VS) ** 2))) * np.sign(dq)
        coef.update(fc=fc, fs=fs - fc)
    elif law == "sigmoid":
        phi1 = np.array([1.5, 1.0])
        tau = tau + phi1 * (1 / (1 + np.exp(-SLOPE * dq)) - 0.5)
        coef["fsg"] = phi1
    elif law == "position":
        h1s, h1c, h2s = np.array([0.3, -0.2]), np.array([0.2, 0.25]), np.array([-0.15, 0.1])
        tau = tau + fc * np.sign(dq) + h1s * np.sin(q) + h1c * np.cos(q) + h2s * np.sin(2 * q)
        coef.update(fc=fc, h1s=h1s, h1c=h1c, h2s=h2s, h2c=np.zeros(2))
    elif law == "load":
        fl = np.array([0.08, 0.05])  # [1]: Coulomb friction of 8 and 5 % of the load
        tau = tau + fc * np.sign(dq) + fl * np.abs(rigid) * np.sign(dq)
        coef.update(fc=fc, fl=fl)
    return tau, coef


@pytest.fixture(scope="module")
def robot():
    return load_robot("double_pendulum", friction=())


def _data(robot, law: str, seed: int, duration: float = 40.0):
    traj = random_trajectory(robot, harmonics=5, wf=0.3, seed=seed)
    t = np.arange(int(duration * RATE)) / RATE
    q, dq, ddq = traj.sample(t)
    m, d = robot.model, robot.model.createData()
    tau = np.array([pin.rnea(m, d, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
    fr, coef = _friction(law, q, dq, tau)
    tau = tau + fr
    rng = np.random.default_rng(seed + 100)
    tau = tau + NOISE * np.sqrt(np.mean(tau**2, axis=0)) * rng.standard_normal(tau.shape)
    return (q, dq, ddq, tau), coef


def _fit(robot, train, valid):
    def fit(r):
        return identify(r, tuple(train), validation=valid)

    return fit


def _standard(result, robot_fit, name):
    """The identified coefficient of a joint term per joint, NaN where it is not a base
    parameter of its own (regrouped with a rigid-body one: cos(q_1) is the first body's
    gravity column of a double pendulum)."""
    out = []
    for dof in robot_fit.dof_names:
        full = f"{dof}.{name}"
        out.append(result.estimate[result.names.index(full)] if full in result.names else np.nan)
    return np.array(out)


def _check(got, true, atol):
    ok = np.isfinite(got)
    np.testing.assert_allclose(got[ok], true[ok], atol=atol)
    return int(ok.sum())


# ------------------------------------------------------------------ columns
def test_columns_are_the_formulas(robot):
    rng = np.random.default_rng(0)
    q = rng.uniform(-3, 3, (50, 2))
    dq = rng.uniform(-1, 1, (50, 2))
    shapes = FrictionShapes(stribeck_velocity=(0.1, 0.3), sigmoid_slope=(5.0, 40.0),
                            sigmoid_shift=(0.02, -0.01))  # fmt: skip
    r = robot.with_terms(
        JointTerms(asymmetric=True, stribeck=True, sigmoid=True, harmonics=2, shapes=shapes)
    )
    vals = r.layout.joint_values(r.dofs.angles(q), dq, np.zeros_like(dq))
    col = {t: vals[..., i] for i, t in enumerate(r.terms.enabled)}
    vs, a, c = np.array([0.1, 0.3]), np.array([5.0, 40.0]), np.array([0.02, -0.01])
    np.testing.assert_allclose(col["fvp"], np.maximum(dq, 0))
    np.testing.assert_allclose(col["fvn"], np.minimum(dq, 0))
    np.testing.assert_allclose(col["fcp"], dq > 0)
    np.testing.assert_allclose(col["fcn"], -1.0 * (dq < 0))
    np.testing.assert_allclose(col["fs"], np.exp(-((dq / vs) ** 2)) * np.sign(dq))
    gaz = 1 / (1 + np.exp(-a * (dq + c))) - 1 / (1 + np.exp(-a * c))
    np.testing.assert_allclose(col["fsg"], gaz, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(col["h2c"], np.cos(2 * q))
    np.testing.assert_allclose(col["h1s"], np.sin(q))


def test_parse_friction():
    spec = parse_friction("viscous,position:3")
    assert spec.kinds == {"viscous", "position"} and spec.harmonics == 3
    assert parse_friction(["position"]).harmonics == 2
    for bad, match in [
        ("position:9", "order 1..4"),
        ("viscous:2", "takes no order"),
        ("stiction", "unknown friction kind"),
    ]:
        with pytest.raises(InputError, match=match):
            parse_friction(bad)


# ----------------------------------------------------------------- recovery
@pytest.mark.parametrize("law", ["linear", "asymmetric", "position", "load"])
def test_linear_laws_recover_their_coefficients(robot, law):
    train, coef = _data(robot, law, seed=1)
    terms = candidate_terms(robot.terms, law, SelectionOptions())
    r = robot.with_terms(terms)
    res = identify(r, tuple(train))
    checked = 0
    for name, true in coef.items():
        # 0.3 % torque noise: within 2 % of the largest coefficient of the law
        checked += _check(_standard(res, r, name), true, 0.02 * np.abs(true).max() + 2e-3)
    assert checked >= 2 * len(coef) - 3  # all but the terms regrouped with gravity


@pytest.mark.parametrize(("law", "true_shape"), [("stribeck", VS), ("sigmoid", SLOPE)])
def test_nonlinear_laws_recover_shape_and_coefficients(robot, law, true_shape):
    train, coef = _data(robot, law, seed=1)
    valid, _ = _data(robot, law, seed=2, duration=20.0)
    opts = SelectionOptions(candidates=(law,), combine=False)
    res, sel = select_model(_fit(robot, train, valid), robot, opts)
    key = "vs" if law == "stribeck" else "slope"
    shape = np.array([j.candidates[0].parameters[key] for j in sel.joints])
    # grid factor 2-2.5, three rounds of bisection in log(shape): within 5 %
    np.testing.assert_allclose(shape, true_shape, rtol=0.05)
    if law == "sigmoid":  # the true shift c is 0: none of SIGMOID_SHIFTS beats it
        assert [j.candidates[0].parameters["shift"] for j in sel.joints] == [0.0, 0.0]
    r = robot.with_terms(sel.terms)
    for name, true in coef.items():
        assert _check(_standard(res, r, name), true, 0.02 * np.abs(true).max()) == 2
    assert res.relative_error.validation < 1.2 * NOISE  # the noise, little more


@pytest.mark.parametrize("law", ["asymmetric", "stribeck", "sigmoid", "position", "load"])
def test_selection_picks_the_true_law_on_training_data(robot, law):
    train, _ = _data(robot, law, seed=3)
    valid, _ = _data(robot, law, seed=4, duration=20.0)
    opts = SelectionOptions(
        combine=False, stribeck_grid=(0.03, 0.1, 0.3), sigmoid_grid=(8.0, 25.0, 80.0)
    )
    res, sel = select_model(_fit(robot, train, valid), robot, opts)
    assert sel.criterion == "BIC on the training data"
    assert [j.chosen for j in sel.joints] == [law, law]
    doc = res.to_dict()["friction_selection"]
    assert [d["chosen"] for d in doc] == [law, law]
    assert {c["model"] for c in doc[0]["candidates"]} == set(opts.candidates)
    assert res.context["joint_terms_per_joint"] == {
        name: list(keep) for name, keep in zip(robot.dof_names, sel.terms.per_dof, strict=True)
    }


def test_linear_truth_is_not_fitted_worse(robot):
    train, _ = _data(robot, "linear", seed=5)
    valid, _ = _data(robot, "linear", seed=6, duration=20.0)
    linear = robot.with_terms(candidate_terms(robot.terms, "linear", SelectionOptions()))
    before = identify(linear, tuple(train), validation=valid).relative_error.validation
    res, sel = select_model(_fit(robot, train, valid), robot, SelectionOptions(combine=False))
    # the laws that contain the linear one win on noise by a hair only: the BIC's
    # ln(n) per parameter keeps the simpler model, which predicts as well as before
    assert [j.chosen for j in sel.joints] == ["linear", "linear"]
    assert res.relative_error.validation <= before * (1 + 1e-9)
    for j in sel.joints:
        lin = next(c for c in j.candidates if c.model == "linear")
        assert lin.validation_error <= min(c.validation_error for c in j.candidates) * 1.02


def test_bic_without_validation_data(robot):
    train, _ = _data(robot, "stribeck", seed=7)
    opts = SelectionOptions(candidates=("linear", "stribeck"), combine=False)
    _, sel = select_model(lambda r: identify(r, tuple(train)), robot, opts)
    assert sel.criterion == "BIC on the training data"
    assert [j.chosen for j in sel.joints] == ["stribeck", "stribeck"]


# ------------------------------------------------------------------ back-ends
@pytest.mark.parametrize("law", ["asymmetric", "stribeck", "sigmoid", "position", "load"])
def test_streamed_and_forked_paths_agree(robot, law):
    from manip_id.identification import identify

    train, _ = _data(robot, law, seed=8, duration=10.0)
    shapes = FrictionShapes(stribeck_velocity=tuple(VS), sigmoid_slope=tuple(SLOPE))
    r = robot.with_terms(candidate_terms(robot.terms, law, SelectionOptions(), shapes))
    serial = identify(r, tuple(train))
    forked = identify(r, tuple(train), base=serial.base, run=RunOptions(workers=2))
    blocks = [tuple(a[k : k + 500] for a in train) for k in range(0, train[0].shape[0], 500)]
    streamed = identify(r, iter(blocks), base=serial.base)
    scale = np.abs(serial.estimate).max()
    for other in (forked, streamed):
        assert np.abs(other.estimate - serial.estimate).max() <= 1e-9 * scale


def _npz_block(path: str, start: int, stop: int):
    """A part of :func:`identify`: one block of an NPZ file (a Dask task)."""
    with np.load(path) as z:
        yield tuple(z[k][start:stop] for k in ("q", "dq", "ddq", "tau"))


@pytest.mark.slow
def test_dask_path_agrees_for_every_new_term(robot, tmp_path):
    pytest.importorskip("distributed")
    from distributed import Client, LocalCluster

    from manip_id.identification import identify

    train, _ = _data(robot, "stribeck", seed=9, duration=10.0)
    path = str(tmp_path / "joints.npz")
    np.savez(path, **dict(zip(("q", "dq", "ddq", "tau"), train, strict=True)))
    shapes = FrictionShapes(stribeck_velocity=tuple(VS), sigmoid_slope=tuple(SLOPE))
    terms = JointTerms(
        offset=True,
        asymmetric=True,
        stribeck=True,
        sigmoid=True,
        harmonics=2,
        load=True,
        shapes=shapes,
    )
    r = robot.with_terms(terms)
    serial = identify(r, tuple(train))
    parts = [(_npz_block, (path, a, a + 500)) for a in range(0, train[0].shape[0], 500)]
    cluster = LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        host="127.0.0.1",
        scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
    )
    client = Client(cluster)
    try:
        dask = identify(r, parts, base=serial.base, run=RunOptions(scheduler=client))
    finally:
        client.close()
        cluster.close()
    scale = np.abs(serial.estimate).max()
    assert np.abs(dask.estimate - serial.estimate).max() <= 1e-9 * scale


def test_simulator_evaluates_shaped_and_per_joint_laws(robot):
    from manip_id.control.closed_loop import Plant
    from manip_id.robot.regressor import joint_torques

    shapes = FrictionShapes(stribeck_velocity=(0.08, 0.2), sigmoid_slope=(30.0, 10.0))
    per_dof = (("fv", "fc", "fs"), ("fv", "fsg"))  # joint 1 Stribeck, joint 2 sigmoid
    terms = JointTerms(
        viscous=True, coulomb=True, stribeck=True, sigmoid=True, shapes=shapes, per_dof=per_dof
    )
    r = robot.with_terms(terms)
    theta = r.nominal_parameters.copy()
    theta[r.layout.joint_columns("fv")] = [0.3, 0.2]
    theta[r.layout.joint_columns("fc")] = [0.5, 9.0]  # joint 2 has no fc: 9 is ignored
    theta[r.layout.joint_columns("fs")] = [0.7, 9.0]
    theta[r.layout.joint_columns("fsg")] = [9.0, 1.2]
    dq = np.array([0.05, -0.3])
    expected = [
        0.3 * 0.05 + (0.5 + 0.7 * np.exp(-((0.05 / 0.08) ** 2))) * 1.0,
        0.2 * -0.3 + 1.2 * (1 / (1 + np.exp(10.0 * 0.3)) - 0.5),
    ]
    plant = Plant(r, theta, rate=100.0)
    np.testing.assert_allclose(plant.joint_torque(np.zeros(2), dq), expected, rtol=1e-12)
    np.testing.assert_allclose(joint_torques(r, theta, np.zeros(2), dq), expected, rtol=1e-12)


# ----------------------------------------------------------------------- CLI
def test_cli_friction_auto_on_data_files(robot, tmp_path, capsys):
    import json

    from manip_id.cli import main

    paths = []
    for k, seed in enumerate((11, 12)):
        (q, dq, ddq, tau), _ = _data(robot, "sigmoid", seed=seed, duration=20.0)
        t = np.arange(q.shape[0]) / RATE + 30.0 * k
        path = tmp_path / f"part{k}.npz"
        np.savez(path, t=t, q=q, dq=dq, ddq=ddq, tau=tau, joint_names=np.array(robot.dof_names))
        paths.append(str(path))
    out = tmp_path / "auto.json"
    argv = ["identify", "double_pendulum", "--data", paths[0], "--validate", paths[1]]
    assert main([*argv, "--friction", "auto", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "friction model per joint (by BIC on the training data):" in text
    report = json.loads(out.read_text())
    table = report["friction_selection"]
    assert [j["joint"] for j in table] == robot.dof_names
    for j in table:
        assert j["chosen"] in ("sigmoid", "sigmoid+position")
        assert {"model", "parameters", "validation_error", "bic"} <= set(j["candidates"][0])
    assert set(report["joint_terms_per_joint"]) == set(robot.dof_names)
    assert len(report["friction_shapes"]["sigmoid_slope"]) == 2
    assert report["relative_error"]["validation"] < 1.5 * NOISE  # 20 s of training data


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--simulate", "--friction", "auto"], "--friction auto applies to --data files"),
        (["--simulate", "--friction", "position:9"], "order 1..4"),
        (["--simulate", "--friction", "stiction"], "unknown friction kind 'stiction'"),
    ],
)
def test_cli_bad_friction_one_line_exit_2(capsys, args, message):
    from manip_id.cli import main

    assert main(["identify", "double_pendulum", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("manip-id: error:") and message in err[0]


def test_profile_takes_the_laws(tmp_path):
    path = tmp_path / "pendulum.toml"
    path.write_text('[model]\nfriction = ["viscous", "coulomb", "stribeck", "position:3"]\n')
    r = load_robot("double_pendulum", profile=path)
    assert r.terms.enabled == ("fv", "fc", "fs", "h1s", "h1c", "h2s", "h2c", "h3s", "h3c")
    path.write_text('[model]\nfriction = ["stiction"]\n')
    with pytest.raises(InputError, match="model.friction holds 'stiction'"):
        load_robot("double_pendulum", profile=path)


def test_load_law_is_refused_where_there_is_no_acceleration(robot):
    from manip_id.control.closed_loop import Plant
    from manip_id.models import accumulate_energy
    from manip_id.robot.regressor import slotine_li_regressor

    r = robot.with_terms(JointTerms(viscous=True, load=True))
    (q, dq, ddq, tau), _ = _data(robot, "linear", seed=13, duration=2.0)
    for call in (
        lambda: accumulate_energy(r, q, dq, tau, dt=1 / RATE),
        lambda: slotine_li_regressor(r, q[0], dq[0], ddq[0], dq[0]),
        lambda: Plant(r, r.nominal_parameters, rate=100.0),
    ):
        with pytest.raises(InputError, match="load friction law"):
            call()


def test_a_law_the_data_cannot_carry_is_no_candidate(robot):
    # 0.07 and 0.1 rad of motion: four harmonics and the offset are not independent there
    traj = random_trajectory(robot, harmonics=5, wf=0.3, seed=1).scaled(0.02)
    q, dq, ddq = traj.sample(np.arange(4000) / RATE)
    m, d = robot.model, robot.model.createData()
    tau = np.array([pin.rnea(m, d, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
    tau += 0.3 * dq + 0.5 * np.sign(dq) + 1e-3 * np.random.default_rng(0).standard_normal(tau.shape)
    opts = SelectionOptions(candidates=("linear", "position"), harmonics=4, combine=False)
    res, sel = select_model(lambda r: identify(r, (q, dq, ddq, tau)), robot, opts)
    assert [j.chosen for j in sel.joints] == ["linear", "linear"]
    position = res.context["friction_selection"][0]["candidates"][1]
    assert position["model"] == "position" and position["bic"] is None
    assert "position n/a (not excited)" in sel.text()
