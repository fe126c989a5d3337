"""Drift: unchanged simulated robots pass the tests at their level, a changed friction is named.

Simulated ur5 runs (Pinocchio's ``rnea`` plus friction, white torque noise relative to each
joint's RMS, exact ``ddq``) saved as NPZ; the reference and every file are identified with
WLS (the noise differs per joint), so the covariances are honest and the p-values uniform.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import get_robot

from manip_id.cli import main
from manip_id.datasets import save_dataset
from manip_id.errors import ModelMismatchError
from manip_id.identification import FileOptions, identify
from manip_id.monitor.drift import compare, drift_files
from manip_id.simulation import MeasurementNoise, simulate
from manip_id.trajectories import random_trajectory

FV = np.array([2.0, 2.0, 1.5, 0.5, 0.5, 0.5])  # [N m s/rad]
FC = np.array([3.0, 3.0, 2.0, 1.0, 1.0, 1.0])  # [N m]
N_UNCHANGED = 60
CHANGED_JOINT = 2  # elbow_joint


@pytest.fixture(scope="module")
def robot():
    return get_robot("ur5", friction=("viscous", "coulomb"))


@pytest.fixture(scope="module")
def theta(robot):
    th = robot.nominal_parameters.copy()
    th[robot.layout.joint_columns("fv")] = FV
    th[robot.layout.joint_columns("fc")] = FC
    return th


def _file(robot, theta, folder, seed):
    traj = random_trajectory(robot, seed=1000 + seed)
    sim = simulate(
        robot,
        traj,
        duration=10.0,
        rate=200.0,
        theta=theta,
        noise=MeasurementNoise(tau=0.02),
        seed=seed,
    )
    return str(save_dataset(sim.dataset, folder / f"run{seed}.npz"))


@pytest.fixture(scope="module")
def fleet(robot, theta, tmp_path_factory):
    folder = tmp_path_factory.mktemp("drift")
    ref_files = [_file(robot, theta, folder, s) for s in range(3)]
    reference = identify(robot, ref_files, method="wls", files=FileOptions(audit=False))
    same = [_file(robot, theta, folder, 100 + s) for s in range(N_UNCHANGED)]
    worn = theta.copy()
    worn[robot.layout.joint_column(CHANGED_JOINT, "fv")] *= 1.3  # +30 % viscous friction
    changed = [_file(robot, worn, folder, 500 + s) for s in range(5)]
    return reference, ref_files, same, changed


def test_unchanged_robots_give_uniform_p_values(robot, fleet):
    """False alarms at 0.05 over 60 unchanged robots: about 5 %.

    With exactly uniform p-values the count of 60 is Binomial(60, 0.05) (mean 3), above 3
    a third of the time, so the count is tested for not exceeding 5 % significantly
    (one-sided binomial test at 1 %, i.e. at most 7 of 60) and the p-values for
    uniformity (Kolmogorov-Smirnov at 1 %); all files share one reference, whose own
    error makes the tests correlated, hence the 3-file reference has 3x a file's data.
    """
    from scipy import stats

    reference, _, same, _ = fleet
    rep = drift_files(robot, reference, same, alpha=0.05)
    p = np.array([f.p_value for f in rep.files])
    assert len(p) == N_UNCHANGED >= 40
    n_false = int(np.sum(p < 0.05))
    assert stats.binomtest(n_false, N_UNCHANGED, 0.05, alternative="greater").pvalue > 0.01
    assert n_false <= 7
    assert stats.kstest(p, "uniform").pvalue > 0.01, np.sort(p)
    flagged_terms = sum(any(t.changed for t in f.terms) for f in rep.files)
    assert stats.binomtest(flagged_terms, N_UNCHANGED, 0.05, alternative="greater").pvalue > 0.01
    assert rep.covariance_kind == "honest (hac std, white-noise correlations)"


def test_changed_viscous_friction_is_flagged_on_that_joint_alone(robot, fleet):
    reference, _, _, changed = fleet
    rep = drift_files(robot, reference, changed)
    name = f"{robot.dof_names[CHANGED_JOINT]}.fv"
    for f in rep.files:
        assert f.changed and f.p_value < 1e-6
        flagged = [t.name for t in f.terms if t.changed]
        assert flagged == [name], flagged
        term = next(t for t in f.terms if t.name == name)
        assert term.change == pytest.approx(0.3, abs=0.05)
        assert "elbow_joint viscous friction +" in term.sentence()


def test_bad_reference_is_a_clear_error(robot, fleet):
    reference, ref_files, _, _ = fleet
    other = get_robot("ur5", friction=("viscous",))
    with pytest.raises(ModelMismatchError):
        drift_files(other, reference, ref_files[:1])
    plain = identify(other, ref_files[:2], files=FileOptions(audit=False))
    with pytest.raises(ModelMismatchError):
        compare(reference, plain)


def test_groups_are_tested_as_one(robot, fleet, tmp_path):
    """Two robots of three logs each (folders): the worn one is flagged on its elbow alone."""
    reference, _, same, changed = fleet
    out = tmp_path / "drift.json"
    ref = tmp_path / "ref.json"
    ref.write_text(json.dumps(reference.to_dict()))
    groups = {}
    for name, files in (("robot_a", same[:3]), ("robot_b", changed[:3])):
        folder = tmp_path / name
        folder.mkdir()
        groups[name] = []
        for f in files:
            link = folder / Path(f).name
            link.symlink_to(f)
            groups[name].append(str(link))
    argv = ["drift", "ur5", "--friction", "viscous,coulomb", "--reference", str(ref)]
    argv += ["--group-by", "folder", "--data", *groups["robot_a"], *groups["robot_b"]]
    assert main([*argv, "--json", str(out)]) == 0
    files = json.loads(out.read_text())["drift"]["files"]
    assert [Path(f["file"]).name for f in files] == ["robot_a", "robot_b"]
    assert files[0]["changed"] is False and files[1]["changed"] is True
    assert [t["name"] for t in files[1]["terms"] if t["changed"]] == ["elbow_joint.fv"]
    assert files[1]["n_samples"] == 3 * 2001


def test_cli_drift_json(robot, fleet, tmp_path, capsys):
    reference, _, same, changed = fleet
    ref = tmp_path / "ref.json"
    ref.write_text(json.dumps(reference.to_dict()))
    out = tmp_path / "drift.json"
    argv = ["drift", "ur5", "--friction", "viscous,coulomb", "--reference", str(ref)]
    status = main([*argv, "--data", same[0], changed[0], "--json", str(out)])
    assert status == 0
    doc = json.loads(out.read_text())["drift"]
    files = doc["files"]
    assert [f["file"] for f in files] == [same[0], changed[0]]
    assert files[0]["changed"] is False and files[1]["changed"] is True
    terms = {t["name"]: t for t in files[1]["terms"]}
    assert terms["elbow_joint.fv"]["changed"] and terms["elbow_joint.fv"]["p_value"] < 1e-6
    assert set(terms["elbow_joint.fv"]) >= {"name", "change", "p_value", "changed"}
    assert "elbow_joint viscous friction" in capsys.readouterr().out
    # a reference that is not a result: one line, status 2
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    assert main([*argv[:-2], "--reference", str(bad), "--data", same[0]]) == 2
    err = capsys.readouterr().err
    assert err.startswith("manip-id: error:") and len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_dask_local_cluster_gives_the_serial_report(robot, fleet):
    """One task per file on a LocalCluster: the same p-values as in this process."""
    from distributed import Client, LocalCluster

    reference, _, same, changed = fleet
    files = [same[0], changed[0]]
    serial = drift_files(robot, reference, files)
    cluster = LocalCluster(
        n_workers=1,
        threads_per_worker=1,
        host="127.0.0.1",
        scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
    )
    try:
        with Client(cluster) as client:
            dist = drift_files(robot, reference, files, scheduler=client)
    finally:
        cluster.close()
    for a, b in zip(dist.files, serial.files, strict=True):
        assert a.chi2 == pytest.approx(b.chi2, rel=1e-8)
        assert [t.changed for t in a.terms] == [t.changed for t in b.terms]
