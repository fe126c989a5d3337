"""``manip-id monitor``: detections in the JSON at the simulated collision, every model kind.

Simulated ur5 files (NPZ) with a known external torque on one joint; models from a plain
OLS result, a physically consistent one, a momentum-model one, and an exported URDF +
sidecar (the true parameters): each detects the interval, and reports nothing on a
collision-free file.
"""

from __future__ import annotations

import html
import json

import numpy as np
import pytest
from conftest import get_robot

from manip_id.cli import main
from manip_id.datasets import Dataset, save_dataset
from manip_id.export import export_urdf
from manip_id.identification import FileOptions, identify
from manip_id.simulation import simulate
from manip_id.trajectories import random_trajectory

FV = np.array([2.0, 2.0, 1.5, 0.5, 0.5, 0.5])  # [N m s/rad]
FC = np.array([3.0, 3.0, 2.0, 1.0, 1.0, 1.0])  # [N m]
NOISE = np.array([0.05, 0.1, 0.05, 0.02, 0.02, 0.02])  # torque noise std [N m]
HIT = (1, 2.0, 2.5, 12.0)  # joint, start [s], stop [s], external torque [N m]
ROBOT = ["ur5", "--friction", "viscous,coulomb"]


@pytest.fixture(scope="module")
def robot():
    return get_robot("ur5", friction=("viscous", "coulomb"))


@pytest.fixture(scope="module")
def files(robot, tmp_path_factory):
    folder = tmp_path_factory.mktemp("monitor_cli")
    theta = robot.nominal_parameters.copy()
    theta[robot.layout.joint_columns("fv")] = FV
    theta[robot.layout.joint_columns("fc")] = FC
    out = {"theta": theta, "folder": folder}
    for name, seed, hit in (("calib", 1, False), ("calib2", 2, False), ("clean", 3, False),
                            ("hit", 4, True)):  # fmt: skip
        traj = random_trajectory(robot, seed=200 + seed)
        ds = simulate(robot, traj, duration=5.0, rate=500.0, theta=theta).dataset
        # white noise of one size in every file (simulate's is relative to each file's RMS)
        tau = ds.tau + NOISE * np.random.default_rng(seed).standard_normal(ds.tau.shape)
        if hit:
            j, a, b, size = HIT
            tau[(ds.t >= a) & (ds.t < b), j] -= size  # the motors supply less: tau_ext helps
        ds = Dataset(t=ds.t + 100.0, q=ds.q, dq=ds.dq, tau=tau, ddq=ds.ddq)  # own time base
        out[name] = str(save_dataset(ds, folder / f"{name}.npz"))
    return out


def _result(robot, files, kind: str):
    kw = {"consistent": True} if kind == "consistent" else {}
    kw |= {"model": "momentum"} if kind == "momentum" else {}
    res = identify(robot, [files["calib"], files["calib2"]], files=FileOptions(audit=False), **kw)
    path = files["folder"] / f"result_{kind}.json"
    path.write_text(json.dumps(res.to_dict()))
    return str(path)


def _check_detections(doc, files):
    j, a, b, size = HIT
    dets = doc["detections"]
    assert [d["file"] for d in dets] == [files["hit"]], dets
    d = dets[0]
    assert 100.0 + a <= d["start"] <= 100.0 + a + 0.15  # the file's own time [s]
    assert 100.0 + b <= d["stop"] <= 100.0 + b + 0.4  # decay of 12 N m to ~0.03 N m
    assert d["joints"][0] == "shoulder_lift_joint" or "shoulder_lift_joint" in d["joints"]
    assert d["peak"] == pytest.approx(size, rel=0.15)
    assert {f["file"]: f["n_detections"] for f in doc["files"]} == {
        files["clean"]: 0,
        files["hit"]: 1,
    }


@pytest.mark.parametrize("kind", ["plain", "consistent", "momentum"])
def test_monitor_json_from_results(robot, files, kind, tmp_path, capsys):
    """Plain OLS, physically consistent, and the acceleration-free momentum model."""
    model = _result(robot, files, kind)
    out = tmp_path / "mon.json"
    report = tmp_path / "report"
    argv = [*ROBOT, "--model", model, "--calibrate", files["calib"], files["calib2"]]
    argv += ["--data", files["clean"], files["hit"], "--json", str(out)]
    argv += ["--report", str(report)] if kind == "plain" else []
    assert main(["monitor", *argv]) == 0
    doc = json.loads(out.read_text())
    _check_detections(doc, files)
    th = doc["thresholds"]
    assert th["false_alarm"] == 1e-3 and th["rate"] <= 1e-3
    assert [j["name"] for j in th["joints"]] == list(robot.dof_names)
    assert "shoulder_lift_joint" in capsys.readouterr().out
    if kind == "plain":
        assert (report / "residuals_1.png").is_file() and (report / "index.html").is_file()
        page = (report / "index.html").read_text()
        assert page.index("Was anything detected?") < page.index("<h2>Summary</h2>")
        assert "1 detection(s)</span> in 2 file(s)" in page
        j, a, _, _ = HIT
        first = doc["detections"][0]["start"]
        assert f"the first alarm at {first:.4f} s" in page and first >= 100.0 + a
        assert page.count('class="bad"') >= 1  # the hit joint crossed its bound
        # calibrated on the files the model was identified on: the page says so
        assert "Calibrated on the model's own training data" in html.unescape(page)
        assert doc["thresholds"]["in_sample"] == [files["calib"], files["calib2"]]


def test_monitor_with_saved_thresholds(robot, files, tmp_path):
    """Calibrate once (--json), monitor later with --thresholds: the same detections."""
    model = _result(robot, files, "plain")
    first, second = tmp_path / "first.json", tmp_path / "second.json"
    base = ["monitor", *ROBOT, "--model", model, "--gain", "30", "--filter-gain", "none"]
    assert main([*base, "--calibrate", files["calib"], "--data", files["hit"],
                 "--json", str(first)]) == 0  # fmt: skip
    argv = ["monitor", *ROBOT, "--model", model, "--thresholds", str(first)]
    assert main([*argv, "--data", files["hit"], "--json", str(second)]) == 0
    a, b = json.loads(first.read_text()), json.loads(second.read_text())
    assert a["detections"] == b["detections"] and len(a["detections"]) >= 1
    assert b["thresholds"]["joints"][0]["gain"] == 30.0
    assert b["thresholds"]["joints"][0]["filter_gain"] is None


def test_monitor_from_exported_urdf(robot, files, tmp_path):
    urdf = tmp_path / "ur5_identified.urdf"
    export_urdf(robot, files["theta"], urdf)
    out = tmp_path / "mon.json"
    argv = ["monitor", str(urdf), "--identified", "--calibrate", files["calib"], files["calib2"]]
    assert main([*argv, "--data", files["clean"], files["hit"], "--json", str(out)]) == 0
    _check_detections(json.loads(out.read_text()), files)


def test_monitor_bad_input_is_one_line(robot, files, tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"hello": 1}))
    base = ["monitor", *ROBOT, "--calibrate", files["calib"], "--data", files["hit"]]
    plain = _result(robot, files, "plain")
    good = [*base, "--model", plain]
    for argv, says in (
        ([*base, "--model", str(bad)], "not an identification result"),
        (["monitor", "panda", "--model", plain, *base[4:]], "ur5"),  # another robot
        ([*good, "--gain", "-3"], "gain"),
        (base, "--model"),  # no model
        ([*good[:4], "--model", plain, "--thresholds", str(bad), "--data", files["hit"]],
         "not monitor thresholds"),
        ([*good, "--json", files["hit"]], "input"),  # an input as the output
    ):  # fmt: skip
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith("manip-id: error:") and len(err.strip().splitlines()) == 1, err
        assert says in err, err


def test_monitor_reads_csv_columns_and_windows(robot, files, tmp_path):
    """A CSV of other column names (--column) and a window in the file's own time give the
    detections of the NPZ file."""
    d = np.load(files["hit"])
    nv = robot.nv
    header = ["stamp", *[f"pos{j}" for j in range(nv)], *[f"vel{j}" for j in range(nv)]]
    header += [f"eff{j}" for j in range(nv)]
    rows = np.hstack([d["t"][:, None], d["q"], d["dq"], d["tau"]])
    csv = tmp_path / "hit.csv"
    np.savetxt(csv, rows, delimiter=",", header=",".join(header), comments="", fmt="%.17g")
    cols = ["--column", "t=stamp", "--column", "q=pos*", "--column", "dq=vel*"]
    cols += ["--column", "tau=eff*"]
    ref, out = tmp_path / "ref.json", tmp_path / "csv.json"
    model = _result(robot, files, "plain")
    base = ["monitor", *ROBOT, "--model", model, "--calibrate", files["calib"]]
    assert main([*base, "--data", f"{files['hit']}@1.5:4", "--json", str(ref)]) == 0
    argv = [*base, "--data", f"{csv}@1.5:4", *cols, "--json", str(out)]
    assert main(argv) == 0
    a, b = json.loads(ref.read_text())["detections"], json.loads(out.read_text())["detections"]
    assert len(a) == 1 and 101.5 <= a[0]["start"] <= 102.2  # the window is in seconds from
    for x, y in zip(a, b, strict=True):  # the first stamp; times are the file's own
        assert x["start"] == pytest.approx(y["start"]) and x["peak"] == pytest.approx(y["peak"])


def test_bounds_from_the_training_files_are_flagged_in_sample(robot, files, tmp_path):
    """Calibrating on the files the model was identified on warns and says so in the JSON;
    another file, or another window of a training file, does not."""
    from manip_id.errors import MonitorWarning
    from manip_id.monitor import calibrate_thresholds, load_model

    model = load_model(robot, _result(robot, files, "plain"))
    assert {path for path, _ in model.training} == {files["calib"], files["calib2"]}
    with pytest.warns(MonitorWarning, match="training data"):
        th = calibrate_thresholds(robot, model, [files["clean"], files["calib2"]])
    assert th.in_sample == [files["calib2"]] and th.to_dict()["in_sample"] == [files["calib2"]]
    clean = calibrate_thresholds(robot, model, [files["clean"]])
    assert clean.in_sample == []
    trained = identify(robot, [f"{files['calib']}@0:2"], files=FileOptions(audit=False))
    path = tmp_path / "windowed.json"
    path.write_text(json.dumps(trained.to_dict()))
    windowed = load_model(robot, str(path))
    assert windowed.training == ((files["calib"], "0:2"),)
    later = calibrate_thresholds(robot, windowed, [f"{files['calib']}@2:5"])
    assert later.in_sample == []
    with pytest.warns(MonitorWarning):
        calibrate_thresholds(robot, windowed, [files["calib"]])  # the whole file holds it
