"""What a newcomer meets first (issue 39): a simulated robot that differs from its URDF, an
answer that comes first and short, and a command line reference that lists everything.

The checks are independent of the code under test: the logs against Pinocchio's inverse
dynamics of the truth written beside them, the nominal model's error recomputed from the
URDF with ``pinocchio.rnea``, and the reference page against the parser's own options.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from manip_id import load_dataset, load_robot
from manip_id.cli import build_parser, main
from manip_id.physics.consistency import check_consistency

ROOT = Path(__file__).resolve().parents[1]
CLI_DOC = ROOT / "docs" / "cli.md"
#: The demo's robot, as `make demo` simulates it (shorter logs).
DIFFERS = ["--friction", "viscous,coulomb", "--joint-terms", "fv=0.4,fc=0.6",
           "--perturb", "0.3", "--tool", "0.8", "--seed", "2"]  # fmt: skip
NOISE = 0.01  # the simulated torque noise, relative to each joint's RMS torque


def _rnea(model: pin.Model, d) -> np.ndarray:
    data = model.createData()
    return np.array([pin.rnea(model, data, *s) for s in zip(d.q, d.dq, d.ddq, strict=True)])


def _truth_model(robot, theta: np.ndarray) -> pin.Model:
    """The URDF's kinematics with the bodies of ``theta`` (Pinocchio's own conversion)."""
    model = robot.model.copy()
    for i in range(robot.n_bodies):
        model.inertias[i + 1] = pin.Inertia.FromDynamicParameters(theta[10 * i : 10 * i + 10])
    return model


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> Path:
    """Two 10 s logs of the demo's panda (unlike its URDF), each its own excitation."""
    out = tmp_path_factory.mktemp("first") / "logs"
    argv = ["simulate", "panda", "--out", str(out), "--files", "2", "--duration", "10"]
    assert main([*argv, *DIFFERS, "--quiet"]) == 0
    return out


def test_the_simulated_robot_differs_from_its_urdf_as_stated(logs):
    robot = load_robot("panda", friction="viscous,coulomb")
    truth = json.loads((logs / "truth.json").read_text())
    theta = np.array([truth["parameters"][n] for n in robot.parameter_names])
    assert truth["differs_from_urdf"]["tool_mass"] == 0.8
    assert check_consistency(robot, theta).consistent  # a real robot's parameters
    nominal = robot.nominal_parameters
    masses, nominal_masses = theta[: 10 * robot.n_bodies : 10], nominal[: 10 * robot.n_bodies : 10]
    assert np.median(np.abs(np.log(masses / nominal_masses))) > 0.1  # tens of percent off
    fv, fc = theta[robot.n_rigid :: 2], theta[robot.n_rigid + 1 :: 2]
    assert len(fv) == robot.nv  # the joint terms set for every joint, then perturbed
    assert np.all(fv > 0) and np.all(fc > 0) and not np.allclose(fv, 0.4)
    model = _truth_model(robot, theta)
    for name in ("run_0.npz", "run_1.npz"):
        d = load_dataset(logs / name)
        clean = _rnea(model, d) + fv * d.dq + fc * np.sign(d.dq)
        noise = (d.tau - clean).std(axis=0) / np.sqrt((clean**2).mean(axis=0))
        np.testing.assert_allclose(noise, NOISE, rtol=0.2)  # only the stated noise left
    a, b = (load_dataset(logs / f"run_{k}.npz") for k in range(2))
    assert not np.allclose(a.q, b.q)  # two motions: one trains, the other validates
    assert "0.8 kg tool (not in the URDF)" in (logs / "README.txt").read_text()


def test_a_tool_alone_adds_its_point_mass_to_the_last_body(tmp_path):
    out = tmp_path / "tool"
    argv = ["simulate", "ur5", "--out", str(out), "--files", "1", "--duration", "1"]
    assert main([*argv, "--tool", "1.5", "--quiet"]) == 0
    robot = load_robot("ur5")
    truth = json.loads((out / "truth.json").read_text())["parameters"]
    theta = np.array([truth[n] for n in robot.parameter_names])
    delta = theta - robot.nominal_parameters
    last = slice(10 * (robot.n_bodies - 1), 10 * robot.n_bodies)
    assert np.count_nonzero(delta[: last.start]) == 0  # the other bodies untouched
    lever = np.zeros(3)
    lever["XYZ".index(robot.model.joints[-1].shortname()[-1])] = 0.1  # [m] on the last axis
    point = pin.Inertia(1.5, lever, np.zeros((3, 3)))
    np.testing.assert_allclose(delta[last], point.toDynamicParameters(), atol=1e-12)


def test_identify_answers_first_how_much_better_than_the_urdf(logs, tmp_path, capsys):
    out = tmp_path / "r.json"
    train, valid = str(logs / "run_0.npz"), str(logs / "run_1.npz")
    argv = ["identify", "panda", "--friction", "viscous,coulomb", "--data", train,
            "--validate", valid, "--method", "wls", "--json", str(out)]  # fmt: skip
    assert main(argv) == 0
    lines = capsys.readouterr().out.splitlines()
    first = re.match(r"identified model: ([\d.]+) x better than the nominal model on the "
                     r"validation data", lines[0])  # fmt: skip
    assert first, lines[0]
    # the nominal (URDF) model's validation error, recomputed with Pinocchio
    robot = load_robot("panda", friction="viscous,coulomb")
    v = load_dataset(logs / "run_1.npz")
    urdf = _rnea(robot.model, v)  # rnea leaves the URDF's joint damping and friction out
    urdf = urdf + robot.model.damping * v.dq + robot.model.friction * np.sign(v.dq)
    nominal = np.linalg.norm(v.tau - urdf) / np.linalg.norm(v.tau)
    doc = json.loads(out.read_text())
    e = doc["relative_error"]
    assert e["nominal_validation"] == pytest.approx(nominal, rel=1e-6)
    assert float(first.group(1)) == pytest.approx(nominal / e["validation"], rel=0.01)
    assert float(first.group(1)) >= 10  # the demo's point: the URDF is 10x worse
    assert max(e["per_joint_validation"]) < 1.3 * NOISE  # every joint at the noise floor
    assert lines[1].startswith("verdict: ")
    assert len(lines) <= 25  # short by default
    table = [x.split() for x in lines if x.split()[:1] and x.split()[0] in doc["joints"]]
    assert [t[0] for t in table] == doc["joints"]  # one row per joint: train, valid, nominal
    got = np.array([[float(x) for x in t[1:]] for t in table])
    np.testing.assert_allclose(got[:, 1], 100 * np.array(e["per_joint_validation"]), atol=0.006)
    assert not any(x.startswith("parameter ") for x in lines)  # the full table: --verbose
    assert [x for x in lines if "pre-fit audit" in x] == [
        "pre-fit audit: nothing found in 2 file(s)"
    ]


def test_verbose_adds_every_parameter_and_quiet_prints_nothing(logs, capsys):
    assert main(["identify", "panda", "--data", str(logs / "run_0.npz"), "--quiet"]) == 0
    assert capsys.readouterr().out == ""
    assert main(["identify", "panda", "--data", str(logs / "run_0.npz"), "--verbose"]) == 0
    out = capsys.readouterr().out  # the audit's table and the data quality, then the answer
    answer = out[out.index("identified model: ") :]
    rows = [x for x in answer.splitlines() if re.match(r"panda_joint\d\.\w+ ", x)]
    assert len(rows) == 43  # every base parameter of the rigid panda (published count)
    assert "audit against the nominal model of panda" in out[: len(out) - len(answer)]


def test_warnings_say_what_to_do(capsys):
    assert main(["identify", "ur5", "--simulate", "--duration", "5", "--quiet"]) == 0
    err = capsys.readouterr().err
    line = next(x for x in err.splitlines() if "not physical" in x)
    assert line.endswith("Do: add --consistent to estimate a physical model.")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--joint-terms", "fv=0.4"], "--joint-terms sets fv, which the robot's model does not"),
        (["--friction", "viscous", "--joint-terms", "xx=1"], "TERM one of Ia, fv, fc, fo, k"),
        (["--friction", "viscous", "--joint-terms", "fv=-1"], "fv must be a finite number >= 0"),
        (["--friction", "viscous", "--joint-terms", "fv=a"], "fv takes a number, got 'a'"),
        (["--perturb", "-0.1"], "--perturb must be a fraction in [0, 5], got -0.1"),
        (["--tool", "-1"], "--tool must be a mass >= 0 [kg], got -1.0"),
    ],
)
def test_bad_truth_options_are_one_line_exit_2(tmp_path, capsys, argv, message):
    assert main(["simulate", "ur5", "--out", str(tmp_path / "s"), "--duration", "1", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "s").exists()


# ------------------------------------------------------------- the reference
def _sections(text: str) -> dict[str, str]:
    """``### manip-id CMD`` (and the shared options) -> the text of that section."""
    parts = re.split(r"^### ", text, flags=re.MULTILINE)[1:]
    return {p.split("\n", 1)[0].strip(): p for p in parts}


def _options(parser: argparse.ArgumentParser) -> list[str]:
    return [
        o
        for a in parser._actions
        if a.help != argparse.SUPPRESS
        for o in a.option_strings
        if o.startswith("--") and o != "--help"
    ]


def missing_from_reference(text: str) -> list[str]:
    """Every command of ``manip-id --help`` and option of one that ``text`` does not list
    (in the command's section or among the shared options)."""
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    sections = _sections(text)
    shared = sections.get("Options shared by several commands", "")
    missing = []
    for name, parser in sub.choices.items():
        own = sections.get(f"manip-id {name}")
        if own is None:
            missing.append(name)
            continue
        for option in _options(parser):
            listed = rf"`{re.escape(option)}[` ,]"
            if not (re.search(listed, own) or re.search(listed, shared)):
                missing.append(f"{name} {option}")
    return missing


def test_every_command_and_option_is_in_the_reference():
    missing = missing_from_reference(CLI_DOC.read_text(encoding="utf-8"))
    assert not missing, f"docs/cli.md does not list: {', '.join(missing)}"


def test_a_missing_command_or_option_is_found():
    text = CLI_DOC.read_text(encoding="utf-8")
    without_option = text.replace("- `--perturb FRACTION`", "- `--perturbation FRACTION`")
    assert "simulate --perturb" in missing_from_reference(without_option)
    without_command = text.replace("### manip-id warmup", "### warm up")
    assert "warmup" in missing_from_reference(without_command)


def test_command_sections_are_written_from_the_parser():
    """docs/cli.md's shared options and command sections are what docs/cli_reference.py
    writes from the parser: an option whose help changed and a page left behind fail."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "_cli_reference", ROOT / "docs" / "cli_reference.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    text = CLI_DOC.read_text(encoding="utf-8")
    assert module.page(text) == text, "run: python docs/cli_reference.py"
    stale = text.replace("estimator [default wls]", "estimator [default ols]")
    assert module.page(stale) != stale  # the check bites
