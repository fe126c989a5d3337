"""Excitation design (``design_excitation``, ``manip-id excite``), checked against independent
computations: the written file re-read and re-checked at 1 kHz against the URDF limits,
torques from ``pinocchio.rnea``, clearances from ``pinocchio.computeDistances`` on the
robot's own (mesh) geometry plus the world, gradients against central differences."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id import load_dataset
from manip_id.cli import main
from manip_id.errors import InputError
from manip_id.trajectories import RestFourier, World, format_of, write_trajectory
from manip_id.trajectories.design import _Objective
from manip_id.trajectories.excitation import base_columns
from manip_id.trajectories.fourier import trajectory_to_configuration
from manip_id.trajectories.information import InformationModel, criterion_value
from manip_id.trajectories.world import CollisionScene

UR5_START = "0,-1.57,1.2,-1.2,-1.57,0"


def test_rest_family_starts_and_ends_at_rest_in_the_start_pose():
    rng = np.random.default_rng(0)
    start = np.array([0.3, -1.0, 0.5])
    fam = RestFourier(start, 4, 2 * np.pi / 7.0)
    traj = fam.trajectory(rng.standard_normal(fam.n_free))
    for t in (0.0, 7.0, 14.0):  # the FourierTrajectory's own analytic sampling
        q, dq, ddq = traj.sample(t)
        np.testing.assert_allclose(q, start, atol=1e-12)
        np.testing.assert_allclose(dq, 0.0, atol=1e-12)
        np.testing.assert_allclose(ddq, 0.0, atol=1e-12)
    _, dq, _ = traj.sample(np.linspace(0, 7, 50))
    assert np.abs(dq).max() > 0.1  # it moves in between
    with pytest.raises(InputError, match="at least 2 harmonics"):
        RestFourier(start, 1, 1.0)


@pytest.mark.parametrize("kind", ["d", "cond", "e"])
def test_criterion_gradient_matches_central_differences(kind):
    robot = get_robot("ur5", friction="viscous,offset", armature=True)  # smooth joint terms
    base = base_columns(robot)
    info = InformationModel(robot, base, np.ones(robot.nv))
    fam = RestFourier(np.array([0.2, -1.2, 1.0, -1.0, -1.5, 0.3]), 3, 2 * np.pi / 5.0)
    t = np.arange(40) * 5.0 / 40
    obj = _Objective(info, fam, t, np.zeros((base.size, base.size)), 1.0, kind)
    z = 0.4 * np.random.default_rng(1).standard_normal(fam.n_free)
    _, g = obj.value_and_gradient(z)
    h = 1e-4  # eigenvalues of F (cond ~1e7) carry ~1e-9 relative rounding: not smaller
    for i in np.random.default_rng(2).choice(fam.n_free, 8, replace=False):
        e = np.zeros_like(z)
        e[i] = h
        fd = (obj.value(z + e) - obj.value(z - e)) / (2 * h)
        assert g[i] == pytest.approx(fd, rel=1e-4, abs=2e-6)


def test_d_criterion_is_minus_log_det_of_the_stacked_regressor():
    robot = get_robot("ur5")
    base = base_columns(robot)
    rng = np.random.default_rng(3)
    ang, dq, ddq = rng.uniform(-1, 1, (3, 30, robot.nv))
    Y = np.vstack([pin.computeJointTorqueRegressor(robot.model, robot.model.createData(),
                   trajectory_to_configuration(robot, a), v, w)[:, base]
                   for a, v, w in zip(ang, dq, ddq, strict=True)])  # fmt: skip
    info = InformationModel(robot, base, np.full(robot.nv, 2.0))
    F = info.information(info.matrix(ang, dq, ddq))
    value, _ = criterion_value(F, "d")
    assert value == pytest.approx(-np.linalg.slogdet(Y.T @ Y / 4.0)[1], rel=1e-10)


def test_clearance_gradient_matches_central_differences():
    robot = get_robot("panda")
    world = World.from_dict({"plane": [{"normal": [0, 0, 1], "offset": -0.01}]})
    scene = CollisionScene(robot, world)
    q = robot.neutral() + np.array([0.3, 0.8, -0.2, -1.8, 0.4, 1.5, 0.2])
    best, g = scene.closest(q, gradient=True)
    h = 1e-6
    fd = [(scene.closest(q + h * e)[0].distance - scene.closest(q - h * e)[0].distance) / (2 * h)
          for e in np.eye(robot.nv)]  # fmt: skip
    np.testing.assert_allclose(g, fd, atol=1e-6)


@pytest.mark.parametrize(
    "doc, message",
    [
        ({"box": [{"size": [1, 1], "position": [0, 0, 0]}]}, "size must be 3 numbers"),
        ({"sphere": [{"radius": -1, "position": [0, 0, 0]}]}, "radius must be positive"),
        ({"plane": [{"normal": [0, 0, 1]}]}, "missing \\['offset'\\]"),
        ({"cone": []}, "expected tables plane, box, sphere, cylinder"),
    ],
)
def test_world_file_errors_say_what_was_expected(doc, message):
    with pytest.raises(InputError, match=message):
        World.from_dict(doc)


def _independent_scene(robot, plane_offset: float):
    """The robot's own mesh geometry, the SRDF's disabled pairs and the table as a halfspace:
    built here with Pinocchio and coal, not through the design code."""
    import coal

    geom = robot.collision_model.copy()
    n = len(geom.geometryObjects)
    table = coal.Halfspace(np.array([0.0, 0.0, 1.0]), plane_offset)
    geom.addGeometryObject(pin.GeometryObject("table", 0, 0, pin.SE3.Identity(), table))
    geom.addAllCollisionPairs()
    srdf = Path(robot.source).parents[1] / "srdf" / "ur5.srdf"  # example-robot-data's layout
    pin.removeCollisionPairs(robot.model, geom, str(srdf))
    keep = []
    for cp in geom.collisionPairs:
        a, b = sorted((cp.first, cp.second))
        ja, jb = geom.geometryObjects[a].parentJoint, geom.geometryObjects[b].parentJoint
        if b == n:  # the table: links past the first moving joint
            if ja > 1:
                keep.append((a, b))
        elif ja != jb and robot.model.parents[ja] != jb and robot.model.parents[jb] != ja:
            keep.append((a, b))
    geom.removeAllCollisionPairs()
    for a, b in keep:
        geom.addCollisionPair(pin.CollisionPair(a, b))
    return geom


def test_excite_writes_a_trajectory_within_every_limit_and_clear_of_the_table(tmp_path, capsys):
    robot = get_robot("ur5")
    (tmp_path / "table.toml").write_text("[[plane]]\nnormal = [0, 0, 1]\noffset = -0.01\n")
    out, js = tmp_path / "traj.csv", tmp_path / "design.json"
    argv = ["excite", "ur5", "--duration", "4", "--harmonics", "3", "--start", UR5_START,
            "--world", tmp_path / "table.toml", "--out", out, "--json", js, "--starts", "3",
            "--maxiter", "15", "--clearance", "0.03"]  # fmt: skip
    status = main([str(a) for a in argv])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    assert "min clearance" in captured.out and "criterion d" in captured.out
    d = load_dataset(out)  # the package's own CSV reader
    assert d.joint_names == tuple(robot.dof_names) and d.n_samples == 4001  # 1 kHz
    m = robot.model
    assert np.all(d.q >= m.lowerPositionLimit) and np.all(d.q <= m.upperPositionLimit)
    assert np.all(np.abs(d.dq) <= m.velocityLimit)
    data = m.createData()
    tau = np.array([pin.rnea(m, data, *s) for s in zip(d.q, d.dq, d.ddq, strict=True)])
    np.testing.assert_allclose(d.tau, tau, atol=1e-6)
    assert np.all(np.abs(tau) <= m.effortLimit)
    # rest at both ends, in the start pose
    start = np.array([float(x) for x in UR5_START.split(",")])
    for k in (0, -1):
        np.testing.assert_allclose(d.q[k], start, atol=1e-9)
        np.testing.assert_allclose(d.dq[k], 0.0, atol=1e-9)
        np.testing.assert_allclose(d.ddq[k], 0.0, atol=1e-9)
    # velocities are the derivative of the positions (an independent check of the file)
    np.testing.assert_allclose(np.gradient(d.q, d.t, axis=0)[1:-1], d.dq[1:-1], atol=2e-3)
    # clearance on the robot's meshes (the hulls the design used contain them)
    geom = _independent_scene(robot, -0.01)
    gdata = pin.GeometryData(geom)
    least = np.inf
    for q in d.q[::40]:
        pin.computeDistances(m, data, geom, gdata, q)
        least = min(least, min(r.min_distance for r in gdata.distanceResults))
    assert least >= 0.03 - 1e-9
    doc = json.loads(js.read_text())["excitation"]
    assert doc["min_clearance"] <= least + 1e-4  # hulls contain the meshes (GJK tolerance)
    assert set(doc["limit_usage"]) == {"position", "velocity", "acceleration", "torque"}
    assert doc["criterion"] < doc["criterion_random"]
    # refuses to replace its output without --force
    assert main([str(a) for a in argv]) == 2
    assert "exists; give --force" in capsys.readouterr().err
    # simulate along the design: noise-free torques are rnea on the same motion
    sim = tmp_path / "sim"
    argv = ["simulate", "ur5", "--trajectory", js, "--out", sim, "--files", "1", "--noise", "0",
            "--rate", "1000"]  # fmt: skip
    assert main([str(a) for a in argv]) == 0, capsys.readouterr().err
    log = load_dataset(sim / "run_0.npz")
    np.testing.assert_allclose(log.q, d.q, atol=1e-8)  # the CSV holds 10 digits
    np.testing.assert_allclose(log.tau, d.tau, atol=1e-6)


def test_designed_motion_is_more_informative_than_random_ones_of_the_family():
    from manip_id.trajectories import DesignOptions, design_excitation

    robot = get_robot("ur5")
    start = np.array([float(x) for x in UR5_START.split(",")])
    opts = DesignOptions(harmonics=3, start=start, starts=3, maxiter=15, rate=100.0,
                         self_collision=False)  # fmt: skip
    design = design_excitation(robot, 4.0, options=opts)
    base = base_columns(robot)

    def logdet(traj):  # stacked regressor of pinocchio, 400 samples
        t = np.linspace(0, 4, 400, endpoint=False)
        a, v, w = traj.sample(t)
        data = robot.model.createData()
        scale = 1.0 / (opts.noise * robot.effort_limit)
        Y = np.vstack([
            scale[:, None] * pin.computeJointTorqueRegressor(robot.model, data, q, vk, wk)[:, base]
            for q, vk, wk in zip(a, v, w, strict=True)
        ])  # fmt: skip
        return np.linalg.slogdet(Y.T @ Y)[1]

    fam = RestFourier(start, 3, 2 * np.pi / 4.0)
    rng = np.random.default_rng(7)
    lo, hi = robot.model.lowerPositionLimit, robot.model.upperPositionLimit
    room = 0.9 * np.minimum(hi - start, start - lo)  # [rad]
    random_values = []
    for _ in range(5):  # random members of the family, scaled into the same limits
        z = rng.standard_normal(fam.n_free)
        a, v, _ = fam.trajectory(z).sample(np.linspace(0, 4, 2000))
        s = min(
            np.min(room / np.abs(a - start).max(axis=0)),
            np.min(0.9 * robot.model.velocityLimit / np.abs(v).max(axis=0)),
        )
        random_values.append(logdet(fam.trajectory(s * z)))
    assert logdet(design.trajectory) > max(random_values)


@pytest.mark.parametrize("fmt", ["yaml", "urscript", "json", "npz", "mcap"])
def test_every_output_format_parses_back(tmp_path, fmt):
    rng = np.random.default_rng(0)
    t = np.linspace(0, 1, 11)
    q, dq, ddq, tau = rng.standard_normal((4, 11, 6))
    names = [f"j{k}" for k in range(6)]
    path = tmp_path / f"traj.{fmt}"
    write_trajectory(path, fmt, t, q, dq, ddq, tau, names)
    if fmt == "yaml":
        import yaml

        doc = yaml.safe_load(path.read_text())
        assert doc["joint_names"] == names and len(doc["points"]) == 11
        p = doc["points"][7]
        np.testing.assert_allclose(p["positions"], q[7], rtol=1e-9)
        np.testing.assert_allclose(p["accelerations"], ddq[7], rtol=1e-9)
        assert p["time_from_start"]["sec"] + p["time_from_start"][
            "nanosec"
        ] * 1e-9 == pytest.approx(0.7)
    elif fmt == "urscript":
        lines = path.read_text().splitlines()
        assert lines[0].startswith("def ") and "movej(" in lines[2]
        servo = [ln for ln in lines if ln.strip().startswith("servoj(")]
        assert len(servo) == 11 and "t=0.1," in servo[0]
        row = [float(x) for x in servo[3].split("[")[1].split("]")[0].split(",")]
        np.testing.assert_allclose(row, q[3], rtol=1e-9)
    elif fmt == "json":
        doc = json.loads(path.read_text())
        np.testing.assert_allclose(doc["tau"], tau)
    elif fmt == "mcap":
        from rosbags.highlevel import AnyReader

        assert format_of(path) == "mcap"
        with AnyReader([path]) as reader:
            (msg,) = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()]
        assert list(msg.joint_names) == names and len(msg.points) == 11
        np.testing.assert_array_equal(msg.points[7].velocities, dq[7])
        assert msg.points[7].time_from_start.nanosec == 700_000_000
    else:
        d = load_dataset(path)
        np.testing.assert_allclose(d.ddq, ddq)
        assert d.joint_names == tuple(names)


def test_sequential_design_predicts_the_std_of_the_combined_data():
    _sequential_design()


def _sequential_design():
    """A design after a poor earlier log (its information built here from pinocchio's
    regressor); returns it with the relative std before and after computed here and the
    mask of the parameters the earlier log left poorly identified."""
    from manip_id.identifiability import analyze
    from manip_id.trajectories import DesignOptions, PriorInformation, design_excitation

    robot = get_robot("ur5")
    an = analyze(robot, seed=0)
    base = np.asarray(an.base.independent)
    sigma = 0.01 * robot.effort_limit  # [N m]
    data = robot.model.createData()

    def information(angles, dq, ddq):  # pinocchio's regressor, stacked and weighted
        Y = np.vstack([
            pin.computeJointTorqueRegressor(robot.model, data, a, v, w)[:, base] / sigma[:, None]
            for a, v, w in zip(angles, dq, ddq, strict=True)
        ])  # fmt: skip
        return Y.T @ Y

    rng = np.random.default_rng(4)  # a poor earlier log: small motions of three joints
    n = 300
    angles = np.array(UR5_START.split(","), float) + 0.05 * rng.standard_normal((n, 6))
    angles[:, 3:] = angles[0, 3:]
    dq, ddq = 0.2 * rng.standard_normal((2, n, 6))
    dq[:, 3:] = ddq[:, 3:] = 0.0
    theta = robot.nominal_parameters
    ref = theta[base] + an.base.K @ theta[an.base.dependent]
    F0 = information(angles, dq, ddq) + np.diag(1.0 / np.maximum(np.abs(ref), 1e-3) ** 2)
    prior = PriorInformation(F0, base, list(an.base.base_names), ref, sigma)
    opts = DesignOptions(harmonics=3, start=angles[0], starts=2, maxiter=10, rate=100.0,
                         self_collision=False)  # fmt: skip
    design = design_excitation(robot, 4.0, options=opts, prior=prior)
    _, a, v, w = design.samples()
    expected = np.sqrt(np.diag(np.linalg.inv(F0 + information(a[:-1], v[:-1], w[:-1]))))
    np.testing.assert_allclose(design.predicted_std, expected, rtol=0.05)
    before = np.sqrt(np.diag(np.linalg.inv(F0)))
    keep = np.abs(ref) > 1e-3 * np.abs(ref).max()
    poor = keep & (before > 0.1 * np.abs(ref))
    assert poor.sum() >= 3
    assert np.all(design.predicted_std[poor] < before[poor])
    with np.errstate(divide="ignore"):
        return design, before / np.abs(ref), expected / np.abs(ref), poor


def test_sequential_report_names_the_poorly_identified_parameters_before_and_after(tmp_path):
    from manip_id.viz.excite_report import write_excite_report

    design, before, after, poor = _sequential_design()
    robot = get_robot("ur5")
    doc = {"robot": "ur5", "excitation": design.to_dict()}
    write_excite_report(tmp_path / "rep", robot, design, doc, source="previous.json")
    index = (tmp_path / "rep" / "index.html").read_text()
    start = index.index("What does it add to the earlier data?")
    section = index[start : index.index("</table>", start)]
    assert "previous.json" in section
    rows = {}
    for tr in section.split("<tr")[2:]:
        cells = [c.split("</td>")[0] for c in tr.split("<td>")[1:]]
        rows[cells[0]] = (float(cells[1]), float(cells[2]))
    names = design.base_names
    assert {names[i] for i in np.flatnonzero(poor)} <= set(rows)  # every one the prior left
    for name, (shown_before, shown_after) in rows.items():
        i = names.index(name)
        assert shown_before == pytest.approx(100 * before[i], rel=5e-3)
        assert shown_after == pytest.approx(100 * after[i], rel=0.05)


def _series(coefficients: dict, t: np.ndarray):
    """The Fourier series of the design's JSON coefficients, evaluated here (positions,
    velocities, accelerations), shape (N, nv) each."""
    q0, a, b = (np.asarray(coefficients[k], float) for k in ("q0", "a", "b"))
    wf = float(coefficients["wf"])
    w = wf * np.arange(1, a.shape[1] + 1)  # [rad/s] per harmonic
    s, c = np.sin(np.outer(t, w)), np.cos(np.outer(t, w))  # (N, L)
    q = q0 + s @ (a / w).T - c @ (b / w).T
    return q, c @ a.T + s @ b.T, -(s * w) @ a.T + (c * w) @ b.T


def _usage_table(index: str) -> dict:
    """The limit-usage table of the report's index.html: joint -> {column: text}."""
    from html.parser import HTMLParser

    start = index.index("Does it stay within the limits?")
    table = index[index.index("<table>", start) : index.index("</table>", start)]

    class Cells(HTMLParser):
        rows: list[list[str]] = []

        def handle_starttag(self, tag, attrs):
            if tag == "tr":
                self.rows.append([])

        def handle_data(self, data):
            if self.rows and data.strip():
                self.rows[-1].append(data.strip())

    p = Cells()
    p.rows = []
    p.feed(table)
    head, *body = p.rows
    return {r[0]: dict(zip(head[1:], r[1:], strict=True)) for r in body}


def test_excite_report_and_mcap_agree_with_independent_checks(tmp_path, capsys):
    from rosbags.highlevel import AnyReader

    robot = get_robot("ur5")
    m, margin, rate = robot.model, 0.05, 200.0
    (tmp_path / "table.toml").write_text("[[plane]]\nnormal = [0, 0, 1]\noffset = -0.01\n")
    out, js, rep = tmp_path / "traj.mcap", tmp_path / "design.json", tmp_path / "rep"
    argv = ["excite", "ur5", "--duration", "4", "--harmonics", "3", "--start", UR5_START,
            "--world", tmp_path / "table.toml", "--out", out, "--json", js, "--report", rep,
            "--starts", "2", "--maxiter", "10", "--rate", rate]  # fmt: skip
    assert main([str(a) for a in argv]) == 0, capsys.readouterr().err
    doc = json.loads(js.read_text())["excitation"]
    # the MCAP bag: one JointTrajectory, read back with rosbags' own reader
    with AnyReader([out]) as reader:
        (conn,) = reader.connections
        assert conn.msgtype == "trajectory_msgs/msg/JointTrajectory"
        assert conn.topic == "/joint_trajectory_controller/joint_trajectory"
        (msg,) = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()]
    assert list(msg.joint_names) == list(robot.dof_names) and len(msg.points) == 801
    t = np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in msg.points])
    np.testing.assert_allclose(t, np.arange(801) / rate, atol=1e-9)
    q, dq, ddq = (np.array([getattr(p, f) for p in msg.points])
                  for f in ("positions", "velocities", "accelerations"))  # fmt: skip
    for got, want in zip((q, dq, ddq), _series(doc["coefficients"], t), strict=True):
        np.testing.assert_allclose(got, want, atol=1e-9)
    assert all(p.effort.size == 0 for p in msg.points)
    # limit usage: the JSON against the bag's samples and the URDF, then the report's table
    data = m.createData()
    tau = np.array([pin.rnea(m, data, *s) for s in zip(q, dq, ddq, strict=True)])
    lo, hi = m.lowerPositionLimit, m.upperPositionLimit
    expected = {
        "position": np.abs(q - 0.5 * (lo + hi)).max(axis=0) / ((1 - 2 * margin) * (hi - lo) / 2),
        "velocity": np.abs(dq).max(axis=0) / ((1 - margin) * m.velocityLimit),
        "torque": np.abs(tau).max(axis=0) / ((1 - margin) * m.effortLimit),
    }
    table = _usage_table((rep / "index.html").read_text())
    assert list(table) == list(robot.dof_names)
    for kind, values in doc["limit_usage"].items():
        for j, name in enumerate(robot.dof_names):
            shown = table[name][f"{kind} [%]"]
            if values[name] is None:
                assert kind == "acceleration" and shown == "no limit"
                continue
            assert float(shown) == pytest.approx(100 * values[name], rel=5e-3)
            if kind in expected:
                assert values[name] == pytest.approx(expected[kind][j], rel=1e-6)
    # the closest approach: its witness points are min_clearance apart
    p1, p2 = np.array(doc["closest_points"])
    assert np.linalg.norm(p2 - p1) == pytest.approx(doc["min_clearance"], abs=1e-6)
    if "plane0" in doc["closest_pair"]:
        assert (p2 if doc["closest_pair"][1] == "plane0" else p1)[2] == pytest.approx(-0.01)
    scene = (rep / "scene.html").read_text()
    assert "closest approach" in scene and doc["closest_pair"][0] in scene and "plane0" in scene
    for name in ("limit_usage", "motion", "predicted_std"):
        assert (rep / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert json.loads((rep / "result.json").read_text())["excitation"] == doc
    # the report folder is not replaced without --force
    argv[argv.index(out)] = tmp_path / "other.mcap"
    argv[argv.index(js)] = tmp_path / "other.json"
    assert main([str(a) for a in argv]) == 2
    assert "--force" in capsys.readouterr().err


def test_sigma_without_from_is_refused_before_work(tmp_path, capsys):
    """--sigma sets the identified model's torque margin: without --from it has no model."""
    out = tmp_path / "t.csv"
    argv = ["excite", "ur5", "--duration", "4", "--sigma", "2", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--sigma applies with --from" in err[0], err
    assert not out.exists()
