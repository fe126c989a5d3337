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
    res = identify(robot, _arrays(train), validation=_arrays(val))
    assert res.method == "wls"
    ratio = np.asarray(res.relative_error.validation_per_joint) / floor
    assert np.all(ratio < 1.2), ratio
    doc = result_to_dict(res)
    assert not [w for w in doc["warnings"] if w.startswith("worse than the nominal")]

    ols = identify(robot, _arrays(train), validation=_arrays(val), method="ols")
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
    res = identify(robot, (d.q, d.dq, d.ddq, d.tau), consistent=ConsistentOptions())
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
        robot, (d.q, d.dq, d.ddq, d.tau), consistent=ConsistentOptions(mass_range=(lo, hi))
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
    from manip_id.robot.model import load_robot

    robot = load_robot("double_pendulum", friction=())
    train, _ = _data(robot, "stribeck", seed=3, duration=20.0)
    valid, _ = _data(robot, "asymmetric", seed=4, duration=20.0)  # another law: a trap
    opts = SelectionOptions(
        candidates=("linear", "asymmetric", "stribeck"),
        combine=False,
        stribeck_grid=(0.03, 0.1, 0.3),
        refine=1,
    )
    with_val, sel_val = select_model(
        lambda r: identify(r, tuple(train), validation=tuple(valid)), robot, opts
    )
    alone, sel = select_model(lambda r: identify(r, tuple(train)), robot, opts)
    assert [j.chosen for j in sel_val.joints] == [j.chosen for j in sel.joints]
    for a, b in zip(sel_val.joints, sel.joints, strict=True):
        np.testing.assert_allclose([c.bic for c in a.candidates], [c.bic for c in b.candidates])
    assert [j.chosen for j in sel.joints] == ["stribeck", "stribeck"]  # the training law
    for res in (with_val, alone):
        assert res.to_dict()["friction_criterion"] == "BIC on the training data"


# ------------------------------------------------------------------ the auditor
@pytest.fixture(scope="module")
def synchronous_logs(tmp_path_factory):
    """Exactly synchronous simulated logs of every command: identify's runs, payload's
    unloaded and loaded runs (a 2 kg payload the nominal model lacks), and drive-gains'
    runs in currents (G = 10 N m/A)."""
    from manip_id.cli import main

    root = tmp_path_factory.mktemp("sync")
    sim = ["--files", "1", "--duration", "20", "--seed", "0", "--force"]
    assert main(["simulate", "ur5", "--out", str(root / "plain"), *sim]) == 0
    assert main(["simulate", "ur5", "--out", str(root / "pl"), "--payload", "2", *sim]) == 0
    gains = ["--payload", "2", "--drive-gains", "10"]
    assert main(["simulate", "ur5", "--out", str(root / "dg"), *gains, *sim]) == 0
    return root


@pytest.mark.parametrize(("folder", "currents"), [("plain", False), ("pl", False), ("dg", True)])
def test_auditor_finds_no_delay_on_synchronous_logs(synchronous_logs, folder, currents):
    from manip_id.audit import AuditOptions, audit_files

    robot = get_robot("ur5")
    files = sorted(str(p) for p in (synchronous_logs / folder).glob("*.npz"))
    assert len(files) == (1 if folder == "plain" else 2)
    audit = audit_files(robot, files, AuditOptions(currents=currents))
    for fa in audit.files:
        assert "delay" not in fa.suggestions, (fa.file, fa.findings)
        assert not [f for f in fa.findings if "motion stream" in f], fa.findings
        step = 1.0 / fa.rate
        assert abs(fa.joints[0].delay or 0.0) < step  # the lag searched is below a sample


def _corrupt(path, out):
    d = dict(np.load(path))
    d["t"] = d["t"].copy()
    d["q"] = d["q"].copy()
    d["t"][4] = 2.68e154  # [s] a stamp of the real arm's log
    d["q"][700, 2] = 253.0  # [rad] a position spike of the real arm's log
    np.savez(out, **d)
    return d


def test_drop_bad_rows_drops_a_corrupted_stamp_and_a_spike(synchronous_logs, tmp_path):
    """One corrupted time stamp and one q spike: refused without --drop-bad-rows (with the
    hint), dropped and counted per reason with it, in the audit and in identify; the
    rows kept are exactly the others."""
    from manip_id.audit import AuditOptions, audit_files
    from manip_id.datasets import RowCounts, iter_rows, open_source, parse_file_spec
    from manip_id.errors import DataError

    robot = get_robot("ur5")
    src_path = next((synchronous_logs / "plain").glob("*.npz"))
    bad = tmp_path / "bad.npz"
    d = _corrupt(src_path, bad)
    with pytest.raises(DataError, match="drop-bad-rows"):
        audit_files(robot, [str(bad)])
    audit = audit_files(robot, [str(bad)], AuditOptions(drop_bad_rows=True))
    (fa,) = audit.files
    assert fa.dropped == {"time stamp": 1, "position spike": 1}
    assert fa.n_rows == d["t"].shape[0] - 2
    counts = RowCounts()
    spec = parse_file_spec(str(bad))
    rows = np.concatenate(list(iter_rows(open_source(spec), drop_bad_rows=True, counts=counts)))
    keep = np.ones(d["t"].shape[0], dtype=bool)
    keep[[4, 700]] = False
    np.testing.assert_array_equal(rows[:, 0], d["t"][keep])
    assert counts.reasons == {"time stamp": 1, "position spike": 1}


def test_truncated_last_line_is_dropped_with_a_note(synchronous_logs, tmp_path):
    from manip_id.datasets import RowCounts, iter_rows, open_source, parse_file_spec

    src = np.load(next((synchronous_logs / "plain").glob("*.npz")))
    n = 50
    cols = [src["t"][:n, None], src["q"][:n], src["dq"][:n], src["tau"][:n]]
    table = np.hstack(cols)
    names = [str(x) for x in src["joint_names"]]
    head = ["t"] + [f"{f}_{j}" for f in ("q", "dq", "tau") for j in names]
    text = ",".join(head) + "\n" + "\n".join(",".join(repr(float(v)) for v in r) for r in table)
    path = tmp_path / "cut.csv"
    path.write_text(text[: text.rindex(",", 0, text.rindex(","))])  # two cells short, no end
    counts = RowCounts()
    with pytest.warns(UserWarning, match="truncated last line"):
        rows = np.concatenate(
            list(iter_rows(open_source(parse_file_spec(str(path))), counts=counts))
        )
    assert rows.shape[0] == n - 1 and counts.reasons == {"truncated last line": 1}
    np.testing.assert_allclose(rows, table[: n - 1])


def test_multi_file_audit_reports_every_file(synchronous_logs, tmp_path):
    from manip_id.audit import audit_files
    from manip_id.errors import DataError

    robot = get_robot("ur5")
    good = [str(p) for p in sorted((synchronous_logs / "pl").glob("*.npz"))]
    bad = tmp_path / "bad.npz"
    _corrupt(good[0], bad)
    audit = audit_files(robot, [str(bad), *good])
    assert [fa.file for fa in audit.files] == good
    assert list(audit.failed) == [str(bad)]
    assert f"{bad}: not audited" in audit.table()
    with pytest.raises(DataError, match="1 of 3 file"):
        audit.check()


def test_scale_suggestion_only_for_determined_joints():
    from manip_id.audit.findings import torque_findings
    from manip_id.audit.report import JointAudit

    joints = [
        JointAudit("a", 0.1, None, 0.0, 0.0),  # currents of a 10 N m/A drive
        JointAudit("b", None, None, 0.0, 0.0),  # not determined
        JointAudit("c", 1.0, None, 0.0, 0.0),  # already in N m
    ]
    suggestions: dict = {}
    text = " ".join(torque_findings(joints, 0.005, None, suggestions))
    assert suggestions["torque_scale"] == [10.0, None, 1.0]
    assert "try --torque-scale 10,?,1" in text
    assert "scale not determined for b" in text and "give their gains" in text


def test_consistent_fit_on_a_non_physical_urdf_gives_the_repair_hint(tmp_path):
    """Bodies made non-physical by hand (a negative moment, a negative mass): the prior is
    refused with the bodies named and the way out (``manip-id repair``)."""
    import xml.etree.ElementTree as ET

    from manip_id.errors import PhysicalConsistencyError
    from manip_id.robot.model import load_robot

    tree = ET.parse(get_robot("ur5").source)
    links = {lk.get("name"): lk for lk in tree.getroot().findall("link")}
    links["shoulder_link"].find("inertial/inertia").set("ixx", "-0.01")
    links["wrist_2_link"].find("inertial/mass").set("value", "-1.219")
    path = tmp_path / "ur5_broken.urdf"
    tree.write(path)
    robot = load_robot(str(path))
    sim = _demo_like(get_robot("ur5"), 3)
    d = sim.dataset
    with pytest.raises(PhysicalConsistencyError) as info:
        identify(robot, (d.q, d.dq, d.ddq, d.tau), consistent=ConsistentOptions())
    text = str(info.value)
    assert "manip-id repair ROBOT OUT.urdf" in text
    assert "shoulder_pan_joint" in text and "wrist_2_joint" in text


def test_verdict_gives_the_raw_error_beside_the_filtered_one():
    """The real-log case: 0.741 % against the 3 Hz-filtered torques, 2.46 % raw."""
    doc = {
        "relative_error": {"validation": 0.00741, "nominal_validation": 0.0123},
        "relative_error_raw": {"validation": 0.0246, "nominal_validation": 0.0288},
    }
    text = verdict_text(doc)
    assert "predicts the filtered validation torques to 0.741 % (nominal model 1.230 %)" in text
    assert "the raw ones to 2.460 % (nominal model 2.880 %)" in text
    assert "filtered" not in verdict_text({"relative_error": doc["relative_error"]})


def test_point_mass_payload_is_reported_as_such(synchronous_logs, tmp_path, capsys):
    """The simulated payload is a 2 kg point mass (truth.json): reported as a point mass,
    without the "not physically consistent" warning."""
    import json

    from manip_id.cli import main

    folder = synchronous_logs / "pl"
    truth = (folder / "truth.json").read_text()
    assert "point mass" in (folder / "README.txt").read_text() or "point" in truth
    out = tmp_path / "p.json"
    argv = ["payload", "ur5", "--unloaded", str(folder / "run_0.npz"), "--loaded"]
    argv += [str(folder / "payload_2kg_0.npz"), "--frame", "wrist_3_joint", "--json", str(out)]
    assert main(argv) == 0
    text = capsys.readouterr()
    assert "a point mass: its inertia about the centre of mass is zero" in text.out
    assert "not physically consistent" not in text.out + text.err
    doc = json.loads(out.read_text())
    assert doc["payload"]["point_mass"] is True
    assert abs(doc["payload"]["mass"] - 2.0) < 0.01


def test_split_of_a_periodic_simulation_warns_in_the_api():
    """Dataset.split says what the CLI says when the training part of a periodic simulated
    motion spans more than one period (the period from the trajectory, independent)."""
    import warnings

    from manip_id.errors import DataWarning

    robot = get_robot("ur5")
    traj = random_trajectory(robot, seed=3, harmonics=3)
    period = float(traj.period)
    long = simulate(robot, traj, duration=2.0 * period, rate=50.0).dataset
    with pytest.warns(DataWarning, match=f"periodic \\({period:g} s\\)"):
        long.split(0.7)  # 1.4 periods of training
    short = simulate(robot, traj, duration=1.2 * period, rate=50.0).dataset
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        train, valid = short.split(0.7)  # 0.84 periods: new motion in the validation part
    assert train.duration < period
