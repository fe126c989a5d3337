"""`manip-id payload` and `manip-id drive-gains` on NPZ files written here from Pinocchio data."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import get_robot
from test_payload import make_payload, make_runs, truth

import manip_id.datasets.csv as csv_module
from manip_id.cli import main
from manip_id.datasets import load_dataset, save_dataset

GAINS = np.array([0.45, 0.8, 1.1, 1.4, 1.7, 2.3])  # [N m / A]


def _save(path, block, robot, t0=0.0):
    q, dq, ddq, tau = block
    t = t0 + 0.01 * np.arange(q.shape[0])
    np.savez(path, t=t, q=q, dq=dq, ddq=ddq, tau=tau, joint_names=np.array(robot.dof_names))
    return str(path)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """ur5 runs (torques and currents) and double-pendulum runs, as NPZ files."""
    d = tmp_path_factory.mktemp("payload_runs")
    ur5 = get_robot("ur5")
    payload = make_payload()
    u, ld = make_runs(ur5, "tool0", payload, n=500)
    cu, cl = make_runs(ur5, "tool0", payload, n=500, seed=3, gains=GAINS)
    pend = get_robot("double_pendulum")
    pu, pl = make_runs(pend, "link2", payload, n=300)
    return {
        "payload": payload,
        "u": _save(d / "u.npz", u, ur5),
        "l": _save(d / "l.npz", ld, ur5),
        "cu": _save(d / "cu.npz", cu, ur5),
        "cl": _save(d / "cl.npz", cl, ur5),
        "pu": _save(d / "pu.npz", pu, pend),
        "pl": _save(d / "pl.npz", pl, pend),
    }


def _run(argv, capsys):
    status = main(argv)
    return status, capsys.readouterr()


def test_payload_command(files, tmp_path, capsys):
    out = tmp_path / "p.json"
    status, cap = _run(
        [
            "payload",
            "ur5",
            "--unloaded",
            files["u"],
            "--loaded",
            files["l"],
            "--frame",
            "tool0",
            "--json",
            str(out),
        ],
        capsys,
    )
    assert status == 0, cap.err
    doc = json.loads(out.read_text())
    want = truth(files["payload"])
    p = doc["payload"]
    assert p["mass"] == pytest.approx(want[0], abs=1e-6)
    assert p["com"] == pytest.approx(want[1:4].tolist(), abs=1e-6)
    assert p["inertia"] == pytest.approx(want[4:].tolist(), abs=1e-6)
    assert len(p["com_std"]) == 3 and len(p["inertia_std"]) == 6
    assert p["frame"] == "tool0" and p["parent_joint"] == "wrist_3_joint"
    assert doc["source"]["loaded"] == [files["l"]]
    assert "mass" in cap.out and "wrote" in cap.out


def test_payload_windows_and_several_files(files, tmp_path, capsys):
    """Loaded runs given as two windows of one file (repeated --loaded) equal the whole file."""
    out1, out2 = tmp_path / "a.json", tmp_path / "b.json"
    base = ["payload", "ur5", "--unloaded", files["u"], "--frame", "tool0"]
    s1, _ = _run([*base, "--loaded", files["l"], "--json", str(out1)], capsys)
    s2, cap = _run(
        [
            *base,
            "--loaded",
            files["l"] + "@#0:#250",
            "--loaded",
            files["l"] + "@#250:",
            "--json",
            str(out2),
        ],
        capsys,
    )
    assert s1 == 0 and s2 == 0, cap.err
    a, b = json.loads(out1.read_text()), json.loads(out2.read_text())
    assert b["n_samples"]["loaded"] == 500
    assert b["payload"]["mass"] == pytest.approx(a["payload"]["mass"], abs=1e-9)


def test_partly_identifiable_payload_names_components(files, tmp_path, capsys):
    out = tmp_path / "p.json"
    status, cap = _run(
        [
            "payload",
            "double_pendulum",
            "--unloaded",
            files["pu"],
            "--loaded",
            files["pl"],
            "--frame",
            "link2",
            "--consistent",
            "--json",
            str(out),
        ],
        capsys,
    )
    assert status == 0, cap.err
    p = json.loads(out.read_text())["payload"]
    assert "com.x" in p["not_identifiable"] and p["com"][0] is None
    assert p["physically_consistent"] is True
    assert "manip-id: warning:" in cap.err and "com.x" in cap.err


def test_known_base_from_identify_json(files, tmp_path, capsys):
    ident = tmp_path / "id.json"
    status, cap = _run(["identify", "ur5", "--data", files["u"], "--json", str(ident)], capsys)
    assert status == 0, cap.err
    out = tmp_path / "p.json"
    status, cap = _run(
        [
            "payload",
            "ur5",
            "--known-base",
            str(ident),
            "--loaded",
            files["l"],
            "--frame",
            "tool0",
            "--json",
            str(out),
        ],
        capsys,
    )
    assert status == 0, cap.err
    doc = json.loads(out.read_text())
    assert doc["known_base"] is True
    assert doc["payload"]["mass"] == pytest.approx(files["payload"].mass, abs=1e-6)


def test_drive_gains_command(files, tmp_path, capsys):
    out = tmp_path / "g.json"
    status, cap = _run(
        [
            "drive-gains",
            "ur5",
            "--unloaded",
            files["cu"],
            "--loaded",
            files["cl"],
            "--frame",
            "tool0",
            "--payload-mass",
            str(files["payload"].mass),
            "--json",
            str(out),
        ],
        capsys,
    )
    assert status == 0, cap.err
    doc = json.loads(out.read_text())
    assert [g["joint"] for g in doc["drive_gains"]] == get_robot("ur5").dof_names
    assert [g["gain"] for g in doc["drive_gains"]] == pytest.approx(GAINS.tolist(), abs=1e-6)
    assert doc["torque_scale"] == pytest.approx(GAINS.tolist(), abs=1e-6)
    assert all(g["determined"] for g in doc["drive_gains"])
    want = truth(files["payload"])
    assert doc["payload"]["com"] == pytest.approx(want[1:4].tolist(), abs=1e-6)
    # known centre of mass and inertia, TLS
    status, cap = _run(
        [
            "drive-gains",
            "ur5",
            "--unloaded",
            files["cu"],
            "--loaded",
            files["cl"],
            "--frame",
            "tool0",
            "--payload-mass",
            str(want[0]),
            "--payload-com",
            ",".join(map(str, want[1:4])),
            "--payload-inertia",
            ",".join(map(str, want[4:])),
            "--method",
            "tls",
            "--json",
            str(out),
        ],
        capsys,
    )
    assert status == 0, cap.err
    doc = json.loads(out.read_text())
    assert doc["torque_scale"] == pytest.approx(GAINS.tolist(), abs=1e-6)
    assert doc["method"] == "tls"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["payload", "ur5", "--unloaded", "U", "--loaded", "L", "--frame", "tool9"],
            "no frame 'tool9'",
        ),
        (
            ["payload", "ur5", "--unloaded", "U", "--loaded", "U", "--frame", "tool0"],
            "both an unloaded and a loaded run",
        ),
        (
            [
                "payload",
                "ur5",
                "--unloaded",
                "U@#0:#250",
                "--loaded",
                "U@#250:",
                "--frame",
                "tool0",
            ],
            "no payload information",
        ),
        (
            ["payload", "ur5", "--unloaded", "U", "--loaded", "PL", "--frame", "tool0"],
            "robot 'ur5'",
        ),
        (["payload", "ur5", "--loaded", "L", "--frame", "tool0"], "--unloaded"),
        (
            [
                "drive-gains",
                "ur5",
                "--unloaded",
                "CU",
                "--loaded",
                "CL",
                "--frame",
                "tool0",
                "--payload-mass",
                "0",
            ],
            "--payload-mass must be > 0",
        ),
        (
            [
                "drive-gains",
                "ur5",
                "--unloaded",
                "CU",
                "--loaded",
                "CL",
                "--frame",
                "tool0",
                "--payload-mass",
                "1",
                "--payload-com",
                "1,2",
            ],
            "3 comma-separated",
        ),
        (
            [
                "drive-gains",
                "ur5",
                "--unloaded",
                "CU",
                "--loaded",
                "CL",
                "--frame",
                "tool0",
                "--payload-mass",
                "1",
                "--payload-inertia",
                "1,0,1,0,0,1",
            ],
            "needs --payload-com",
        ),
    ],
)
def test_bad_input_is_one_line_exit_2(files, capsys, argv, message):
    names = {
        "U": files["u"],
        "L": files["l"],
        "PL": files["pl"],
        "CU": files["cu"],
        "CL": files["cl"],
    }

    def sub(a):
        head, sep, tail = a.partition("@")
        return names.get(head, head) + sep + tail

    status, cap = _run([sub(a) for a in argv], capsys)
    assert status == 2
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("manip-id: error:"), cap.err
    assert message in lines[0]
    assert "Traceback" not in cap.err


def test_unknown_frame_lists_the_valid_ones(files, capsys):
    status, cap = _run(
        ["payload", "ur5", "--unloaded", files["u"], "--loaded", files["l"], "--frame", "hand"],
        capsys,
    )
    assert status == 2
    assert "tool0" in cap.err and "wrist_3_link" in cap.err


def test_torque_scale_from_drive_gains(files, tmp_path, capsys):
    """identify on currents with --torque-scale-from the drive-gains JSON equals identify on
    the torques (the same motion)."""
    gains_json = tmp_path / "g.json"
    status, cap = _run(
        [
            "drive-gains",
            "ur5",
            "--unloaded",
            files["cu"],
            "--loaded",
            files["cl"],
            "--frame",
            "tool0",
            "--payload-mass",
            str(files["payload"].mass),
            "--json",
            str(gains_json),
        ],
        capsys,
    )
    assert status == 0, cap.err
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    status, cap = _run(
        [
            "identify",
            "ur5",
            "--data",
            files["cu"],
            "--torque-scale-from",
            str(gains_json),
            "--json",
            str(a),
        ],
        capsys,
    )
    assert status == 0, cap.err
    torque_file = tmp_path / "t.npz"
    with np.load(files["cu"]) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["tau"] = arrays["tau"] * GAINS
    np.savez(torque_file, **arrays)
    status, cap = _run(["identify", "ur5", "--data", str(torque_file), "--json", str(b)], capsys)
    assert status == 0, cap.err
    ra, rb = json.loads(a.read_text()), json.loads(b.read_text())
    assert ra["torque_scale"] == pytest.approx(GAINS.tolist(), abs=1e-6)
    va = [p["value"] for p in ra["base_parameters"]]
    vb = [p["value"] for p in rb["base_parameters"]]
    assert va == pytest.approx(vb, rel=1e-5, abs=1e-7)
    status, cap = _run(
        [
            "identify",
            "ur5",
            "--data",
            files["cu"],
            "--torque-scale-from",
            str(gains_json),
            "--torque-scale",
            "2",
        ],
        capsys,
    )
    assert status == 2 and "--torque-scale-from" in cap.err


def test_files_without_accelerations_are_preprocessed(tmp_path, capsys):
    """Smooth Fourier motions logged without ddq at 200 Hz: each file filtered and
    differentiated on its own (the real-log pipeline), the payload still comes out."""
    import pinocchio as pin
    from test_payload import loaded_model

    from manip_id.trajectories import random_trajectory, trajectory_to_configuration

    ur5 = get_robot("ur5")
    payload = make_payload()
    m0, m1 = loaded_model(ur5, "tool0", payload)
    paths = []
    for seed, model in ((0, m0), (1, m1)):
        traj = random_trajectory(ur5, harmonics=5, seed=seed)
        t = np.arange(0, 20.0, 1 / 200.0)
        angles, dq, ddq = traj.sample(t)
        q = trajectory_to_configuration(ur5, angles)
        data = model.createData()
        tau = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(t.size)])
        path = tmp_path / f"run{seed}.npz"
        np.savez(path, t=t, q=q, dq=dq, tau=tau, joint_names=np.array(ur5.dof_names))
        paths.append(str(path))
    out = tmp_path / "p.json"
    status, cap = _run(
        [
            "payload",
            "ur5",
            "--unloaded",
            paths[0],
            "--loaded",
            paths[1],
            "--frame",
            "tool0",
            "--json",
            str(out),
        ],
        capsys,
    )
    assert status == 0, cap.err
    doc = json.loads(out.read_text())
    p = doc["payload"]
    assert doc["preprocess"][0]["preprocess"]["cutoff"] == 3.0
    assert len(doc["data_quality"]["loaded"]) == 1
    assert p["mass"] == pytest.approx(payload.mass, rel=0.01)
    assert p["com"] == pytest.approx(payload.lever.tolist(), abs=0.005)


def test_payload_parses_a_csv_once_and_equals_its_npz(files, tmp_path, monkeypatch, capsys):
    """The pre-fit audit records the CSV rows it parses; the scans read them back."""
    csvs = {k: str(save_dataset(load_dataset(files[k]), tmp_path / f"{k}.csv")) for k in "ul"}
    monkeypatch.setattr(csv_module, "_reader_of", lambda path, delimiter: "numpy")
    rows: list[int] = []
    tables = csv_module.CsvSource._tables

    def counted(self, chunk, reader=None):
        for first, table in tables(self, chunk, reader):
            rows.append(table.shape[0])
            yield first, table

    monkeypatch.setattr(csv_module.CsvSource, "_tables", counted)
    docs = {}
    for fmt, paths in (("csv", csvs), ("npz", files)):
        out = tmp_path / f"{fmt}.json"
        argv = ["payload", "ur5", "--unloaded", paths["u"], "--loaded", paths["l"]]
        status, cap = _run([*argv, "--frame", "tool0", "--json", str(out)], capsys)
        assert status == 0, cap.err
        docs[fmt] = json.loads(out.read_text())["payload"]
        if fmt == "csv":
            assert sum(rows) == 1000  # the 500 rows of each file parsed once
    for key in ("mass", "com", "inertia"):
        np.testing.assert_allclose(docs["csv"][key], docs["npz"][key], rtol=1e-12, atol=1e-15)
