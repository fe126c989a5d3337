"""The temperature friction law: viscous and Coulomb coefficients linear in temperature.

Independent references: the simulated joints' torques are Pinocchio's rnea plus the law
written out here in numpy, ``(fv0 + fv1 (T - Tref)) dq + (fc0 + fc1 (T - Tref)) sign(dq)``
with the truth's own reference ``Tref`` (not manip_id's columns, nor its T0), the
temperature drifting from 25 to 45 degC over the record; the fit's reference T0 is the
training rows' mean temperature, so the truth at T0 is ``fv0 + fv1 (T0 - Tref)``.
"""

from __future__ import annotations

import json
import sys

import numpy as np
import pinocchio as pin
import pytest

from manip_id import load_robot
from manip_id.cli import main
from manip_id.datasets import Dataset, load_dataset, save_dataset
from manip_id.errors import InputError, MissingTemperatureError
from manip_id.export import export_urdf
from manip_id.identification import FileOptions, RunOptions, identify
from manip_id.robot.friction import FrictionShapes, TemperatureStats
from manip_id.robot.model import JointTerms
from manip_id.robot.regressor import joint_torques, regressor
from manip_id.simulation import ThermalOptions, inverse_dynamics
from manip_id.trajectories import random_trajectory

RATE = 200.0  # [Hz]
NOISE = 0.003  # torque noise, relative to each joint's RMS
T_NOISE = 0.05  # temperature sensor noise [K]
TREF = 35.0  # the truth's reference temperature [degC]
FV0, FV1 = np.array([0.3, 0.2]), np.array([-0.006, -0.004])  # [N m s/rad], [N m s/(rad K)]
FC0, FC1 = np.array([0.8, 0.5]), np.array([-0.012, -0.008])  # [N m], [N m/K]
OFFSET = np.array([0.0, 4.0])  # joint 2 runs 4 K warmer [K]
LAW = "viscous,coulomb,temperature"


@pytest.fixture(scope="module")
def robot():
    return load_robot("double_pendulum", friction=())


def _record(robot, seed: int = 1, duration: float = 40.0, t_start=25.0, t_end=45.0):
    """A simulated record: ``(t, q, dq, ddq, tau, T)`` with T (N, 2) [degC]."""
    traj = random_trajectory(robot, harmonics=5, wf=0.3, seed=seed)
    t = np.arange(int(duration * RATE)) / RATE
    q, dq, ddq = traj.sample(t)
    m, d = robot.model, robot.model.createData()
    tau = np.array([pin.rnea(m, d, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
    temp = t_start + (t_end - t_start) * t[:, None] / t[-1] + OFFSET  # [degC]
    dt = temp - TREF
    tau = tau + (FV0 + FV1 * dt) * dq + (FC0 + FC1 * dt) * np.sign(dq)
    rng = np.random.default_rng(seed + 100)
    tau = tau + NOISE * np.sqrt(np.mean(tau**2, axis=0)) * rng.standard_normal(tau.shape)
    temp = temp + T_NOISE * rng.standard_normal(temp.shape)
    return t, q, dq, ddq, tau, temp


def _dataset(robot, rec, temp=True) -> Dataset:
    t, q, dq, ddq, tau, T = rec
    names = tuple(robot.dof_names)
    return Dataset(t=t, q=q, dq=dq, ddq=ddq, tau=tau, joint_names=names, temp=T if temp else None)


def _coef(result, robot, name):
    return np.array([result.estimate[result.names.index(f"{d}.{name}")] for d in robot.dof_names])


# ------------------------------------------------------------------ columns
def test_columns_are_the_formula_and_one_column_is_broadcast(robot):
    rng = np.random.default_rng(0)
    q, dq, ddq = robot.random_states(30)
    temp = rng.uniform(20, 50, (30, 1))
    shapes = FrictionShapes(temperature_reference=(30.0, 40.0))
    r = robot.with_terms(JointTerms(viscous=True, coulomb=True, temperature=True, shapes=shapes))
    assert r.terms.enabled == ("fv", "fc", "fvt", "fct")
    assert r.parameter_units[-2:] == ["N m s/(rad K)", "N m/K"]
    Y = regressor(r, q, dq, ddq, temp=temp)
    for j, dof in enumerate(r.dof_names):
        t0 = (30.0, 40.0)[j]
        np.testing.assert_allclose(
            Y[:, j, r.parameter_index(f"{dof}.fvt")], (temp[:, 0] - t0) * dq[:, j], rtol=1e-14
        )
        np.testing.assert_allclose(
            Y[:, j, r.parameter_index(f"{dof}.fct")], (temp[:, 0] - t0) * np.sign(dq[:, j])
        )
    # one column per joint gives the same as the broadcast column
    np.testing.assert_array_equal(regressor(r, q, dq, ddq, temp=np.repeat(temp, 2, axis=1)), Y)
    # without a temperature: a clear error, not zeros
    with pytest.raises(InputError, match="needs the measured temperature"):
        regressor(r, q, dq, ddq)
    with pytest.raises(InputError, match="temp.shape"):
        regressor(r, q, dq, ddq, temp=np.ones((30, 3)))


def test_temperature_sums_merge_and_broadcast():
    rng = np.random.default_rng(1)
    a, b = rng.normal(30, 3, (100, 1)), rng.normal(40, 3, (50, 1))
    s = TemperatureStats.of(a) + TemperatureStats.of(b)
    mean, low, high = s.per_dof(3)
    both = np.vstack([a, b])[:, 0]
    np.testing.assert_allclose(mean, both.mean(), rtol=1e-14)
    np.testing.assert_allclose(low, both.min())
    np.testing.assert_allclose(high, both.max())


# ----------------------------------------------------------------- recovery
def test_recovers_the_coefficients_and_beats_the_constant_model(robot):
    rec = _record(robot)
    train, valid = _dataset(robot, rec).split(0.7)  # validation: the hottest 30 %
    r = load_robot("double_pendulum", friction=LAW)
    res = identify(r, train, validation=valid)
    t0 = np.array(res.context["friction_shapes"]["temperature_reference"])
    np.testing.assert_allclose(t0, train.temp.mean(axis=0), rtol=1e-12)  # the training mean
    fv, fc = _coef(res, r, "fv"), _coef(res, r, "fc")
    fvt, fct = _coef(res, r, "fvt"), _coef(res, r, "fct")
    # the truth at the fit's reference T0
    # (measured: errors <= 2e-4 on fv, fc and <= 2e-5 on the slopes; tolerances 5-10x)
    np.testing.assert_allclose(fv, FV0 + FV1 * (t0 - TREF), atol=2e-3)  # [N m s/rad]
    np.testing.assert_allclose(fc, FC0 + FC1 * (t0 - TREF), atol=2e-3)  # [N m]
    np.testing.assert_allclose(fvt, FV1, atol=1e-4)  # [N m s/(rad K)]: 2.5 % of FV1[1]
    np.testing.assert_allclose(fct, FC1, atol=1e-4)  # [N m/K]: 1.3 % of FC1[1]
    plain = identify(
        load_robot("double_pendulum", friction="viscous,coulomb"), train, validation=valid
    )
    assert res.relative_error.validation < 0.5 * plain.relative_error.validation
    assert res.relative_error.validation < 3 * NOISE


def test_noise_free_recovery_is_exact(robot):
    t, q, dq, ddq, _, _ = _record(robot, duration=10.0)
    temp = 25 + 20 * t[:, None] / t[-1] + OFFSET
    m, d = robot.model, robot.model.createData()
    tau = np.array([pin.rnea(m, d, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
    tau = tau + (FV0 + FV1 * (temp - TREF)) * dq + (FC0 + FC1 * (temp - TREF)) * np.sign(dq)
    r = load_robot("double_pendulum", friction=LAW)
    ds = Dataset(t=t, q=q, dq=dq, ddq=ddq, tau=tau, temp=temp)
    res = identify(r, ds)
    t0 = temp.mean(axis=0)
    np.testing.assert_allclose(_coef(res, r, "fvt"), FV1, atol=1e-10)
    np.testing.assert_allclose(_coef(res, r, "fct"), FC1, atol=1e-10)
    np.testing.assert_allclose(_coef(res, r, "fv"), FV0 + FV1 * (t0 - TREF), atol=1e-10)
    np.testing.assert_allclose(_coef(res, r, "fc"), FC0 + FC1 * (t0 - TREF), atol=1e-10)


def test_the_simulator_evaluates_the_law(robot):
    r = load_robot("double_pendulum", friction=LAW)
    shapes = FrictionShapes(temperature_reference=(TREF, TREF))
    r = r.with_terms(JointTerms(viscous=True, coulomb=True, temperature=True, shapes=shapes))
    theta = r.nominal_parameters.copy()
    for name, v in (("fv", FV0), ("fc", FC0), ("fvt", FV1), ("fct", FC1)):
        theta[r.layout.joint_columns(name)] = v
    traj = random_trajectory(robot, harmonics=4, wf=0.4, seed=3)
    t = np.arange(200) / 100.0
    q, dq, ddq = traj.sample(t)
    temp = ThermalOptions(25.0, 45.0, tuple(OFFSET)).temperature(t, t[-1], 2)
    np.testing.assert_allclose(temp[-1], 45.0 + OFFSET)
    expected = (FV0 + FV1 * (temp - TREF)) * dq + (FC0 + FC1 * (temp - TREF)) * np.sign(dq)
    np.testing.assert_allclose(joint_torques(r, theta, q, dq, temp=temp), expected, atol=1e-12)
    m, d = robot.model, robot.model.createData()
    rigid = np.array([pin.rnea(m, d, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
    got = inverse_dynamics(r, theta, q, dq, ddq, temp=temp)
    np.testing.assert_allclose(got - rigid, expected, atol=1e-9)
    # a constant temperature: every sample at 40 degC
    const = inverse_dynamics(r, theta, q, dq, ddq, temp=40.0)
    fric = (FV0 + FV1 * 5.0) * dq + (FC0 + FC1 * 5.0) * np.sign(dq)
    np.testing.assert_allclose(const - rigid, fric, atol=1e-9)


# --------------------------------------------------------------- all paths
@pytest.fixture(scope="module")
def files(robot, tmp_path_factory):
    """The record as NPZ (with ddq and one temperature column per joint), CSV (one
    temperature column for every joint, foreign header) and NPZ without temperature."""
    folder = tmp_path_factory.mktemp("temperature")
    rec = _record(robot, seed=4, duration=30.0)
    save_dataset(_dataset(robot, rec), folder / "run.npz")
    save_dataset(_dataset(robot, rec, temp=False), folder / "plain.npz")
    t, q, dq, ddq, tau, T = rec
    with open(folder / "run.csv", "w") as fh:
        fh.write("time,p1,p2,v1,v2,a1,a2,e1,e2,motor_temp\n")
        rows = np.column_stack([t, q, dq, ddq, tau, T[:, 0]])
        np.savetxt(fh, rows, delimiter=",", fmt="%.17g")
    return folder, rec


@pytest.mark.slow
def test_streamed_forked_dask_and_in_memory_agree(robot, files):
    folder, rec = files
    r = load_robot("double_pendulum", friction=LAW)
    train, valid = f"{folder / 'run.npz'}@0:20", f"{folder / 'run.npz'}@20:"
    out = {}
    for name, run in (
        ("streamed", RunOptions(chunk=500)),
        ("forked", RunOptions(workers=2)),
        ("dask", RunOptions(scheduler="local:2")),
    ):
        out[name] = identify(
            r, [train], validation=[valid], run=run, files=FileOptions(audit=False)
        )
    out["fleet"] = identify(
        r, [train], validation=[valid], run=RunOptions(chunk=700), files=FileOptions(audit=False)
    )
    ds = load_dataset(folder / "run.npz")
    k = int(np.searchsorted(ds.t, ds.t[0] + 20.0))  # the window [0, 20) s
    out["memory"] = identify(r, ds.slice(0, k), validation=ds.slice(k, ds.n_samples))
    ref = out["streamed"]
    assert ref.context["friction_shapes"]["temperature_reference"] == pytest.approx(
        rec[5][:k].mean(axis=0), rel=1e-12
    )
    for name, res in out.items():
        assert res.names == ref.names
        scale = np.maximum(np.abs(ref.estimate), 1.0)
        assert np.max(np.abs(res.estimate - ref.estimate) / scale) < 1e-9, name
        assert res.relative_error.validation == pytest.approx(
            ref.relative_error.validation, rel=1e-9
        )
        assert res.context["friction_shapes"] == ref.context["friction_shapes"], name


def test_cli_npz_and_csv_column_map(robot, files, tmp_path):
    folder, _ = files
    common = ["identify", "double_pendulum", "--friction", LAW, "--quiet"]
    a, b = tmp_path / "npz.json", tmp_path / "csv.json"
    assert main([*common, "--data", str(folder / "run.npz"), "--json", str(a)]) == 0
    cols = [*("--column", "t=time", "--column", "q=p*", "--column", "dq=v*"),
            *("--column", "ddq=a*", "--column", "tau=e*")]  # fmt: skip
    argv = [*common, "--data", str(folder / "run.csv"), *cols, "--column", "temp=motor_temp"]
    assert main([*argv, "--json", str(b)]) == 0
    ra, rb = json.loads(a.read_text()), json.loads(b.read_text())
    va = {p["name"]: p["value"] for p in ra["base_parameters"]}
    vb = {p["name"]: p["value"] for p in rb["base_parameters"]}
    # the CSV's one column is joint 1's temperature; joint 2's is the same plus 4 K (and
    # its own sensor noise): only differences enter, so the slopes agree with the NPZ's
    for j, dof in enumerate(robot.dof_names):
        for name, true in (("fvt", FV1), ("fct", FC1)):
            assert vb[f"{dof}.{name}"] == pytest.approx(va[f"{dof}.{name}"], abs=2e-4)
            assert va[f"{dof}.{name}"] == pytest.approx(true[j], abs=1e-3)
    shapes = ra["friction_shapes"]["temperature_reference"]
    assert len(shapes) == 2 and shapes[1] - shapes[0] == pytest.approx(4.0, abs=0.01)


def test_cli_missing_temperature_is_one_line(files, capsys):
    folder, _ = files
    argv = ["identify", "double_pendulum", "--friction", LAW, "--data"]
    assert main([*argv, str(folder / "plain.npz")]) == 2
    out = capsys.readouterr()
    assert out.out == ""  # said before the pre-fit audit prints its table
    err = out.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("manip-id: error:")
    assert "temperature" in err[0] and "plain.npz" in err[0] and "temp array" in err[0]
    cols = [*("--column", "t=time", "--column", "q=p*", "--column", "dq=v*"),
            *("--column", "ddq=a*", "--column", "tau=e*")]  # fmt: skip
    assert main([*argv, str(folder / "run.csv"), *cols]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--column temp=" in err[0] and "run.csv" in err[0]
    with pytest.raises(MissingTemperatureError, match="no temp field"):
        identify(load_robot("double_pendulum", friction=LAW), load_dataset(folder / "plain.npz"))


def test_identify_arrays_without_temperature_is_refused(robot):
    t, q, dq, ddq, tau, _ = _record(robot, duration=5.0)
    with pytest.raises(MissingTemperatureError):
        identify(load_robot("double_pendulum", friction=LAW), (q, dq, ddq, tau))


# ------------------------------------------------------------------- export
def test_sidecar_round_trip(robot, files, tmp_path):
    folder, rec = files
    r = load_robot("double_pendulum", friction=LAW)
    ds = load_dataset(folder / "run.npz")
    res = identify(r, ds, consistent=True)
    t0 = tuple(res.context["friction_shapes"]["temperature_reference"])
    fit = r.with_terms(JointTerms(viscous=True, coulomb=True, temperature=True,
                                  shapes=FrictionShapes(temperature_reference=t0)))  # fmt: skip
    theta = res.standard.values
    out = tmp_path / "hot.urdf"
    export_urdf(fit, theta, out)
    side = json.loads(out.with_name("hot.identified.json").read_text())
    assert side["joint_model"]["temperature"] is True
    assert side["joint_model"]["shapes"]["temperature_reference"] == list(t0)
    back = load_robot(out, identified=True)
    assert back.terms == fit.terms
    traj = random_trajectory(robot, harmonics=4, wf=0.4, seed=9)
    t = np.arange(300) / 100.0
    q, dq, ddq = traj.sample(t)
    temp = 50.0 - 10.0 * t[:, None] / t[-1]  # other temperatures than the fit's
    expected = np.einsum("njp,p->nj", regressor(fit, q, dq, ddq, temp=temp), theta)
    got = inverse_dynamics(back, back.nominal_parameters, q, dq, ddq, temp=temp)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9 * np.abs(expected).max())
    # the joint terms are the sidecar's coefficients in the law written out
    exported = back.with_parameters(back.nominal_parameters)
    d = exported.createData()
    rigid = np.array([pin.rnea(exported, d, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
    for j, dof in enumerate(back.dof_names):
        c = side["joints"][dof]
        dt = temp[:, 0] - t0[j]
        law = (c["fv"] + c["fvt"] * dt) * dq[:, j] + (c["fc"] + c["fct"] * dt) * np.sign(dq[:, j])
        np.testing.assert_allclose(got[:, j] - rigid[:, j], law, atol=1e-9)


# ---------------------------------------------------------------- selection
def test_auto_adds_the_temperature_candidate_only_with_a_temperature(robot, files, tmp_path):
    folder, _ = files
    argv = ["identify", "double_pendulum", "--friction", "auto", "--split", "0.7", "--quiet"]
    hot, plain = tmp_path / "hot.json", tmp_path / "plain.json"
    assert main([*argv, "--data", str(folder / "run.npz"), "--json", str(hot)]) == 0
    assert main([*argv, "--data", str(folder / "plain.npz"), "--json", str(plain)]) == 0
    rh, rp = json.loads(hot.read_text()), json.loads(plain.read_text())
    for j in rh["friction_selection"]:
        models = [c["model"] for c in j["candidates"]]
        assert "temperature" in models
        assert j["chosen"].startswith("temperature")  # the truth's law, by validation error
    assert len(rh["friction_shapes"]["temperature_reference"]) == 2
    for j in rp["friction_selection"]:  # no temperature: the candidates of before
        assert not any(c["model"].startswith("temperature") for c in j["candidates"])
    assert rp["friction_shapes"]["temperature_reference"] is None
    assert rh["relative_error"]["validation"] < 0.5 * rp["relative_error"]["validation"]


# --------------------------------------------------------------- consistent
@pytest.mark.parametrize("solver", ["sdp", "logchol"])
def test_consistent_friction_stays_physical_over_the_temperature_range(robot, monkeypatch, solver):
    # a truth whose viscous friction would turn negative above 40 degC: least squares
    # follows it, the consistent estimate keeps fv(T) >= 0 at the range's ends
    monkeypatch.setattr(sys.modules[__name__], "FV0", np.array([0.02, 0.2]))
    rec = _record(robot, seed=5, duration=20.0)
    r = load_robot("double_pendulum", friction=LAW)
    ls = identify(r, _dataset(robot, rec))
    res = identify(r, _dataset(robot, rec), consistent={"solver": solver})
    shapes = res.context["friction_shapes"]
    t0, lo, hi = (np.array(shapes[k]) for k in ("temperature_reference", "temperature_low",
                                                 "temperature_high"))  # fmt: skip
    np.testing.assert_allclose(lo, rec[5].min(axis=0))
    np.testing.assert_allclose(hi, rec[5].max(axis=0))
    names, theta = r.parameter_names, res.standard.values  # the standard parameters

    def law(th, base, slope, end):
        return np.array([th[names.index(f"{d}.{base}")] + th[names.index(f"{d}.{slope}")]
                         * (end[j] - t0[j]) for j, d in enumerate(r.dof_names)])  # fmt: skip

    fv_ls = _coef(ls, r, "fv") + _coef(ls, r, "fvt") * (hi - t0)
    assert fv_ls[0] < -0.02  # least squares: negative viscous friction when hot
    for base, slope in (("fv", "fvt"), ("fc", "fct")):
        for end in (lo, hi):
            assert np.all(law(theta, base, slope, end) >= -1e-7)
    assert abs(law(theta, "fv", "fvt", hi)[0]) < 1e-6  # the constraint binds


def test_the_law_is_refused_where_there_is_no_temperature(robot):
    from manip_id.control.closed_loop import Plant
    from manip_id.models import accumulate_energy
    from manip_id.robot.regressor import slotine_li_regressor

    r = load_robot("double_pendulum", friction=LAW)
    _, q, dq, ddq, tau, _ = _record(robot, duration=2.0)
    for call in (
        lambda: accumulate_energy(r, q, dq, tau, dt=1 / RATE),
        lambda: slotine_li_regressor(r, q[0], dq[0], ddq[0], dq[0]),
        lambda: Plant(r, r.nominal_parameters, rate=100.0),
    ):
        with pytest.raises(InputError, match="temperature friction law"):
            call()


def test_cli_online_method_and_report_carry_the_temperature(robot, files, tmp_path):
    folder, _ = files
    argv = ["identify", "double_pendulum", "--friction", LAW, "--quiet", "--split", "0.7"]
    out = tmp_path / "rls.json"
    data = ["--data", str(folder / "run.npz")]
    assert main([*argv, *data, "--method", "rls", "--json", str(out)]) == 0
    values = {p["name"]: p["value"] for p in json.loads(out.read_text())["base_parameters"]}
    for j, dof in enumerate(robot.dof_names):
        assert values[f"{dof}.fvt"] == pytest.approx(FV1[j], abs=1e-3)
        assert values[f"{dof}.fct"] == pytest.approx(FC1[j], abs=1e-3)
    report = tmp_path / "report"  # its figures predict the torques: with the temperature
    assert main([*argv, *data, "--report", str(report)]) == 0
    assert (report / "index.html").is_file() and (report / "residuals.png").is_file()
    assert json.loads((report / "result.json").read_text())["relative_error"]["validation"] < (
        3 * NOISE
    )


def test_cli_bag_and_simulate_refuse_the_law_in_one_line(files, tmp_path, capsys):
    folder, _ = files
    bag = tmp_path / "run.mcap"
    assert main(["convert", str(folder / "run.npz"), str(bag)]) == 0
    assert "temp not carried by JointState" in capsys.readouterr().out
    for argv in (["--data", str(bag)], ["--simulate"]):
        assert main(["identify", "double_pendulum", "--friction", LAW, *argv]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("manip-id: error:")
        assert "temperature" in err[0]
    # the bag's own message: a JointState carries no temperature
    assert main(["identify", "double_pendulum", "--friction", LAW, "--data", str(bag)]) == 2
    assert "JointState bag carries no temperature" in capsys.readouterr().err


def test_csv_temperature_columns_by_header_and_by_map(tmp_path):
    from manip_id.errors import DataError

    t = np.arange(5) / 10.0
    head = "t,q_a,q_b,dq_a,dq_b,tau_a,tau_b"
    rows = np.column_stack([t, np.zeros((5, 6))])
    per_joint = tmp_path / "per_joint.csv"
    per_joint.write_text(head + ",temp_a,temp_b\n" + "\n".join(
        ",".join(map(str, [*r, 30.0 + k, 31.0 + k])) for k, r in enumerate(rows)))  # fmt: skip
    ds = load_dataset(per_joint)
    np.testing.assert_allclose(ds.temp, np.column_stack([30 + np.arange(5), 31 + np.arange(5)]))
    three = tmp_path / "three.csv"  # temp_ columns that are not one per joint: not ours
    three.write_text(head + ",temp_x,temp_y,temp_z\n" + "\n".join(
        ",".join(map(str, [*r, 1.0, 2.0, 3.0])) for r in rows))  # fmt: skip
    assert load_dataset(three).temp is None
    with pytest.raises(DataError, match="3 temp columns but 2 tau columns"):
        load_dataset(three, columns={"temp": "temp_*"})
    one = load_dataset(three, columns={"temp": "temp_y"})
    np.testing.assert_allclose(one.temp, np.full((5, 1), 2.0))
