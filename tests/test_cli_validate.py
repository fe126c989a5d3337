"""``manip-id validate`` and ``identify --refine output-error --rollout S`` end to end on
simulated logs (the truth: a perturbed nominal model with friction)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from manip_id import load_robot
from manip_id.cli import main
from manip_id.datasets import save_dataset
from manip_id.simulation import MeasurementNoise, simulate
from manip_id.trajectories import random_trajectory


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """Two logs of a double pendulum whose truth is the nominal model with its bodies
    scaled (1.3 and 0.8) and viscous and Coulomb friction (1 % torque noise)."""
    robot = load_robot("double_pendulum", friction="viscous,coulomb")
    theta = robot.nominal_parameters.copy()
    theta[robot.layout.joint_columns("fv")] = [0.05, 0.03]
    theta[robot.layout.joint_columns("fc")] = [0.05, 0.02]
    theta[robot.layout.body_slice(0)] *= 1.3  # a whole body scaled stays physical
    theta[robot.layout.body_slice(1)] *= 0.8
    folder = tmp_path_factory.mktemp("logs")
    paths = []
    for seed in (0, 1):
        traj = random_trajectory(robot, harmonics=3, seed=seed)
        noise = MeasurementNoise(tau=0.01)
        sim = simulate(robot, traj, duration=5.0, rate=500.0, theta=theta, noise=noise, seed=seed)
        paths.append(save_dataset(sim.dataset, folder / f"run_{seed}.npz"))
    return tuple(paths)


def test_validate_reports_identified_and_nominal(logs, tmp_path, capsys):
    train, valid = logs
    fit = tmp_path / "fit.json"
    ident = ["identify", "double_pendulum", "--friction", "viscous,coulomb", "--quiet"]
    assert main([*ident, "--data", str(train), "--json", str(fit)]) == 0
    out, fig = tmp_path / "rollout.json", tmp_path / "rollout.png"
    cmd = ["validate", "double_pendulum", "--model", str(fit), "--data", str(valid)]
    assert (
        main([*cmd, "--horizon", "0.1", "--starts", "10", "--json", str(out), "--figure", str(fig)])
        == 0
    )
    doc = json.loads(out.read_text())["rollout"]
    assert doc["horizon"] == 0.1
    for side in ("identified", "nominal"):
        assert len(doc[side]["position_rms"]) == 2 and len(doc[side]["velocity_rms"]) == 2
        assert doc[side]["n_starts"] == 10
    # the simulated truth differs from the nominal model: the identified one follows better
    assert max(doc["identified"]["position_rms"]) < max(doc["nominal"]["position_rms"])
    assert "tanh" in doc["regularization"]
    assert fig.stat().st_size > 1000
    assert "rollout over 0.1 s" in capsys.readouterr().out


def test_identify_refines_and_rolls_out(logs, tmp_path):
    train, _ = logs
    out = tmp_path / "ref.json"
    args = ["identify", "double_pendulum", "--friction", "viscous,coulomb", "--quiet"]
    args += ["--data", str(train), "--split", "0.7", "--refine", "output-error"]
    args += ["--refine-horizon", "0.05", "--refine-windows", "20"]
    report = tmp_path / "report"
    assert main([*args, "--rollout", "0.1", "--json", str(out), "--report", str(report)]) == 0
    assert (report / "rollout.png").stat().st_size > 1000
    doc = json.loads(out.read_text())
    rec = doc["refinement"]
    assert rec["method"] == "output-error" and rec["steps"] == 25 and rec["windows"] == 20
    assert rec["cost_after"] <= rec["cost_before"]
    assert doc["rollout"]["horizon"] == 0.1
    assert doc["relative_error"]["validation"] < 0.1
    # the refinement's start rolled out beside it: the same numbers as the run without
    # --refine rolls out for its own estimate
    plain = tmp_path / "plain.json"
    cut = args.index("--refine")
    assert main([*args[:cut], "--rollout", "0.1", "--json", str(plain)]) == 0
    start = json.loads(plain.read_text())["rollout"]["identified"]["position_rms"]
    np.testing.assert_allclose(doc["rollout"]["before_refinement"]["position_rms"], start)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--rollout", "0.1"], "--validate or --split"),
        (["--refine-horizon", "0.1"], "--refine-horizon applies"),
        (["--refine-windows", "5"], "--refine-windows applies"),
        (["--refine", "output-error", "--method", "rls"], "--method ols or wls"),
    ],
)
def test_bad_identify_options_fail_before_work(logs, extra, message, capsys):
    train, _ = logs
    args = ["identify", "double_pendulum", "--data", str(train), *extra]
    assert main(args) == 2
    assert message in capsys.readouterr().err


def test_validate_refuses_a_figure_that_is_not_png(logs, tmp_path, capsys):
    _, valid = logs
    cmd = ["validate", "double_pendulum", "--model", str(tmp_path / "x.json"), "--data", str(valid)]
    assert main([*cmd, "--figure", str(tmp_path / "x.svg")]) == 2
    assert "PNG" in capsys.readouterr().err


@pytest.mark.slow
def test_real_panda_refined_model_rolls_out_closer(panda_log, tmp_path):
    """Train 0-10.5 s, validate 10.5-15 s (the issue's protocol). Measured
    (experiments/panda_rollout.py): rollout error at 0.25 s 0.118 rad refined against
    0.166 rad consistent least squares (0.71x); validation torque error 1.665 % against
    1.590 % plain least squares (1.05x) and 2.210 % consistent."""
    d = str(panda_log)
    # OLS, the protocol measured above: from the WLS start (the default) the refined
    # model rolls out at 0.260 rad against 0.217 rad consistent (issue 40's note)
    base = ["identify", "panda", "--friction", "viscous,coulomb,offset", "--quiet"]
    base += ["--method", "ols"]
    base += ["--data", f"{d}@0:10.5", "--validate", f"{d}@10.5:15"]
    ls, ref = (tmp_path / f"{n}.json" for n in ("ls", "ref"))
    assert main([*base, "--json", str(ls)]) == 0
    args = [*base, "--consistent", "--refine", "output-error", "--rollout", "0.25"]
    assert main([*args, "--json", str(ref)]) == 0
    docs = {k: json.loads(p.read_text()) for k, p in (("ls", ls), ("ref", ref))}

    def norm(errors):
        return sum(x * x for x in errors) ** 0.5

    # the refinement's start is the consistent fit, rolled out beside the refined model
    # (test_identify_refines_and_rolls_out checks it equals that fit's own rollout)
    rollout = docs["ref"]["rollout"]
    refined = norm(rollout["identified"]["position_rms"])
    assert refined <= 0.8 * norm(rollout["before_refinement"]["position_rms"])
    assert not any("made the validation rollout worse" in w for w in docs["ref"]["warnings"])
    err = {k: d["relative_error"]["validation"] for k, d in docs.items()}
    assert err["ref"] <= 1.1 * err["ls"]
    assert docs["ref"]["rollout"]["identified"]["diverged"] == 0


def test_a_refinement_that_rolls_out_worse_is_named():
    """The warning compares the joints' position RMS at the horizon, start against refined
    (the real Panda from the WLS start: 0.260 rad against 0.217 rad, issue 40's note)."""
    from types import SimpleNamespace

    from manip_id.identification.file_run import REFINEMENT_WORSE, refinement_worse

    def report(rms):
        return SimpleNamespace(horizon=0.25, identified=SimpleNamespace(position_rms=rms))

    start = report(np.array([0.1, 0.2, 0.05]))  # norm 0.2291
    text = refinement_worse(report(np.array([0.12, 0.22, 0.06])), start)
    assert text is not None and "0.2291 rad before it" in text and "at 0.25 s" in text
    assert refinement_worse(report(np.array([0.09, 0.2, 0.05])), start) is None  # better
    same = report(start.identified.position_rms * REFINEMENT_WORSE)  # within the margin
    assert refinement_worse(same, start) is None


def test_refine_with_an_export_is_refused_before_work(tmp_path, capsys):
    """The refined estimate is base parameters: no consistent model to export."""
    out = tmp_path / "r.urdf"
    argv = ["identify", "ur5", "--simulate", "--duration", "2", "--consistent"]
    assert main([*argv, "--refine", "output-error", "--export-urdf", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--refine gives base parameters" in err[0], err
    assert not out.exists()


def test_non_physical_values_of_a_refined_estimate_get_their_own_advice():
    """A negative viscous coefficient after the refinement: the warning says the refinement
    is not constrained, and its advice is not "add --consistent" (which was given)."""
    from dataclasses import replace

    from manip_id.cli._answer import advice_for
    from manip_id.identification import identify

    robot = load_robot("double_pendulum", friction="viscous")
    traj = random_trajectory(robot, harmonics=3, seed=1)
    d = simulate(robot, traj, duration=4.0, rate=100.0).dataset
    result = identify(robot, (d.q, d.dq, d.ddq, d.tau), method="ols")
    k = result.names.index(next(n for n in result.names if n.endswith(".fv")))
    bad = replace(result, estimate=result.estimate.copy())
    bad.estimate[k] = -0.5  # [N m s/rad]
    plain = [w for w in bad.to_dict()["warnings"] if w.startswith("non-physical values")]
    assert len(plain) == 1 and "refinement" not in plain[0]
    assert advice_for(plain[0]).startswith("add --consistent")
    refined = replace(bad, context={**bad.context, "refinement": {"method": "output-error"}})
    text = next(w for w in refined.to_dict()["warnings"] if w.startswith("non-physical values"))
    assert "not constrained to physical values" in text
    assert "leave out --refine" in advice_for(text)
