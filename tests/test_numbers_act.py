"""Numbers a user can act on: defaults that do not hurt (WLS), a warning when a joint is
worse than the nominal model, values that say where they come from, an honest auditor."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import get_robot

from manip_id.identification import (
    ConsistentOptions,
    identify,
    result_text,
    result_to_dict,
    verdict_text,
)
from manip_id.simulation import MeasurementNoise, simulate
from manip_id.trajectories import random_trajectory


def _demo_like(robot, seed: int):
    """A demo-like record (20 s at 200 Hz, torque noise 1 % of each joint's RMS)."""
    traj = random_trajectory(robot, seed=seed, harmonics=5)
    return simulate(
        robot, traj, duration=20.0, rate=200.0, noise=MeasurementNoise(tau=0.01), seed=seed
    )


@pytest.fixture(scope="module")
def panda_demo():
    robot = get_robot("panda")
    return robot, _demo_like(robot, 1), _demo_like(robot, 2)


def _arrays(sim):
    d = sim.dataset
    return d.q, d.dq, d.ddq, d.tau


def test_default_method_keeps_every_joint_at_the_noise_floor(panda_demo):
    """The noise floor of joint j, ``||tau_j - tau_true_j|| / ||tau_j||`` on the validation
    record, comes from the simulation's truth; the default fit reaches it on every joint
    (within 1.2x), while plain OLS leaves the 0.3 N m wrist far above and says so."""
    robot, train, val = panda_demo
    tau, truth = val.dataset.tau, val.tau_true
    floor = np.linalg.norm(tau - truth, axis=0) / np.linalg.norm(tau, axis=0)
    res = identify(robot, *_arrays(train), validation=_arrays(val))
    assert res.method == "wls"
    ratio = np.asarray(res.relative_error.validation_per_joint) / floor
    assert np.all(ratio < 1.2), ratio
    doc = result_to_dict(res)
    assert not [w for w in doc["warnings"] if w.startswith("worse than the nominal")]

    ols = identify(robot, *_arrays(train), validation=_arrays(val), method="ols")
    worse = np.asarray(ols.relative_error.validation_per_joint) / floor
    bad = [robot.dof_names[j] for j in np.flatnonzero(worse > 1.5)]
    assert bad, worse  # this record's OLS makes a joint worse (the wrist)
    doc = result_to_dict(ols)
    (warning,) = [w for w in doc["warnings"] if w.startswith("worse than the nominal")]
    assert all(name in warning for name in bad) and "Do: refit with --method wls" in warning
    assert "WORSE than the nominal model" in verdict_text(doc)
    assert warning in result_text(doc)


@pytest.fixture(scope="module")
def ur5_record():
    robot = get_robot("ur5")
    traj = random_trajectory(robot, seed=3)
    sim = simulate(
        robot,
        traj,
        duration=10.0,
        rate=100.0,
        perturb=0.3,
        noise=MeasurementNoise(tau=0.01),
        seed=3,
    )
    return robot, sim


def test_consistent_fit_says_which_values_come_from_the_prior(ur5_record):
    """A column of Pinocchio's regressor that is zero on every sample is a parameter the
    data never see: its value is the prior's, without a data std (text, JSON)."""
    import pinocchio as pin

    robot, sim = ur5_record
    d = sim.dataset
    res = identify(robot, d.q, d.dq, d.ddq, d.tau, consistent=ConsistentOptions())
    doc = result_to_dict(res)
    seen = np.zeros(10 * robot.model.nv, dtype=bool)
    for k in range(0, len(d.q), 50):
        Y = pin.computeJointTorqueRegressor(robot.model, robot.data, d.q[k], d.dq[k], d.ddq[k])
        seen |= np.abs(Y).max(axis=0) > 1e-9
    rows = {r["name"]: r for r in doc["standard_parameters"]}
    names = robot.parameter_names[: 10 * robot.model.nv]
    for name, enters in zip(names, seen, strict=True):
        assert rows[name]["source"] == ("data" if enters else "prior"), name
        assert (rows[name]["std"] is None) == (not enters), name
    assert rows["shoulder_pan_joint.m"]["source"] == "prior"
    text = result_text(doc)
    assert "shoulder_pan_joint 3.7 from the prior (not in the dynamics, no data std)" in text
    assert text.splitlines()[0] == "identification: WLS + consistent (SDP) of ur5"
    assert "masses set by the bounds" not in verdict_text(doc)


def test_masses_held_by_tight_bounds_are_reported_at_their_bounds(ur5_record):
    """Masses of a robot perturbed by 30 % and bounded to 0.1 % of nominal sit on the
    bound (value = nominal x 0.999 or 1.001, checked directly): text, JSON and report say
    so, and no data std is printed for them."""
    from manip_id.viz.report_answers import body_rows

    robot, sim = ur5_record
    d = sim.dataset
    lo, hi = 0.999, 1.001
    res = identify(
        robot, d.q, d.dq, d.ddq, d.tau, consistent=ConsistentOptions(mass_range=(lo, hi))
    )
    doc = result_to_dict(res)
    masses = [r for r in doc["standard_parameters"] if r["name"].endswith(".m")]
    at_bound = {
        r["name"][:-2]
        for r in masses
        if min(abs(r["value"] - lo * r["nominal"]), abs(r["value"] - hi * r["nominal"]))
        <= 1e-4 * r["nominal"]
    }
    assert len(at_bound) >= 4  # 30 % off nominal: the data push most masses to a bound
    assert {r["name"][:-2] for r in masses if r["source"] == "bound"} == at_bound
    assert all(r["std"] is None for r in masses if r["source"] == "bound")
    text = result_text(doc)
    for body in at_bound:
        assert f"{body} " in text and any(
            f"{body} {m['value']:.3g} at bound" in text for m in masses if m["name"] == f"{body}.m"
        )
    if at_bound == {r["name"][:-2] for r in masses}:
        assert "masses set by the bounds, not the data" in verdict_text(doc)
    else:
        assert "set by the bounds, not the data" in verdict_text(doc)
    report = {row["body"]: row.get("mass from") for row in body_rows(doc)}
    assert all(report[b] == "bound" for b in at_bound)


def test_friction_auto_chooses_the_same_laws_with_and_without_validation_data():
    """The choice is made on the training data alone: giving validation data changes
    neither the laws nor their BICs; the JSON says how the choice was made."""
    from test_friction import _data

    from manip_id.identification.selection import SelectionOptions, select_model
    from manip_id.robot import load_robot

    robot = load_robot("double_pendulum", friction=())
    train, _ = _data(robot, "stribeck", seed=3, duration=20.0)
    valid, _ = _data(robot, "asymmetric", seed=4, duration=20.0)  # another law: a trap
    opts = SelectionOptions(
        candidates=("linear", "asymmetric", "stribeck"),
        combine=False,
        stribeck_grid=(0.03, 0.1, 0.3),
        refine=1,
    )
    with_val, sel_val = select_model(lambda r: identify(r, *train, validation=valid), robot, opts)
    alone, sel = select_model(lambda r: identify(r, *train), robot, opts)
    assert [j.chosen for j in sel_val.joints] == [j.chosen for j in sel.joints]
    for a, b in zip(sel_val.joints, sel.joints, strict=True):
        np.testing.assert_allclose([c.bic for c in a.candidates], [c.bic for c in b.candidates])
    assert [j.chosen for j in sel.joints] == ["stribeck", "stribeck"]  # the training law
    for res in (with_val, alone):
        assert res.to_dict()["friction_criterion"] == "BIC on the training data"
