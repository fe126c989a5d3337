"""The hardening catalogue, fourth round (issue 41): each case through the CLI or the API.

- Publication without a race: a file saved into a ``--force`` folder while the run works
  survives (named in a warning); payload log names are unique by construction; a killed
  run's staging folder is named by the next run.
- Budgets before work: simulate's log count, disk and absurd numbers refused at their
  option; quoted user values cut to a bounded length.
- External documents validated at the door, by name (result JSON, drift references,
  sidecars), with a property test feeding them mutated documents.
- The API: ``CollisionMonitor`` per-step checks and its dropout policy, ``FrictionShapes``,
  ``repair_body``.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from manip_id.cli import main
from manip_id.errors import OutputWarning

ENV = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}


@pytest.fixture
def work(tmp_path, monkeypatch):
    """A working folder (the current directory)."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _run(capsys, *argv) -> tuple[int, str, str]:
    status = main([str(a) for a in argv])
    out = capsys.readouterr()
    return status, out.out, out.err


def _error(capsys, *argv) -> str:
    """The one error line of a refused command (exit 2, no traceback)."""
    status, _, err = _run(capsys, *argv)
    lines = [line for line in err.splitlines() if line.startswith("manip-id: error:")]
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def _dead_pid() -> int:
    """The id of a process that has exited (and was reaped)."""
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


# ------------------------------------------------------- publication without a race
def test_a_file_saved_into_a_force_folder_during_the_build_survives(work):
    from manip_id._io import OutputSet

    assert main(["rank", "msd", "--report", "rep", "--samples", "30"]) == 0
    before = sorted(p.name for p in (work / "rep").iterdir())

    def fill(tmp: Path) -> None:
        (tmp / "new.txt").write_text("report\n")
        (work / "rep" / "thesis.tex").write_text("years of work\n")  # the user, meanwhile
        (work / "rep" / "new.txt").write_text("my own new.txt\n")  # same name as ours

    with OutputSet() as out:
        rep = out.report(work / "rep", force=True)
        rep.build(fill)
        with pytest.warns(OutputWarning) as record:
            out.publish()
    names = sorted(p.name for p in (work / "rep").iterdir())
    assert (work / "rep" / "thesis.tex").read_text() == "years of work\n"
    assert (work / "rep" / "new.txt").read_text() == "report\n"
    assert (work / "rep" / "new.txt.user-1").read_text() == "my own new.txt\n"
    assert not set(before) - {".manip-id-report.json"} & set(names) - {"new.txt"}
    text = " ".join(str(w.message) for w in record)
    assert "thesis.tex" in text and "new.txt.user-1" in text
    assert not [p for p in os.listdir(work) if ".old-" in p or ".tmp-" in p]


@pytest.mark.slow
def test_simulate_force_keeps_a_file_the_user_saves_mid_run(work):
    args = ["simulate", "msd", "--out", "sim", "--files", "3", "--duration", "400"]
    assert main(args) == 0
    cmd = [sys.executable, "-m", "manip_id", *args, "--force"]
    proc = subprocess.Popen(cmd, cwd=work, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while not list(work.glob(".sim.tmp-*")) and proc.poll() is None:
            assert time.monotonic() < deadline, "the staging folder never appeared"
            time.sleep(0.02)
        (work / "sim" / "notes.txt").write_text("mine\n")
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert (work / "sim" / "notes.txt").read_text() == "mine\n"
    assert b"notes.txt" in err and b"warning" in err
    assert (work / "sim" / "run_2.npz").is_file()


def test_payload_masses_equal_to_six_digits_get_two_files(work, capsys):
    status, out, err = _run(
        capsys, "simulate", "msd", "--out", "sim", "--files", "1", "--duration", "1",
        "--payload", "1,1.0000001",
    )  # fmt: skip
    assert status == 0, err
    import json

    truth = json.loads((work / "sim" / "truth.json").read_text())
    names = [f["name"] for f in truth["files"]]
    assert len(set(names)) == 3 and all((work / "sim" / n).is_file() for n in names)
    masses = {f["name"]: f["payload_mass"] for f in truth["files"]}
    from manip_id import load_dataset

    # the two loaded logs differ (different masses, different seeds): none overwrote another
    a, b = (load_dataset(work / "sim" / n) for n in names[1:])
    assert masses[names[1]] != masses[names[2]] and not np.allclose(a.tau, b.tau)


def test_a_mass_given_twice_is_refused_before_work(work, capsys):
    line = _error(capsys, "simulate", "msd", "--out", "sim", "--payload", "2,2.0")
    assert "twice" in line and not (work / "sim").exists()


def test_a_killed_runs_staging_folder_is_named_by_the_next_run(work, capsys):
    pid = _dead_pid()
    stale = work / f".sim.tmp-{pid}-abcd"
    stale.mkdir()
    (stale / "run_0.npz").write_bytes(b"half")
    status, _, err = _run(capsys, "simulate", "msd", "--out", "sim", "--files", "1",
                          "--duration", "1")  # fmt: skip
    assert status == 0
    assert str(stale.name) in err and f"process {pid}" in err
    assert (stale / "run_0.npz").read_bytes() == b"half"  # named, never deleted


def test_a_live_runs_staging_folder_is_not_named(work, capsys):
    live = work / f".sim.tmp-{os.getppid()}-abcd"
    live.mkdir()
    status, _, err = _run(capsys, "simulate", "msd", "--out", "sim", "--files", "1",
                          "--duration", "1")  # fmt: skip
    assert status == 0 and live.name not in err


# ------------------------------------------------------------- budgets before work
@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--files", "1000000000"], "at most 10000"),
        (["--files", "6000", "--payload", "1"], "at most 10000"),
        (["--noise", "1e300"], "--noise"),
        (["--payload", "1e9"], "--payload"),
        (["--drive-gains", "1e-300"], "--drive-gains"),
        (["--drive-gains", "1,1e300"], "--drive-gains"),
    ],
)
def test_simulate_refuses_absurd_requests_at_their_option(work, capsys, argv, match):
    t0 = time.process_time()
    line = _error(capsys, "simulate", "msd", "--out", "sim", *argv)
    assert match in line and not (work / "sim").exists()
    assert time.process_time() - t0 < 60  # refused up front (a generous guard, not a timing)


def test_simulate_refuses_a_folder_larger_than_the_free_disk(work, capsys, monkeypatch):
    import shutil
    from collections import namedtuple

    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10**9, 10**9 - 10**6, 10**6))
    line = _error(capsys, "simulate", "msd", "--out", "sim", "--files", "2")
    assert "GB are free" in line and not (work / "sim").exists()


def test_a_100mb_header_cell_gives_a_short_error(work, capsys):
    (work / "big.csv").write_text("x" * 10_000_000 + ",q_a\n0,1\n")
    line = _error(capsys, "identify", "msd", "--data", "big.csv")
    assert len(line) < 2000 and "10000000 characters" in line


def test_a_byte_order_mark_does_not_hide_the_first_column(work, capsys):
    from manip_id import load_dataset

    rows = "".join(f"{k / 100},{k / 1000},0.1,{k / 50}\n" for k in range(20))
    (work / "bom.csv").write_text("\ufefft,q_cart,dq_cart,tau_cart\n" + rows, encoding="utf-8")
    (work / "plain.csv").write_text("t,q_cart,dq_cart,tau_cart\n" + rows)
    a, b = load_dataset(work / "bom.csv"), load_dataset(work / "plain.csv")
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_array_equal(a.tau, b.tau)


def test_a_long_user_value_in_a_cli_message_is_cut(work, capsys):
    for value in ("-1," + "1" * 100_000, "x" * 100_000, "1," * 50_000):
        line = _error(capsys, "simulate", "msd", "--out", "sim", f"--payload={value}")
        assert len(line) < 1000, line[:200]


# ------------------------------------------------------------ robots read from the text
def _chain_urdf(n: int, mimic: bool = False) -> str:
    """A serial chain of ``n`` revolute joints (joint ``j1`` mimics ``j0`` with ``mimic``)."""
    links = "".join(
        f'<link name="l{k}"><inertial><mass value="1"/><origin xyz="0 0 0.1"/>'
        f'<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>'
        for k in range(n + 1)
    )
    joints = "".join(
        f'<joint name="j{k}" type="revolute"><parent link="l{k}"/><child link="l{k + 1}"/>'
        f'<origin xyz="0 0 0.2"/><axis xyz="0 1 0"/>'
        f'<limit lower="-3" upper="3" velocity="2" effort="100"/>'
        + ('<mimic joint="j0" multiplier="1"/>' if mimic and k == 1 else "")
        + "</joint>"
        for k in range(n)
    )
    return f'<?xml version="1.0"?><robot name="chain">{links}{joints}</robot>'


def test_a_1000_joint_urdf_is_refused_from_its_text(work, monkeypatch):
    import pinocchio as pin

    from manip_id import load_robot
    from manip_id.errors import RobotError

    (work / "big.urdf").write_text(_chain_urdf(1000))
    built = []
    monkeypatch.setattr(pin, "buildModelFromUrdf", lambda *a, **k: built.append(a))
    with pytest.raises(RobotError, match="1000 movable joints.*limit of 300"):
        load_robot(work / "big.urdf")
    assert built == []  # refused before Pinocchio saw it


def test_a_user_urdf_with_a_moving_mimic_joint_is_refused(work, capsys):
    from manip_id import load_robot

    (work / "m.urdf").write_text(_chain_urdf(3, mimic=True))
    line = _error(capsys, "rank", "m.urdf", "--samples", "30")
    assert "'j1' mimics 'j0'" in line and "lock both" in line
    # locking both ends is the documented way out: the robot then loads with j2 alone
    robot = load_robot(work / "m.urdf", active_joints=["j2"])
    assert robot.nv == 1 and list(robot.joint_names) == ["j2"]


def test_an_example_robot_with_mimic_grippers_is_loaded_with_a_warning():
    from manip_id import load_robot
    from manip_id.errors import RobotWarning

    with pytest.warns(RobotWarning, match="mimics"):
        robot = load_robot("baxter")
    assert robot.nv == 19  # the documented 19 independent joints


# --------------------------------------------------------------------------- the API
def _monitor():
    from manip_id.monitor import CollisionMonitor

    robot = _robot("double_pendulum")
    return robot, CollisionMonitor(robot, robot.nominal_parameters, thresholds=0.5)


def _robot(name):
    from conftest import get_robot

    return get_robot(name)


def _external_torque_run(monitor, robot, dropout: int | None):
    """Residuals of the monitor on a held pose with a 2 N m push on joint 0 from sample 200
    (the torque needed to hold plus the push: tau_ext = -push is what the observer sees)."""
    import pinocchio as pin

    q = np.array([0.3, -0.2])
    g = pin.computeGeneralizedGravity(robot.model, robot.model.createData(), q)
    monitor.reset()
    steps = []
    for k in range(400):
        tau = g - (np.array([2.0, 0.0]) if k >= 200 else 0.0)
        qk = np.full(2, np.nan) if k == dropout else q
        steps.append(monitor.step(qk, np.zeros(2), tau, 0.005))
    return steps


def test_a_dropout_is_skipped_and_does_not_blind_the_monitor():
    robot, monitor = _monitor()
    clean = _external_torque_run(monitor, robot, dropout=None)
    holed = _external_torque_run(monitor, robot, dropout=100)
    assert holed[100].skipped and monitor.dropouts == 1
    assert not any(s.skipped for s in clean)
    # the push is seen after the dropout, as without it: |r_0| -> 2 N m (-tau_ext)
    assert holed[-1].detected[0] and clean[-1].detected[0]
    np.testing.assert_allclose(holed[-1].residual, clean[-1].residual, atol=1e-9)
    np.testing.assert_allclose(clean[-1].residual, [2.0, 0.0], atol=1e-3)


@pytest.mark.parametrize("dt", [-0.01, 0.0, float("nan"), float("inf"), "0.01", True])
def test_the_monitor_refuses_a_bad_time_step_on_every_call(dt):
    from manip_id.errors import InputError

    _, monitor = _monitor()
    with pytest.raises(InputError, match="dt"):
        monitor.step(np.zeros(2), np.zeros(2), np.zeros(2), dt)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"stribeck_velocity": "abc"}, "one real number per DoF"),
        ({"sigmoid_slope": [[1.0, 2.0]]}, "one real number per DoF"),
        ({"sigmoid_shift": [1j, 2]}, "one real number per DoF"),
        ({"stribeck_velocity": [0.1, -1]}, "positive"),
    ],
)
def test_friction_shapes_refuse_bad_values_with_our_error(kwargs, match):
    from manip_id.errors import InputError
    from manip_id.robot.friction import FrictionShapes

    with pytest.raises(InputError, match=match):
        FrictionShapes(**kwargs)


def test_friction_shapes_of_another_size_are_refused_by_the_robot():
    from manip_id import load_robot
    from manip_id.errors import InputError
    from manip_id.robot.friction import FrictionShapes
    from manip_id.robot.model import JointTerms

    terms = JointTerms(viscous=True, coulomb=True, stribeck=True,
                       shapes=FrictionShapes(stribeck_velocity=(0.1, 0.2, 0.3)))  # fmt: skip
    with pytest.raises(InputError, match="3 value.*nv=2"):
        load_robot("double_pendulum").__class__(
            "double_pendulum", load_robot("double_pendulum").model, terms
        )


@pytest.mark.parametrize(
    ("pi", "match"),
    [
        ([1.0 + 1j] + [0.0] * 9, "complex"),
        ([1.0, 0.0, 0.0], "10 parameters"),
        ([1.0, 0, 0, 0, np.nan, 0, 0.1, 0, 0, 0.1], "finite"),
        ("abc", "numeric"),
    ],
)
def test_repair_body_refuses_bad_input_with_our_error(pi, match):
    from manip_id.errors import InputError
    from manip_id.physics.repair import repair_body

    with pytest.raises(InputError, match=match):
        repair_body(pi)


# ------------------------------------------- external documents: a property test of readers
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

BAD_VALUES = ["abc", None, True, [], {}, float("nan"), float("inf"), -1.0, 1e308, [1.0, "x"]]
PROPERTY = settings(max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])  # fmt: skip


@pytest.fixture(scope="module")
def reference_doc(tmp_path_factory) -> dict:
    import json

    folder = tmp_path_factory.mktemp("ref")
    path = folder / "ref.json"
    argv = ["identify", "msd", "--simulate", "--duration", "4", "--json", str(path)]
    assert main(argv) == 0
    return json.loads(path.read_text())


def _read_result(doc: dict):
    """``load_result`` of ``doc`` written to a file: the result, or the DataError."""
    import json
    import tempfile

    from manip_id.errors import DataError
    from manip_id.identification import load_result

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "r.json"
        path.write_text(json.dumps(doc))
        try:
            return load_result(path)
        except DataError as exc:
            assert "\n" not in str(exc) and len(str(exc)) < 1000
            return exc


def _by_name(res) -> dict:
    return dict(zip(res.names, res.estimate.tolist(), strict=True))


@PROPERTY
@given(st.permutations(range(3)))
def test_a_reordered_reference_reads_as_the_same_result(reference_doc, order):
    import copy

    doc = copy.deepcopy(reference_doc)
    rows = doc["base_parameters"]
    assert len(rows) == 3
    doc["base_parameters"] = [rows[i] for i in order]
    res, ref = _read_result(doc), _read_result(reference_doc)
    assert _by_name(res) == _by_name(ref) and list(res.names) == list(ref.names)
    np.testing.assert_array_equal(res.covariance, ref.covariance)


def _paths(doc, prefix=()):
    """Every (path, value) of a JSON document's leaves and objects."""
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield (*prefix, k), v
            yield from _paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc[:4]):
            yield (*prefix, i), v
            yield from _paths(v, (*prefix, i))


@PROPERTY
@given(st.data())
def test_a_mutated_result_reads_the_same_or_gives_one_clear_error(reference_doc, data):
    import copy

    from manip_id.errors import DataError

    doc = copy.deepcopy(reference_doc)
    paths = [p for p, _ in _paths(doc)]
    path = data.draw(st.sampled_from(paths))
    parent = doc
    for key in path[:-1]:
        parent = parent[key]
    if data.draw(st.booleans()) and isinstance(parent, dict):
        del parent[path[-1]]
    else:
        parent[path[-1]] = data.draw(st.sampled_from(BAD_VALUES))
    res = _read_result(doc)
    if not isinstance(res, DataError):  # a field not read, or one whose change is harmless
        ref = _read_result(reference_doc)
        assert set(res.names) == set(ref.names)


@PROPERTY
@given(st.integers(0, 2), st.floats(-1e3, -1e-12))
def test_a_negative_variance_is_refused(reference_doc, k, value):
    import copy

    from manip_id.errors import DataError

    doc = copy.deepcopy(reference_doc)
    doc["covariance"][k][k] = value
    res = _read_result(doc)
    assert isinstance(res, DataError) and "negative variance" in str(res)


@pytest.fixture(scope="module")
def sidecar_doc() -> dict:
    from manip_id.export.sidecar import sidecar_document

    robot = _robot("msd")
    return sidecar_document(robot, robot.nominal_parameters, target="urdf", source="msd")


@PROPERTY
@given(st.data())
def test_a_mutated_sidecar_reads_the_same_or_gives_one_clear_error(sidecar_doc, data):
    import copy
    import json
    import tempfile

    from manip_id.errors import InputError
    from manip_id.robot.sidecar import MAX_TERM, read_sidecar

    doc = copy.deepcopy(sidecar_doc)
    paths = [p for p, _ in _paths(doc) if p[0] in ("joints", "parameters", "active_joints")]
    path = data.draw(st.sampled_from(paths))
    parent = doc
    for key in path[:-1]:
        parent = parent[key]
    parent[path[-1]] = data.draw(st.sampled_from(BAD_VALUES))
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "s.json"
        p.write_text(json.dumps(doc))
        try:
            out = read_sidecar(p)
        except InputError as exc:
            assert "\n" not in str(exc) and len(str(exc)) < 1000
            return
    # accepted: then every joint term is a finite number within the bound
    for terms in out["joints"].values():
        for v in terms.values():
            assert isinstance(v, (int, float)) and np.isfinite(v) and abs(v) <= MAX_TERM
    for row in out.get("parameters", []):
        assert np.isfinite(row["value"]) and abs(row["value"]) <= 1e12


# ------------------------------------------------------------------------ repair outputs
def test_repair_json_onto_the_sidecar_is_refused(work, capsys):
    line = _error(capsys, "repair", "msd", "out.urdf", "--json", "out.identified.json")
    assert "sidecar" in line and not list(work.iterdir())


def test_repair_into_a_missing_folder_is_refused(work, capsys):
    line = _error(capsys, "repair", "msd", "missing/out.urdf")
    assert "does not exist" in line and not (work / "missing").exists()


def test_validate_equal_to_data_is_said(work, capsys):
    assert main(["simulate", "msd", "--out", "sim", "--files", "1", "--duration", "4"]) == 0
    capsys.readouterr()
    status, _, err = _run(capsys, "identify", "msd", "--data", "sim/run_0.npz",
                          "--validate", "./sim/run_0.npz")  # fmt: skip
    assert status == 0 and "is also --data" in err and "training data" in err


def test_thresholds_of_another_robot_are_refused_by_joint_names_before_their_gains():
    from manip_id.errors import ModelMismatchError
    from manip_id.monitor import CollisionMonitor, Thresholds

    one = np.ones(1)
    th = Thresholds(dof_names=["cart"], bound=one, noise_bound=one, model_bound=0 * one,
                    gain=25 * one, filter_gain=None, false_alarm=1e-3,
                    methods=["empirical quantile"], rate=0.0, rate_per_joint=0 * one,
                    n_samples=100)  # fmt: skip
    robot = _robot("double_pendulum")
    with pytest.raises(ModelMismatchError, match="double_pendulum moves other joints.*cart"):
        CollisionMonitor(robot, robot.nominal_parameters, th, gain=th.gain)


# ------------------------------------------------------------------------------- MJCF out
def test_an_mjcf_with_a_world_link_and_a_missing_mesh_loads_in_mujoco(work):
    mujoco = pytest.importorskip("mujoco")
    from manip_id import load_robot
    from manip_id.errors import ExportWarning
    from manip_id.export import export_mjcf

    text = _chain_urdf(2).replace('"l2"', '"world"')  # the last link is called world
    missing = work / "nowhere" / "arm.stl"
    text = text.replace(
        '<link name="l1">',
        f'<link name="l1"><visual><geometry><mesh filename="{missing}"/></geometry></visual>',
    )
    (work / "w.urdf").write_text(text)
    robot = load_robot(work / "w.urdf")
    with pytest.warns(ExportWarning, match="'world'.*'world_1'"):
        out = export_mjcf(robot, robot.nominal_parameters, work / "w.xml")
    model = mujoco.MjModel.from_xml_path(str(work / "w.xml"))  # loads: no missing file
    assert model.nbody == 3 and str(missing) in out.skipped


def test_consistent_with_the_fleet_path_is_refused_as_documented(work, capsys):
    assert main(["simulate", "msd", "--out", "sim", "--files", "1", "--duration", "4"]) == 0
    capsys.readouterr()
    line = _error(capsys, "identify", "msd", "--data", "sim/run_0.npz", "--per-file",
                  "--consistent")  # fmt: skip
    assert "--scheduler or --per-file" in line
    docs = Path(__file__).resolve().parents[1] / "docs" / "fleet.md"
    assert "`--consistent` does not\ncombine with `--scheduler` or `--per-file`" in docs.read_text()


# ---------------------------------------------------- absurd numbers named at their option
def test_a_torque_scale_of_1e308_is_refused_at_the_option(work, capsys):
    assert main(["simulate", "msd", "--out", "sim", "--files", "1", "--duration", "4"]) == 0
    capsys.readouterr()
    line = _error(capsys, "identify", "msd", "--data", "sim/run_0.npz", "--torque-scale", "1e308")
    assert "--torque-scale" in line and "1e+308" in line


def test_a_urdf_mass_of_1e300_is_refused_naming_the_link(work, capsys):
    text = _chain_urdf(2).replace('<mass value="1"/>', '<mass value="1e300"/>', 1)
    (work / "heavy.urdf").write_text(text)
    line = _error(capsys, "simulate", "heavy.urdf", "--out", "sim", "--duration", "1")
    assert "link 'l0'" in line and "mass" in line and not (work / "sim").exists()


def test_a_killed_runs_staged_file_is_named_by_the_next_run(work, capsys):
    pid = _dead_pid()
    stale = work / f".o.json.tmp-{pid}-x1y2.json"
    stale.write_text("{")
    status, _, err = _run(capsys, "rank", "msd", "--samples", "30", "--json", "o.json")
    assert status == 0 and stale.name in err and stale.exists()
    assert not [p for p in os.listdir(work) if ".tmp-" in p and str(os.getpid()) in p]


# ------------------------------------------------- the monitor and the temperature law
TREF = 35.0  # the truth's reference temperature [degC]
FV0, FV1 = np.array([0.3, 0.2]), np.array([-0.006, -0.004])  # [N m s/rad], [N m s/(rad K)]
FC0, FC1 = np.array([0.8, 0.5]), np.array([-0.012, -0.008])  # [N m], [N m/K]
TEMP_LAW = "viscous,coulomb,temperature"


def _hot_record(seed: int, rate: float = 1000.0, duration: float = 2.0):
    """``(t, q, dq, ddq, tau, T)``: Pinocchio's rnea plus the temperature law written out
    in numpy (reference TREF), the temperature drifting 25 -> 45 degC (joint 2 4 K warmer)."""
    import pinocchio as pin

    from manip_id import load_robot
    from manip_id.trajectories import random_trajectory

    robot = load_robot("double_pendulum", friction=())
    t = np.arange(int(duration * rate)) / rate
    q, dq, ddq = random_trajectory(robot, harmonics=4, wf=0.4, seed=seed).sample(t)
    m, d = robot.model, robot.model.createData()
    rigid = np.array([pin.rnea(m, d, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
    temp = 25.0 + 20.0 * t[:, None] / t[-1] + np.array([0.0, 4.0])  # [degC]
    friction = (FV0 + FV1 * (temp - TREF)) * dq + (FC0 + FC1 * (temp - TREF)) * np.sign(dq)
    return t, q, dq, ddq, rigid + friction, temp


def test_the_monitor_runs_the_temperature_law_on_the_measured_temperature():
    from manip_id import load_robot
    from manip_id.errors import MissingTemperatureError
    from manip_id.monitor import CollisionMonitor
    from manip_id.robot.friction import FrictionShapes
    from manip_id.robot.model import JointTerms

    shapes = FrictionShapes(temperature_reference=(TREF, TREF))
    robot = load_robot("double_pendulum", friction=()).with_terms(
        JointTerms(viscous=True, coulomb=True, temperature=True, shapes=shapes)
    )
    theta = robot.nominal_parameters.copy()
    for name, v in (("fv", FV0), ("fc", FC0), ("fvt", FV1), ("fct", FC1)):
        theta[robot.layout.joint_columns(name)] = v
    t, q, dq, _, tau, temp = _hot_record(seed=3)
    mon = CollisionMonitor(robot, theta, gain=25.0, filter_gain=None)
    # no external torque: the residual is the discretization error only
    assert np.abs(mon.run(t, q, dq, tau, temp=temp).residual).max() < 1e-6
    # the same run read 20 K too warm: the friction difference shows (so T is used)
    assert np.abs(mon.run(t, q, dq, tau, temp=temp + 20.0).residual).max() > 0.2
    with pytest.raises(MissingTemperatureError, match="temp"):
        mon.run(t, q, dq, tau)
    mon.reset()
    with pytest.raises(MissingTemperatureError, match="temp"):
        mon.step(q[0], dq[0], tau[0], 0.001)
    # a temperature dropout is skipped like any other
    mon.step(q[0], dq[0], tau[0], 0.001, temp[0])
    assert mon.step(q[1], dq[1], tau[1], 0.001, [np.nan, 30.0]).skipped and mon.dropouts == 1


def test_monitor_cli_with_the_temperature_law_reads_the_logs_temp(work, capsys):
    from manip_id.datasets import Dataset, save_dataset

    names = ("joint1", "joint2")
    for seed, name in ((1, "train"), (2, "calib"), (4, "data")):
        t, q, dq, ddq, tau, temp = _hot_record(seed, rate=200.0, duration=10.0)
        save_dataset(Dataset(t=t, q=q, dq=dq, ddq=ddq, tau=tau, joint_names=names, temp=temp),
                     work / f"{name}.npz")  # fmt: skip
        if name == "data":
            plain = Dataset(t=t, q=q, dq=dq, ddq=ddq, tau=tau, joint_names=names)
            save_dataset(plain, work / "plain.npz")
    argv = ["identify", "double_pendulum", "--friction", TEMP_LAW, "--quiet"]
    assert main([*argv, "--data", "train.npz", "--json", "res.json"]) == 0
    capsys.readouterr()
    mon = ["monitor", "double_pendulum", "--model", "res.json", "--calibrate", "calib.npz"]
    status, out, err = _run(capsys, *mon, "--data", "data.npz", "--json", "mon.json")
    assert status == 0, err
    import json

    doc = json.loads((work / "mon.json").read_text())
    # a model that fits the law (noise-free data): bounds far below the friction's size
    assert max(j["bound"] for j in doc["thresholds"]["joints"]) < 0.05
    line = _error(capsys, *mon, "--data", "plain.npz")
    assert "plain.npz" in line and "temp" in line and "npz" in line


def test_the_monitor_refuses_the_load_law_in_one_line(work, capsys):
    from manip_id import load_robot
    from manip_id.errors import InputError
    from manip_id.monitor import CollisionMonitor

    robot = load_robot("double_pendulum", friction="viscous,load")
    with pytest.raises(InputError, match="cannot run the load friction law"):
        CollisionMonitor(robot, robot.nominal_parameters)


# ------------------------------------------------------------ the online estimators
def _estimators():
    from manip_id.estimators.concurrent import ConcurrentLearningEstimator
    from manip_id.estimators.drem import DREMEstimator
    from manip_id.estimators.online import GradientEstimator, RLSEstimator

    return {
        "gradient": lambda: GradientEstimator(np.zeros(3), [1.0, 2.0, 0.5]),
        "normalized": lambda: GradientEstimator(np.zeros(3), 1.0, normalized=True),
        "rls": lambda: RLSEstimator(np.zeros(3), 10.0, forgetting=0.99),
        "drem": lambda: DREMEstimator(np.zeros(3)),
        "concurrent": lambda: ConcurrentLearningEstimator(np.zeros(3), 1.0),
    }


@pytest.mark.parametrize("law", list(_estimators()))
def test_an_estimators_dropout_is_the_sample_left_out(law):
    """Skipping a NaN sample (the documented policy) gives the estimate of the same run
    without that sample, and the time still advances by its dt."""
    rng = np.random.default_rng(0)
    theta = np.array([1.0, -2.0, 0.5])
    Ys = rng.standard_normal((40, 2, 3))
    zs = Ys @ theta
    holed, clean = _estimators()[law](), _estimators()[law]()
    for k in range(40):
        Y = np.full((2, 3), np.nan) if k == 17 else Ys[k]
        holed.step(Y, zs[k] if k != 5 else np.array([np.inf, 0.0]), 0.01)
        if k not in (5, 17):
            clean.step(Ys[k], zs[k], 0.01)
    assert holed.dropouts == 2 and clean.dropouts == 0 and not holed.skipped
    np.testing.assert_array_equal(holed.theta, clean.theta)
    assert holed.t == pytest.approx(40 * 0.01) and clean.t == pytest.approx(38 * 0.01)
    assert np.isfinite(holed.theta).all()


@pytest.mark.parametrize("law", list(_estimators()))
@pytest.mark.parametrize("dt", [-0.01, float("nan"), float("inf"), "0.01", True, None])
def test_an_estimator_refuses_a_bad_time_step(law, dt):
    from manip_id.errors import InputError

    est = _estimators()[law]()
    with pytest.raises(InputError, match="dt"):
        est.step(np.ones((2, 3)), np.ones(2), dt)
    assert est.steps == 0 and est.t == 0.0


@pytest.mark.parametrize("law", ["gradient", "normalized", "drem", "concurrent"])
def test_a_continuous_law_refuses_dt_zero_and_rls_takes_it(law):
    from manip_id.errors import InputError

    with pytest.raises(InputError, match="positive time step"):
        _estimators()[law]().step(np.ones((2, 3)), np.ones(2), 0.0)
    rls = _estimators()["rls"]()
    rls.step(np.ones((2, 3)), np.ones(2), 0.0)  # discrete: dt only stamps the time
    assert rls.steps == 1


@pytest.mark.parametrize("law", list(_estimators()))
@pytest.mark.parametrize(
    ("Y", "z", "match"),
    [
        (np.ones((2, 3)) * 1j, np.ones(2), "complex"),
        (np.ones((2, 3)), "ab", "numeric"),
        (object(), np.ones(2), "numeric"),
        (np.ones((2, 2, 3)), np.ones((2, 2)), r"Y.shape=\(2, 2, 3\)"),
        (np.ones((2, 4)), np.ones(2), "p=3"),
    ],
)
def test_an_estimator_refuses_bad_samples_with_our_error(law, Y, z, match):
    from manip_id.errors import InputError

    with pytest.raises(InputError, match=match):
        _estimators()[law]().step(Y, z, 0.01)


def _controller(composite: float):
    from manip_id import load_robot
    from manip_id.control.adaptive import AdaptiveGains, SlotineLiController

    robot = load_robot("double_pendulum", friction="viscous")
    gains = AdaptiveGains(composite=composite, filter_bandwidth=20.0 if composite else 0.0)
    return robot, SlotineLiController(robot, robot.nominal_parameters * 0.8, gains)


@pytest.mark.parametrize("composite", [0.0, 5.0])
def test_the_adaptive_controller_holds_its_torque_over_a_dropout(composite):
    """A dropout holds the last torque and the last instant's adaptation; the run then
    equals the one whose controller never saw that instant (its dt joined the one before)."""
    _, holed = _controller(composite)
    _, clean = _controller(composite)
    t = np.arange(30) * 0.002
    for k, tk in enumerate(t):
        q = np.array([np.sin(tk), np.cos(2 * tk)])
        dq = np.array([np.cos(tk), -2 * np.sin(2 * tk)])
        ref = (np.zeros(2), np.zeros(2), np.zeros(2))
        if k == 12:
            last = holed.tau.copy()
            tau = holed.torque(np.array([np.nan, 0.0]), dq, *ref)
            np.testing.assert_array_equal(tau, last)
            assert holed.skipped and holed.dropouts == 1
            holed.adapt(0.002)
            continue
        holed.torque(q, dq, *ref)
        holed.adapt(0.002)
        clean.torque(q, dq, *ref)
        clean.adapt(0.004 if k == 11 else 0.002)
    np.testing.assert_allclose(holed.theta_hat, clean.theta_hat, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(holed.tau, clean.tau, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda c: c.adapt(-0.001), "dt"),
        (lambda c: c.adapt(float("nan")), "dt"),
        (lambda c: c.adapt("0.001"), "dt"),
        (
            lambda c: c.torque(np.zeros(3), np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(2)),
            r"q.shape=\(3,\)",
        ),  # fmt: skip
        (
            lambda c: c.torque(np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(2), [np.nan, 0]),
            "reference ddq_d",
        ),  # fmt: skip
        (
            lambda c: c.torque(np.zeros(2), ["a", "b"], np.zeros(2), np.zeros(2), np.zeros(2)),
            "dq must be numeric",
        ),  # fmt: skip
    ],
)
def test_the_adaptive_controller_refuses_bad_calls_with_our_error(call, match):
    from manip_id.errors import InputError

    _, ctrl = _controller(0.0)
    with pytest.raises(InputError, match=match):
        call(ctrl)


# ------------------------------------------------------------------ robot profiles
PROFILE_DOC = {
    "description": "a double pendulum",
    "model": {"friction": ["viscous", "coulomb"], "armature": False},
    "joints": {"active": ["joint1", "joint2"]},
    "excitation": {"harmonics": 3, "period": 5.0, "margin": 0.05, "acceleration_limit": [5.0, 6.0]},
    "data": {"torque_scale": [1.0, 2.0], "columns": {"q": "q*", "tau": ["e1", "e2"]}},
}
PROFILE_VALUES = [*BAD_VALUES, "joint9", 1e300, 0, 10**9, "position:abc", {"x": 1}, "é", [[1.0]]]


def _profile_or_error(doc: dict):
    """The robot loaded with profile ``doc`` (its per-joint values usable), or the error."""
    from manip_id import load_robot
    from manip_id.datasets.stream import torque_scale_vector
    from manip_id.errors import ManipIdError
    from manip_id.robot.profiles import parse_profile
    from manip_id.trajectories.limits import acceleration_limits

    try:
        prof = parse_profile(doc, name="p", source="p.toml")
        robot = load_robot("double_pendulum", profile=prof)
    except ManipIdError as exc:
        text = str(exc)
        assert "\n" not in text and len(text) < 1000 and "p.toml" in text, text
        return exc
    # accepted: every per-joint value fits the robot, every number is finite and sane
    torque_scale_vector(prof.torque_scale, robot.nv)
    acceleration_limits(robot, prof.excitation.acceleration_limit)
    kw = prof.excitation.design_kwargs()
    assert 1 <= kw.get("harmonics", 1) <= 1000 and 0 < kw.get("wf", 1.0) < 1e3
    return robot


@PROPERTY
@given(st.data())
def test_a_mutated_profile_loads_or_gives_one_clear_error(data):
    import copy

    doc = copy.deepcopy(PROFILE_DOC)
    paths = [p for p, _ in _paths(doc)]
    path = data.draw(st.sampled_from(paths))
    parent = doc
    for key in path[:-1]:
        parent = parent[key]
    action = data.draw(st.sampled_from(["delete", "replace", "add"]))
    if action == "delete" and isinstance(parent, dict):
        del parent[path[-1]]
    elif action == "add" and isinstance(parent, dict):
        parent[data.draw(st.sampled_from(["extra", "frictions", "Period", "é"]))] = 1
    else:
        parent[path[-1]] = data.draw(st.sampled_from(PROFILE_VALUES))
    _profile_or_error(doc)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"description": 5}, "description must be a string"),
        ({"excitation": {"period": 1e300}}, "excitation.period must be a number <= 10000"),
        ({"excitation": {"period": 1e-300}}, "excitation.period must be a number >= 0.01"),
        ({"excitation": {"harmonics": 10**9}}, "excitation.harmonics must be a positive integer"),
        ({"excitation": {"acceleration_limit": 1e300}}, "excitation.acceleration_limit must"),
        ({"excitation": {"acceleration_limit": [1.0, 2.0, 3.0]}}, "holds 3 values"),
        ({"data": {"torque_scale": 1e308}}, "data.torque_scale must be non-zero numbers"),
        ({"data": {"torque_scale": [1.0, 2.0, 3.0]}}, "holds 3 values"),
        ({"data": {"columns": {"q": 5.5}}}, "data.columns.q must be column names"),
        ({"data": {"columns": {"t": ""}}}, "data.columns.t must be column names"),
        ({"joints": {"active": ["joint1", "joint1"]}}, "joints.active must be distinct"),
        ({"joints": {"active": []}}, "joints.active must be a non-empty list"),
        ({"joints": {"locked": ["joint1", "joint2"]}}, "joints.locked locks every joint"),
        ({"joints": {"active": ["joint9"]}}, "unknown joint 'joint9'"),
        ({"model": {"friction": ["position:abc"]}}, "model.friction: position friction"),
    ],
)
def test_a_bad_profile_is_refused_naming_the_file_and_the_key(change, match):
    from manip_id.errors import InputError

    doc = {**PROFILE_DOC, **change}
    if "joints" not in change:
        doc["joints"] = PROFILE_DOC["joints"]
    err = _profile_or_error(doc)
    assert isinstance(err, InputError) and "profile p.toml" in str(err), err
    assert re.search(match, str(err)), str(err)


def test_a_profile_column_field_that_is_no_field_is_named_by_the_command(work, capsys):
    (work / "p.toml").write_text('[data.columns]\nbogus = "x*"\n')
    (work / "run.csv").write_text("t,q,tau\n0,0,0\n0.1,0,0\n")
    line = _error(capsys, "audit", "msd", "--profile", "p.toml", "--data", "run.csv")
    assert "p.toml" in line and "data.columns.'bogus'" in line


# ----------------------------------------------------------- repair: a negative mass
def _two_link_urdf(mass: float) -> str:
    """Two revolute joints; the first body is link l1 (``mass``, CoM and inertia rotated)
    plus l1b fixed to it (0.5 kg): the fixed link is merged into the body."""
    inertial = '<inertia ixx="0.01" ixy="0.001" ixz="0" iyy="0.02" iyz="0" izz="0.025"/>'
    return f"""<?xml version="1.0"?>
<robot name="neg">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0.1 0.02 0" rpy="0.3 0 0.2"/>
    <mass value="{mass}"/>{inertial}</inertial></link>
  <link name="l1b"><inertial><origin xyz="0 0 0.05"/><mass value="0.5"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial></link>
  <link name="l2"><inertial><origin xyz="0.1 0 0"/><mass value="1.0"/>{inertial}</inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" velocity="3" effort="50"/></joint>
  <joint name="fix" type="fixed"><parent link="l1"/><child link="l1b"/>
    <origin xyz="0.2 0 0" rpy="0 0.4 0"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.3 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" velocity="3" effort="50"/></joint>
</robot>
"""


def test_a_negative_mass_is_read_as_the_urdf_says_and_repaired_as_a_sign_slip(work, capsys):
    from manip_id import load_robot

    blocks = {}
    for label, mass in (("neg", -2.0), ("pos", 2.0), ("zero", 0.0)):
        (work / f"{label}.urdf").write_text(_two_link_urdf(mass))
        blocks[label] = load_robot(str(work / f"{label}.urdf")).nominal_parameters[:10]
    # a body's 10 parameters are affine in a link's mass: Pinocchio's own readings of the
    # +2 and 0 kg files give the -2 kg body (Pinocchio itself garbles a negative mass)
    expected = 2.0 * blocks["zero"] - blocks["pos"]
    np.testing.assert_allclose(blocks["neg"], expected, rtol=1e-12, atol=1e-14)
    status, out, err = _run(capsys, "repair", "neg.urdf", "out.urdf", "--json", "rep.json")
    assert status == 0, err
    assert "passes the eigenvalue test" in out
    fixed = load_robot(str(work / "out.urdf")).nominal_parameters[:10]
    m = -expected[0]  # the body's mass -1.5 kg taken as 1.5 kg
    assert fixed[0] == pytest.approx(m, rel=1e-9)
    np.testing.assert_allclose(fixed[1:4], expected[1:4], rtol=1e-9)  # the first moment kept
    after = load_robot(str(work / "out.urdf")).nominal_parameters[10:]
    before = load_robot(str(work / "neg.urdf")).nominal_parameters[10:]
    np.testing.assert_allclose(after, before, rtol=1e-9)  # the physical body j2 untouched


# ------------------------------------------------------ SIGTERM: a swallowed signal
def test_a_sigterm_swallowed_in_a_weakref_callback_still_terminates(work, capsys, monkeypatch):
    """A SIGTERM whose exception Python swallows (delivered inside a weakref callback, as
    it can be while a Dask cluster closes) printed "Exception ignored ... Traceback" and the
    run went on to publish, exit 0. Now: no traceback, nothing published, 143."""
    import signal
    import weakref

    from manip_id._io.outputs import OutputSet

    original = OutputSet.write_json

    def write_json(self, *args, **kwargs):
        class Thing:
            pass

        thing = Thing()
        ref = weakref.ref(thing, lambda _: os.kill(os.getpid(), signal.SIGTERM))
        del thing  # the callback runs: the handler raises inside it, and Python swallows it
        assert ref() is None
        return original(self, *args, **kwargs)

    monkeypatch.setattr(OutputSet, "write_json", write_json)
    status, _, err = _run(capsys, "identify", "msd", "--simulate", "--duration", "2",
                          "--json", "o.json")  # fmt: skip
    assert status == 128 + signal.SIGTERM
    assert err.strip().splitlines()[-1] == "manip-id: terminated"
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert not (work / "o.json").exists()
    assert [p.name for p in work.iterdir()] == []
    assert signal.getsignal(signal.SIGTERM) is not None and OutputSet.before_publish is None


@pytest.mark.slow
def test_sigterm_during_a_dask_payload_run_is_one_line(work):
    """``payload --scheduler local:1`` terminated mid-run (its cluster on 127.0.0.1):
    exit 143, one line, no traceback, no output, its processes gone."""
    import signal

    import psutil

    assert main(["simulate", "ur5", "--out", "sim", "--files", "1", "--duration", "300",
                 "--payload", "1.0"]) == 0  # fmt: skip
    cmd = [sys.executable, "-m", "manip_id", "payload", "ur5", "--unloaded", "sim/run_0.npz",
           "--loaded", "sim/payload_1kg_0.npz", "--frame", "tool0", "--scheduler", "local:1",
           "--json", "o.json"]  # fmt: skip
    proc = subprocess.Popen(cmd, cwd=work, env=ENV, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)  # fmt: skip
    parent = psutil.Process(proc.pid)
    children: list = []
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            children[:] = parent.children(recursive=True)
            if len(children) >= 2:  # the cluster's nanny and worker are up
                break
            time.sleep(0.1)
        assert proc.poll() is None and children, "the Dask cluster never started"
        time.sleep(1.0)  # into the accumulation
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(60) == 143
        err = proc.stderr.read().decode()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stderr.close()
    assert err.strip().splitlines() == ["manip-id: terminated"], err
    _, alive = psutil.wait_procs(children, timeout=10)
    assert alive == []
    assert not (work / "o.json").exists()


# ------------------------------------------------- the newer commands, hostile inputs
@pytest.fixture(scope="module")
def msd_files(tmp_path_factory):
    """An msd result (res.json) and one simulated log (sim/run_0.npz)."""
    folder = tmp_path_factory.mktemp("msd")
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        assert main(["simulate", "msd", "--out", "sim", "--files", "1", "--duration", "5"]) == 0
        assert main(["identify", "msd", "--data", "sim/run_0.npz", "--json", "res.json",
                     "--quiet"]) == 0  # fmt: skip
    finally:
        os.chdir(cwd)
    return folder


@pytest.mark.parametrize(
    "argv",
    [
        ["validate", "msd", "--model", "res.json", "--data", "sim/run_0.npz", "--json", "res.json"],
        [
            "drift",
            "msd",
            "--reference",
            "res.json",
            "--data",
            "sim/run_0.npz",
            "--json",
            "res.json",
        ],  # fmt: skip
        ["excite", "msd", "--duration", "4", "--from", "res.json", "--out", "res.json", "--force"],
    ],
    ids=["validate", "drift", "excite"],
)
def test_an_output_onto_a_file_the_command_reads_is_refused(msd_files, monkeypatch, capsys, argv):
    monkeypatch.chdir(msd_files)
    before = (msd_files / "res.json").read_bytes()
    line = _error(capsys, *argv)
    assert "is one of the inputs" in line and "res.json" in line
    assert (msd_files / "res.json").read_bytes() == before


MSD_DESIGN = {
    "robot": "msd",
    "excitation": {
        "duration": 2.0,
        "rate": 200.0,
        "coefficients": {"q0": [0.0], "a": [[0.1, 0.05]], "b": [[0.0, 0.02]], "wf": 1.0},
    },
}


@pytest.mark.parametrize(
    ("path", "value", "match"),
    [
        (None, None, None),  # the design as written: simulated
        (("excitation", "coefficients", "a", 0, 0), float("nan"), r"a\[0\]\[0\] must be a finite"),
        (("excitation", "coefficients", "a", 0), "x", r"a\[0\] must be a non-empty list"),
        (("excitation", "coefficients", "b"), [[1.0]], r"b\[0\] must be a row of 2 numbers"),
        (("excitation", "coefficients", "a", 0, 0), 1e300, "a must be coefficients of magnitude"),
        (("excitation", "coefficients", "wf"), 1e300, "below the Nyquist pulsation"),
        (("excitation", "coefficients", "wf"), 0, "wf must be a positive number"),
        (("excitation", "rate"), "fast", "excitation.rate must be a finite number"),
        (("excitation", "duration"), -1, "excitation.duration must be a positive number"),
        (("excitation", "coefficients"), None, "excitation.coefficients must be an object"),
        (("robot",), 5, "robot must be a string"),
        (("robot",), "ur5", "a design for robot 'ur5', not for 'msd'"),
        (("excitation", "coefficients", "q0"), [0.0, 0.0], "a must be a 2 x 2 matrix"),
    ],
)
def test_a_design_is_read_at_its_door(work, capsys, path, value, match):
    import copy
    import json

    doc = copy.deepcopy(MSD_DESIGN)
    if path is not None:
        parent = doc
        for key in path[:-1]:
            parent = parent[key]
        parent[path[-1]] = value
    (work / "d.json").write_text(json.dumps(doc))
    argv = ["simulate", "msd", "--out", "sim", "--trajectory", "d.json", "--files", "1"]
    if match is None:
        assert main(argv) == 0
        return
    line = _error(capsys, *argv)
    assert "d.json" in line and re.search(match, line), line
    assert not (work / "sim").exists()


def test_a_design_nested_too_deep_or_binary_is_one_line(work, capsys):
    (work / "deep.json").write_text("[" * 100_000)
    (work / "bin.json").write_bytes(b"PK\x03\x04\xff\xfe\x00")
    for name in ("deep.json", "bin.json"):
        line = _error(capsys, "simulate", "msd", "--out", "sim", "--trajectory", name)
        assert name in line and "Error(" not in line


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (["--duration", "1e300"], "sample count"),
        (["--duration", "4", "--noise", "1e300"], "noise is the torque noise std"),
    ],
)
def test_excite_refuses_absurd_numbers_at_their_option(work, capsys, extra, match):
    line = _error(capsys, "excite", "msd", "--out", "e.json", *extra)
    assert match in line
    assert not (work / "e.json").exists()


def test_excite_from_another_robots_result_says_so(msd_files, work, capsys):
    line = _error(capsys, "excite", "double_pendulum", "--duration", "4", "--out", "e.json",
                  "--from", str(msd_files / "res.json"))  # fmt: skip
    assert "a result of robot 'msd', not of 'double_pendulum'" in line


def test_convert_refuses_a_format_that_contradicts_the_suffix(msd_files, work, capsys):
    run = str(msd_files / "sim" / "run_0.npz")
    line = _error(capsys, "convert", run, "out.csv", "--format", "npz")
    assert "suffix says csv" in line and "'npz'" in line
    assert not (work / "out.csv").exists()
    assert main(["convert", run, "out.csv", "--format", "csv"]) == 0


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("matrix = [[1e308]]\n", "gear ratios of magnitude <= 1e+06"),
        ("matrix = [[10.0]]\noffset = [1e300]\n", "offset must be 1 finite values of magnitude"),
    ],
)
def test_a_transmission_with_absurd_numbers_is_refused(msd_files, work, capsys, text, match):
    (work / "t.toml").write_text(text)
    line = _error(capsys, "identify", "msd", "--data", str(msd_files / "sim" / "run_0.npz"),
                  "--transmission", "t.toml")  # fmt: skip
    assert "t.toml" in line and match in line


def test_a_huge_rollout_horizon_gives_a_short_message(msd_files, monkeypatch, capsys):
    monkeypatch.chdir(msd_files)
    line = _error(capsys, "validate", "msd", "--model", "res.json", "--data", "sim/run_0.npz",
                  "--horizon", "1e300")  # fmt: skip
    assert len(line) < 200 and "horizon" in line, line


def test_a_pickled_npz_member_is_named_as_such(work, capsys):
    np.savez(work / "obj.npz", t=np.array([object()] * 3, dtype=object), q=np.zeros((3, 1)),
             dq=np.zeros((3, 1)), tau=np.zeros((3, 1)))  # fmt: skip
    line = _error(capsys, "identify", "msd", "--data", "obj.npz")
    assert "holds Python objects" in line and "truncated" not in line


def test_an_absurd_delay_is_refused_at_the_option(msd_files, work, capsys):
    line = _error(capsys, "identify", "msd", "--data", str(msd_files / "sim" / "run_0.npz"),
                  "--delay", "1e300")  # fmt: skip
    assert "delay" in line and "<= 60" in line


def test_a_joint_named_twice_is_refused(msd_files, work, capsys):
    line = _error(capsys, "rank", "double_pendulum", "--joints", "joint1,joint1")
    assert "'joint1' twice" in line


def test_a_drift_reference_of_another_robot_is_refused_by_name(msd_files, work, capsys):
    import json

    doc = json.loads((msd_files / "res.json").read_text())
    doc["robot"] = "ur5"
    (work / "ref.json").write_text(json.dumps(doc))
    line = _error(capsys, "drift", "msd", "--reference", "ref.json", "--data",
                  str(msd_files / "sim" / "run_0.npz"))  # fmt: skip
    assert "'ur5'" in line and "'msd'" in line


def test_the_monitor_uses_the_models_friction_shapes():
    """The observer evaluated the Stribeck term with the default velocity whatever the
    model's: a model with vs = 0.3 rad/s left a residual of its friction on clean data."""
    import pinocchio as pin

    from manip_id import load_robot
    from manip_id.monitor import CollisionMonitor
    from manip_id.robot.friction import FrictionShapes
    from manip_id.robot.model import JointTerms
    from manip_id.trajectories import random_trajectory

    vs, fs = np.array([0.3, 0.3]), np.array([0.7, 0.4])  # [rad/s], [N m]
    base = load_robot("double_pendulum", friction=())
    robot = base.with_terms(
        JointTerms(stribeck=True, shapes=FrictionShapes(stribeck_velocity=tuple(vs)))
    )
    theta = robot.nominal_parameters.copy()
    theta[robot.layout.joint_columns("fs")] = fs
    t = np.arange(2000) / 1000.0
    q, dq, ddq = random_trajectory(base, harmonics=4, wf=0.4, seed=3).sample(t)
    m, d = base.model, base.model.createData()
    rigid = np.array([pin.rnea(m, d, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
    tau = rigid + fs * np.exp(-((dq / vs) ** 2)) * np.sign(dq)  # the law written out
    mon = CollisionMonitor(robot, theta, gain=25.0, filter_gain=None)
    assert np.abs(mon.run(t, q, dq, tau).residual).max() < 1e-6


def repair_nominal(robot, theta):
    from manip_id.physics.repair import repair_nominal as repair

    return repair(robot, theta)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda M, r: M.with_payload(r, r.nominal_parameters, "heavy"), "payload mass"),
        (lambda M, r: M.with_payload(r, r.nominal_parameters, 1e300), "<= 10000"),
        (lambda M, r: repair_nominal(r, "abc"), "theta"),
        (lambda M, r: repair_nominal(r, np.zeros(r.n_parameters) + 1j), "complex"),
        (lambda M, r: M.load_result(5), "path of a result file"),
        (lambda M, r: r.with_parameters(np.full(r.n_parameters, np.nan)), "theta holds nan"),
    ],
)
def test_the_api_refuses_bad_values_with_our_error(call, match):
    import manip_id as M
    from manip_id import load_robot
    from manip_id.errors import ManipIdError

    robot = load_robot("double_pendulum")
    with pytest.raises(ManipIdError, match=match):
        call(M, robot)


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (["--substeps", "1000000000"], "integration steps \\(duration x rate x substeps\\)"),
        (["--rate", "nan"], "rate must be positive"),
        (["--kappa", "nan"], "--kappa must be a rate >= 0"),
        (["--period", "1e-300"], "--period 1e-300 s is too short"),
    ],
)
def test_adapt_refuses_absurd_numbers_at_their_option(work, capsys, extra, match):
    line = _error(capsys, "adapt", "double_pendulum", "--duration", "0.5", *extra)
    assert re.search(match, line), line


def test_show_names_a_payload_or_gains_document_for_what_it_is(work, capsys):
    import json

    doc = {"command": "drive-gains", "robot": "msd", "drive_gains": [], "n_samples": {}}
    (work / "g.json").write_text(json.dumps(doc))
    line = _error(capsys, "show", "g.json")
    assert "the JSON of manip-id drive-gains, not an identification result" in line


def test_an_absurd_gain_from_a_gains_file_names_the_file(work):
    import json

    from manip_id import load_robot
    from manip_id.errors import DataError
    from manip_id.payload.known import load_torque_scale

    doc = {
        "command": "drive-gains",
        "robot": "msd",
        "drive_gains": [{"joint": "cart", "gain": 1e300}],
    }
    (work / "g.json").write_text(json.dumps(doc))
    with pytest.raises(
        DataError, match=r"g.json: the drive gain of cart must be a number <= 1e\+09"
    ):
        load_torque_scale(work / "g.json", load_robot("msd"))


def test_a_huge_trim_gives_a_short_message(msd_files, work, capsys):
    line = _error(capsys, "identify", "msd", "--data", str(msd_files / "sim" / "run_0.npz"),
                  "--trim", "1e300")  # fmt: skip
    assert len(line) < 300 and "trimming" in line, line


@pytest.mark.parametrize(
    "make",
    [
        lambda E: E["gradient"](record_every="x"),
        lambda E: E["gradient"](t0=float("nan")),
        lambda E: E["gradient"](t0="x"),
        lambda E: E["gradient"](bounds=(np.nan, 1.0)),
        lambda E: E["gradient"](bounds=(np.zeros(3), np.ones(3))),
        lambda E: E["rls"](forgetting="x"),
        lambda E: E["rls"](p_min="x"),
        lambda E: E["rls"](p_max=float("nan")),
        lambda E: E["drem"](alpha="x"),
        lambda E: E["drem"](mu="x"),
        lambda E: E["concurrent"](stack_size="x"),
    ],
)
def test_an_estimators_constructor_refuses_bad_values_with_our_error(make):
    from manip_id.errors import InputError
    from manip_id.estimators.concurrent import ConcurrentLearningEstimator
    from manip_id.estimators.drem import DREMEstimator
    from manip_id.estimators.online import GradientEstimator, RLSEstimator

    E = {
        "gradient": lambda **k: GradientEstimator(np.zeros(2), 1.0, **k),
        "rls": lambda **k: RLSEstimator(np.zeros(2), 1.0, **k),
        "drem": lambda **k: DREMEstimator(np.zeros(2), **k),
        "concurrent": lambda **k: ConcurrentLearningEstimator(np.zeros(2), 1.0, **k),
    }
    with pytest.raises(InputError):
        make(E)


@pytest.mark.parametrize("q", ["ab", np.zeros(2) + 1j, object()], ids=["text", "complex", "object"])
def test_the_monitor_step_refuses_bad_dtypes_with_our_error(q):
    from manip_id.errors import InputError

    _, monitor = _monitor()
    with pytest.raises(InputError, match="q"):
        monitor.step(q, np.zeros(2), np.zeros(2), 0.01)
