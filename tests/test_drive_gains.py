"""Drive-gain identification (Gautier & Briot) against currents made here with Pinocchio.

Currents are ``rnea(model) / g`` per joint, for the unloaded model and for the model
whose frame's parent joint carries the payload; the truth is ``g``.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot
from test_payload import loaded_model, make_payload, make_runs, rnea_run, truth

from manip_id.errors import DataError, InputError
from manip_id.identifiability import analyze
from manip_id.payload import (
    PayloadWarning,
    identify_drive_gains,
    load_torque_scale,
)
from manip_id.robot.model import JointTerms, Robot

GAINS_UR5 = np.array([0.45, 0.8, 1.1, 1.4, 1.7, 2.3])  # [N m / A]


@pytest.fixture(scope="module")
def ur5():
    return get_robot("ur5")


@pytest.fixture(scope="module")
def ur5_base(ur5):
    return analyze(ur5).base


@pytest.mark.parametrize("method", ["ml", "ols", "wls", "tls"])
def test_noise_free_gains(ur5, ur5_base, method):
    payload = make_payload()
    u, ld = make_runs(ur5, "tool0", payload, n=500, gains=GAINS_UR5)
    res = identify_drive_gains(ur5, u, ld, "tool0", payload.mass, method=method, base=ur5_base)
    assert res.determined.all()
    assert np.allclose(res.gains, GAINS_UR5, rtol=0, atol=1e-6)
    # the payload's unknown parameters and the base parameters in torque units
    assert np.allclose(res.payload.values[1:], truth(payload)[1:], atol=1e-6)
    assert res.payload.known[0] and not res.payload.known[1:].any()
    assert np.allclose(res.base_estimate, ur5_base.to_base(ur5.nominal_parameters), atol=1e-6)
    d = res.to_dict()
    assert [g["joint"] for g in d["drive_gains"]] == ur5.dof_names
    assert d["torque_scale"] == pytest.approx(GAINS_UR5.tolist(), abs=1e-6)
    assert d["payload"]["mass"] == payload.mass and d["payload"]["mass_std"] is None
    json.dumps(d)


def test_known_com_and_inertia(ur5, ur5_base):
    payload = make_payload()
    u, ld = make_runs(ur5, "tool0", payload, n=400, gains=GAINS_UR5)
    want = truth(payload)
    res = identify_drive_gains(
        ur5,
        u,
        ld,
        "tool0",
        want[0],
        payload_com=want[1:4],
        payload_inertia=want[4:],
        base=ur5_base,
    )
    assert np.allclose(res.gains, GAINS_UR5, atol=1e-6)
    assert res.payload.known.all()
    assert res.to_dict()["payload"]["known"][0] == "mass"


def _monte_carlo(ur5, ur5_base, method: str, noise, seeds=range(10), white=False):
    """Gains over seeds of current noise (``noise`` [A] per joint); (estimates, z-scores
    against the honest std, or the white-noise std with ``white``)."""
    payload = make_payload(2.0, (0.03, -0.02, 0.1))
    m0, m1 = loaded_model(ur5, "tool0", payload)
    clean_u = rnea_run(ur5, m0, 500, 10, gains=GAINS_UR5)
    clean_l = rnea_run(ur5, m1, 500, 11, gains=GAINS_UR5)
    est, zs = [], []
    for seed in seeds:
        rng = np.random.default_rng(500 + seed)
        u = (*clean_u[:3], clean_u[3] + noise * rng.standard_normal(clean_u[3].shape))
        ld = (*clean_l[:3], clean_l[3] + noise * rng.standard_normal(clean_l[3].shape))
        res = identify_drive_gains(ur5, u, ld, "tool0", payload.mass, method=method, base=ur5_base)
        est.append(res.gains)
        zs.append((res.gains - GAINS_UR5) / (res.gains_std_white if white else res.gains_std))
    return np.array(est), np.array(zs), res.gains_std, clean_u[3]


def test_noisy_gains_within_predicted_uncertainty_ml(ur5, ur5_base):
    """Monte Carlo, 10 seeds of 0.02 A current noise (wrist_3's current is 0.07 A RMS
    unloaded): ML gains are within their predicted std."""
    est, zs, std, _ = _monte_carlo(ur5, ur5_base, "ml", 0.02)
    assert np.abs(zs).max() < 4.0
    assert 0.3 < np.mean(zs**2) < 2.0
    assert np.all(np.abs(zs.mean(axis=0)) < 3.0 / np.sqrt(len(zs)) * 1.5)
    ratio = np.std(est, axis=0, ddof=1) / std
    assert np.all((ratio > 0.4) & (ratio < 1.9)), ratio


@pytest.mark.parametrize("method", ["ols", "wls"])
def test_noisy_gains_within_predicted_uncertainty_ols(ur5, ur5_base, method):
    """OLS/WLS where their assumptions hold: current noise whose torque equivalent
    ``g_j sigma_j`` = 0.002 N m is the same on every joint and small against the
    currents (wrist_3: 0.0009 A against 0.07 A RMS)."""
    est, zs, std, _ = _monte_carlo(ur5, ur5_base, method, 0.002 / GAINS_UR5)
    assert np.abs(zs).max() < 4.0
    assert 0.3 < np.mean(zs**2) < 2.0
    ratio = np.std(est, axis=0, ddof=1) / std
    assert np.all((ratio > 0.4) & (ratio < 1.9)), ratio


def test_ols_shrinks_a_noisy_small_current_ml_does_not(ur5, ur5_base):
    """Errors in variables: with 0.02 A of noise on wrist_3's 0.07 A current, OLS's gain
    comes out low by several predicted (white-noise, as the noise is white) std, on every
    seed; ML's does not."""
    # OLS warns that its wrist_3 gain is far from ML's (the bias this test shows)
    with pytest.warns(PayloadWarning, match="OLS drive gain differs.*wrist_3_joint"):
        _, z_ols, _, _ = _monte_carlo(ur5, ur5_base, "ols", 0.02, seeds=range(5), white=True)
    _, z_ml, _, _ = _monte_carlo(ur5, ur5_base, "ml", 0.02, seeds=range(5))
    assert np.all(z_ols[:, 5] < -3.0)
    assert np.all(np.abs(z_ml[:, 5]) < 3.5)


def test_a_gain_far_from_the_ml_gain_is_named(ur5, ur5_base):
    """OLS/WLS/TLS with 0.02 A of noise on wrist_3's 0.07 A current: its gain is more than 3
    of its std from the ML gain of the same data, and the warning names wrist_3_joint
    (and only it); where OLS's assumptions hold (0.002 N m of torque noise), none. The
    test uses the honest std (larger than the white one for OLS here: the noise in the
    regressor makes the residuals heteroskedastic), so 2000 samples per run."""
    payload = make_payload(2.0, (0.03, -0.02, 0.1))
    m0, m1 = loaded_model(ur5, "tool0", payload)
    u0 = rnea_run(ur5, m0, 2000, 10, gains=GAINS_UR5)
    l0 = rnea_run(ur5, m1, 2000, 11, gains=GAINS_UR5)
    rng = np.random.default_rng(7)

    def noisy(run, sigma):
        return (*run[:3], run[3] + sigma * rng.standard_normal(run[3].shape))

    for method in ("ols", "wls", "tls"):
        with pytest.warns(PayloadWarning, match="maximum-likelihood") as record:
            res = identify_drive_gains(
                ur5, noisy(u0, 0.02), noisy(l0, 0.02), "tool0", 2.0, method=method, base=ur5_base
            )
        text = [str(w.message) for w in record if "maximum-likelihood" in str(w.message)]
        assert len(text) == 1 and "wrist_3_joint" in text[0] and "shoulder_pan" not in text[0]
        assert text[0] in res.warnings
    small = 0.002 / GAINS_UR5
    with warnings.catch_warnings():
        warnings.simplefilter("error", PayloadWarning)
        res = identify_drive_gains(
            ur5, noisy(u0, small), noisy(l0, small), "tool0", 2.0, method="ols", base=ur5_base
        )
    assert res.warnings == []


def _planar_with_turntable() -> Robot:
    """A vertical turntable (z) carrying a two-link arm whose axes are horizontal (y);
    diagonal inertias, centres of mass in the arm's x-z plane."""
    model = pin.Model()
    j1 = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "turn")
    model.appendBodyToJoint(
        j1,
        pin.Inertia(3.0, np.array([0.0, 0.0, 0.1]), np.diag([0.05, 0.05, 0.02])),
        pin.SE3.Identity(),
    )
    j2 = model.addJoint(
        j1, pin.JointModelRY(), pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.3])), "shoulder"
    )
    model.appendBodyToJoint(
        j2,
        pin.Inertia(2.0, np.array([0.2, 0.0, 0.0]), np.diag([0.01, 0.03, 0.03])),
        pin.SE3.Identity(),
    )
    j3 = model.addJoint(
        j2, pin.JointModelRY(), pin.SE3(np.eye(3), np.array([0.4, 0.0, 0.0])), "elbow"
    )
    model.appendBodyToJoint(
        j3,
        pin.Inertia(1.0, np.array([0.15, 0.0, 0.02]), np.diag([0.005, 0.01, 0.01])),
        pin.SE3.Identity(),
    )
    model.addFrame(
        pin.Frame("tool", j3, pin.SE3(np.eye(3), np.array([0.3, 0.0, 0.0])), pin.FrameType.OP_FRAME)
    )
    for name in ("lowerPositionLimit", "upperPositionLimit"):
        setattr(model, name, np.full(3, -2.5 if name.startswith("lower") else 2.5))
    model.velocityLimit = np.full(3, 2.0)
    model.effortLimit = np.full(3, 100.0)
    return Robot("turntable_arm", model, JointTerms())


def test_gain_of_unloaded_vertical_axis_is_named():
    """The turntable never turns and the arm moves in its plane: joint 1 carries no
    torque at all (angular momentum about z stays zero), so its gain is undetermined."""
    robot = _planar_with_turntable()
    payload = pin.Inertia(1.5, np.array([0.05, 0.0, 0.03]), np.diag([0.004, 0.006, 0.005]))
    gains = np.array([0.7, 1.2, 1.9])
    u, ld = make_runs(robot, "tool", payload, n=400, gains=gains, still=(0,))
    assert np.abs(u[3][:, 0]).max() < 1e-12  # the premise, by Pinocchio alone
    for method in ("ml", "ols"):
        with pytest.warns(PayloadWarning) as record:
            res = identify_drive_gains(robot, u, ld, "tool", payload.mass, method=method)
        texts = [str(r.message) for r in record]
        assert any("drive gain of turn" in t for t in texts)
        assert any("unexcited: turn.IzzR" in t for t in texts)  # its own inertia, too
        assert res.determined.tolist() == [False, True, True]
        assert np.allclose(res.gains[1:], gains[1:], atol=1e-6)
    d = res.to_dict()
    assert d["drive_gains"][0]["gain"] is None and not d["drive_gains"][0]["determined"]
    assert any("turn" in w for w in d["warnings"])
    # once the turntable moves, every gain is determined
    u2, ld2 = make_runs(robot, "tool", payload, n=400, gains=gains)
    with warnings.catch_warnings():
        warnings.simplefilter("error", PayloadWarning)
        res2 = identify_drive_gains(robot, u2, ld2, "tool", payload.mass)
    assert np.allclose(res2.gains, gains, atol=1e-6)


def test_bad_inputs(ur5, ur5_base):
    payload = make_payload()
    u, ld = make_runs(ur5, "tool0", payload, n=200, gains=GAINS_UR5)
    for mass in (0.0, -1.0, float("nan")):
        with pytest.raises(InputError, match="mass must be > 0"):
            identify_drive_gains(ur5, u, ld, "tool0", mass, base=ur5_base)
    with pytest.raises(InputError, match="needs its centre of mass"):
        identify_drive_gains(ur5, u, ld, "tool0", 1.0, payload_inertia=np.ones(6))
    with pytest.raises(InputError, match="no frame"):
        identify_drive_gains(ur5, u, ld, "flange", 1.0)
    with pytest.raises(DataError, match="same data"):
        identify_drive_gains(ur5, u, u, "tool0", 1.0, base=ur5_base)
    with pytest.raises(InputError, match="method"):
        identify_drive_gains(ur5, u, ld, "tool0", 1.0, method="lm")
    # on the upper arm the mass only enters with m c_y and I_zz: it cannot fix the scale
    with pytest.raises(InputError, match="cannot fix the scale"):
        identify_drive_gains(ur5, u, ld, "upper_arm_link", 1.0, base=ur5_base)


def test_torque_scale_file(tmp_path, ur5, ur5_base):
    payload = make_payload()
    u, ld = make_runs(ur5, "tool0", payload, n=300, gains=GAINS_UR5)
    res = identify_drive_gains(ur5, u, ld, "tool0", payload.mass, base=ur5_base)
    path = tmp_path / "gains.json"
    path.write_text(json.dumps(res.to_dict()))
    assert np.allclose(load_torque_scale(path, ur5), GAINS_UR5, atol=1e-6)
    doc = res.to_dict()
    doc["drive_gains"][2]["gain"] = None
    path.write_text(json.dumps(doc))
    with pytest.raises(DataError, match="elbow_joint was not determined"):
        load_torque_scale(path)
    doc = res.to_dict()
    doc["drive_gains"] = doc["drive_gains"][::-1]
    path.write_text(json.dumps(doc))
    with pytest.raises(DataError, match="joints"):
        load_torque_scale(path, ur5)
    path.write_text("{}")
    with pytest.raises(DataError, match="drive_gains"):
        load_torque_scale(path)


def test_loaded_runs_without_the_payload_are_refused(ur5, ur5_base):
    payload = make_payload()
    m0, _ = loaded_model(ur5, "tool0", payload)
    u = rnea_run(ur5, m0, 300, 1, noise=0.01, gains=GAINS_UR5)
    other = rnea_run(ur5, m0, 300, 2, noise=0.01, gains=GAINS_UR5)  # no payload mounted
    with pytest.raises(DataError, match="no payload information"):
        identify_drive_gains(ur5, u, other, "tool0", payload.mass, base=ur5_base)
