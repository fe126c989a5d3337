"""Payload identification against data made here with Pinocchio alone.

The loaded robot is the Pinocchio model whose parent-joint inertia of the frame carries
the payload, ``model.inertias[j] += frame_placement.act(payload)``; torques are
``pinocchio.rnea`` of the unloaded and of the loaded model. Nothing of manip_id makes
the data.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id.errors import DataError, InputError, RankDeficiencyError
from manip_id.identifiability import analyze
from manip_id.identification import identify
from manip_id.payload import (
    INERTIA_COMPONENTS,
    KnownBase,
    PayloadWarning,
    identify_payload,
    load_known_base,
    payload_frame,
    payload_quantities,
    payload_regressor,
    payload_transform,
    standard_from_quantities,
)

SYM6 = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))


def make_payload(mass=1.3, com=(0.02, -0.03, 0.08), seed=None) -> pin.Inertia:
    """A physical payload: mass [kg], CoM [m], a positive-definite inertia about the CoM."""
    rot = pin.utils.rotate("z", 0.4) @ pin.utils.rotate("x", -0.3)
    Ic = rot @ np.diag([0.010, 0.012, 0.006]) @ rot.T  # [kg m^2]
    return pin.Inertia(mass, np.asarray(com, dtype=float), Ic)


def truth(payload: pin.Inertia) -> np.ndarray:
    """[m, c (3), I_c (6)] of a Pinocchio inertia, straight from its fields."""
    Ic = payload.inertia
    return np.r_[payload.mass, payload.lever, [Ic[a, b] for a, b in SYM6]]


def loaded_model(robot, frame: str, payload: pin.Inertia) -> tuple[pin.Model, pin.Model]:
    """(unloaded, loaded) Pinocchio models: the payload added to the frame's parent joint."""
    model = robot.model
    fid = model.getFrameId(frame)
    f = model.frames[fid]
    m0 = model.copy()
    m0.armature[:] = 0.0
    m1 = m0.copy()
    m1.inertias[f.parentJoint] = m1.inertias[f.parentJoint] + f.placement.act(payload)
    return m0, m1


def rnea_run(robot, model, n: int, seed: int, noise: float = 0.0, gains=None, still=()):
    """(q, dq, ddq, tau) at ``n`` random states by pinocchio.rnea; ``noise`` [N m] Gaussian;
    ``gains`` divides the torque (currents); joints in ``still`` do not move."""
    rng = np.random.default_rng(seed)
    q, dq, ddq = robot.random_states(n, seed=seed)
    for j in still:
        q[:, j] = 0.3
        dq[:, j] = 0.0
        ddq[:, j] = 0.0
    data = model.createData()
    tau = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(n)])
    if noise:
        tau = tau + noise * rng.standard_normal(tau.shape)
    if gains is not None:
        tau = tau / np.asarray(gains)
    return q, dq, ddq, tau


def make_runs(robot, frame, payload, n=600, seed=0, noise=0.0, gains=None, still=()):
    m0, m1 = loaded_model(robot, frame, payload)
    u = rnea_run(robot, m0, n, 2 * seed, noise, gains, still)
    ld = rnea_run(robot, m1, n, 2 * seed + 1, noise, gains, still)
    return u, ld


@pytest.fixture(scope="module")
def ur5():
    return get_robot("ur5")


@pytest.fixture(scope="module")
def ur5_base(ur5):
    return analyze(ur5).base


@pytest.fixture(scope="module")
def pendulum():
    return get_robot("double_pendulum")


# ------------------------------------------------------------------- geometry
def test_transform_is_pinocchio_se3_action():
    pin.seed(0)  # pin.SE3.Random and pin.Inertia.Random draw from Eigen's generator
    for _ in range(5):
        M = pin.SE3.Random()
        T = payload_transform(M)
        for _ in range(3):
            inertia = pin.Inertia.Random()
            want = M.act(inertia).toDynamicParameters()
            assert np.allclose(T @ inertia.toDynamicParameters(), want, atol=1e-12)
        # linear, so it holds for non-physical vectors too (sums of physical ones)
        a, b = pin.Inertia.Random(), pin.Inertia.Random()
        x = a.toDynamicParameters() - 2.0 * b.toDynamicParameters()
        want = M.act(a).toDynamicParameters() - 2.0 * M.act(b).toDynamicParameters()
        assert np.allclose(T @ x, want, atol=1e-12)


@pytest.mark.parametrize(("name", "frame"), [("ur5", "tool0"), ("double_pendulum", "link2")])
def test_payload_regressor_is_rnea_difference_and_frame_body_regressor(name, frame):
    robot = get_robot(name)
    payload = make_payload()
    m0, m1 = loaded_model(robot, frame, payload)
    d0, d1 = m0.createData(), m1.createData()
    q, dq, ddq = robot.random_states(20, seed=4)
    Yp = payload_regressor(robot, frame, q, dq, ddq)
    phi = payload.toDynamicParameters()
    fid = m0.getFrameId(frame)
    for k in range(20):
        diff = pin.rnea(m1, d1, q[k], dq[k], ddq[k]) - pin.rnea(m0, d0, q[k], dq[k], ddq[k])
        assert np.allclose(Yp[k] @ phi, diff, atol=1e-10)
        # J_f^T (frame body regressor @ phi): Pinocchio's own frame wrench
        pin.rnea(m0, d0, q[k], dq[k], ddq[k])
        pin.updateFramePlacements(m0, d0)
        wrench = pin.frameBodyRegressor(m0, d0, fid) @ phi
        J = pin.computeFrameJacobian(m0, d0, q[k], fid, pin.LOCAL)
        assert np.allclose(J.T @ wrench, Yp[k] @ phi, atol=1e-10)


def test_quantities_and_their_jacobian():
    payload = make_payload()
    phi = payload.toDynamicParameters()
    values, G = payload_quantities(phi)
    assert np.allclose(values, truth(payload), atol=1e-14)
    eps = 1e-6
    for i in range(10):
        e = np.zeros(10)
        e[i] = eps
        fd = (payload_quantities(phi + e)[0] - payload_quantities(phi - e)[0]) / (2 * eps)
        assert np.allclose(G[:, i], fd, atol=1e-7)
    back = standard_from_quantities(values[0], values[1:4], values[4:])
    assert np.allclose(back, phi, atol=1e-14)


def test_unknown_and_fixed_frames(ur5):
    with pytest.raises(InputError, match="no frame 'tool9'.*tool0"):
        payload_frame(ur5, "tool9")
    with pytest.raises(InputError, match="fixed to the base"):
        payload_frame(ur5, "base_link")


# ------------------------------------------------------------------ noise-free
def test_noise_free_recovery_ur5(ur5, ur5_base):
    payload = make_payload()
    u, ld = make_runs(ur5, "tool0", payload)
    res = identify_payload(ur5, u, ld, "tool0", base=ur5_base)
    p = res.payload
    assert p.identifiable.all()
    assert np.allclose(p.values, truth(payload), rtol=0, atol=1e-6)
    assert abs(p.mass - payload.mass) < 1e-6
    assert np.allclose(p.com, payload.lever, atol=1e-6)
    assert p.physically_consistent is True
    # the robot's base parameters too (against Pinocchio's URDF inertias)
    assert np.allclose(res.base_estimate, ur5_base.to_base(ur5.nominal_parameters), atol=1e-6)
    d = res.to_dict()
    assert d["payload"]["mass"] == pytest.approx(payload.mass, abs=1e-6)
    assert d["payload"]["inertia_components"] == list(INERTIA_COMPONENTS)
    assert d["payload"]["not_identifiable"] == []
    json.dumps(d)


def test_last_joint_of_planar_arm_hides_components(pendulum):
    """Payload on link2 of the double pendulum (both axes along x): torques see m, m c_y,
    m c_z and the inertia about x, nothing else (c_x lies along the axis)."""
    assert pendulum.model.joints[2].shortname() == "JointModelRX"
    payload = make_payload()
    u, ld = make_runs(pendulum, "link2", payload, n=400)
    with pytest.warns(PayloadWarning, match="com.x"):
        res = identify_payload(pendulum, u, ld, "link2")
    p = res.payload
    d = p.to_dict()
    assert set(d["not_identifiable"]) == {
        "com.x",
        "inertia.Ixy",
        "inertia.Iyy",
        "inertia.Ixz",
        "inertia.Iyz",
        "inertia.Izz",
    }
    assert d["identifiable"] == ["mass", "com.y", "com.z", "inertia.Ixx"]
    want = truth(payload)
    assert d["mass"] == pytest.approx(want[0], abs=1e-6)
    assert d["com"][1:] == pytest.approx(want[2:4], abs=1e-6)
    assert d["com"][0] is None and d["com_std"][0] is None
    assert d["inertia"][0] == pytest.approx(want[4], abs=1e-6)
    assert p.physically_consistent is None  # the free directions decide
    with pytest.warns(PayloadWarning, match="not identifiable"):
        res_c = identify_payload(pendulum, u, ld, "link2", consistent=True)
    lam = np.linalg.eigvalsh(_pseudo_inertia(res_c.payload.standard))
    assert lam[0] > 0 and res_c.payload.physically_consistent is True
    assert res_c.payload.mass == pytest.approx(want[0], abs=1e-6)


def _pseudo_inertia(phi):
    """J = [[0.5 tr(I) 1 - I, h], [h^T, m]], written here from its definition."""
    m, h = phi[0], phi[1:4]
    xx, xy, yy, xz, yz, zz = phi[4:]
    inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    J = np.zeros((4, 4))
    J[:3, :3] = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    J[:3, 3] = J[3, :3] = h
    J[3, 3] = m
    return J


def test_known_base_equals_joint_fit(ur5, ur5_base):
    payload = make_payload(0.8, (0.0, 0.05, 0.1))
    u, ld = make_runs(ur5, "tool0", payload)
    earlier = identify(ur5, tuple(u), base=ur5_base)
    res = identify_payload(ur5, None, ld, "tool0", known_base=earlier, base=ur5_base)
    assert res.known_base
    assert np.allclose(res.payload.values, truth(payload), atol=1e-6)
    # the same from the JSON file of an identification
    kb = KnownBase.from_result(earlier)
    assert kb.names == list(ur5_base.base_names)


def test_known_base_from_json(tmp_path, ur5, ur5_base):
    doc = {
        "robot": "ur5",
        "base_parameters": [
            {"name": n, "value": float(v), "std": 0.0}
            for n, v in zip(
                ur5_base.base_names, ur5_base.to_base(ur5.nominal_parameters), strict=True
            )
        ],
    }
    path = tmp_path / "id.json"
    path.write_text(json.dumps(doc))
    kb = load_known_base(path)
    payload = make_payload()
    _, ld = make_runs(ur5, "tool0", payload, n=300)
    res = identify_payload(ur5, None, ld, "tool0", known_base=kb, base=ur5_base)
    assert np.allclose(res.payload.values, truth(payload), atol=1e-6)
    doc["robot"] = "ur10"
    path.write_text(json.dumps(doc))
    with pytest.raises(DataError, match="ur10"):
        identify_payload(ur5, None, ld, "tool0", known_base=load_known_base(path), base=ur5_base)
    doc["robot"] = "ur5"
    doc["base_parameters"] = doc["base_parameters"][:-1]
    path.write_text(json.dumps(doc))
    with pytest.raises(DataError, match="do not match"):
        identify_payload(ur5, None, ld, "tool0", known_base=load_known_base(path), base=ur5_base)


# ------------------------------------------------------------------ with noise
def test_noisy_recovery_within_predicted_uncertainty(ur5, ur5_base):
    """Monte Carlo over 12 noise seeds: errors scaled by the predicted std are N(0, 1)-like."""
    payload = make_payload()
    want = truth(payload)
    m0, m1 = loaded_model(ur5, "tool0", payload)
    clean_u = rnea_run(ur5, m0, 500, 100)
    clean_l = rnea_run(ur5, m1, 500, 101)
    z, est = [], []
    for seed in range(12):
        rng = np.random.default_rng(1000 + seed)
        u = (*clean_u[:3], clean_u[3] + 0.05 * rng.standard_normal(clean_u[3].shape))
        ld = (*clean_l[:3], clean_l[3] + 0.05 * rng.standard_normal(clean_l[3].shape))
        p = identify_payload(ur5, u, ld, "tool0", base=ur5_base).payload
        z.append((p.values - want) / p.std)
        est.append(p.values)
    z = np.array(z)
    assert np.abs(z).max() < 4.5
    assert 0.4 < np.mean(z**2) < 1.8
    # empirical spread of mass and CoM against the predicted std
    spread = np.std(np.array(est)[:, :4], axis=0, ddof=1)
    ratio = spread / p.std[:4]
    assert np.all((ratio > 0.45) & (ratio < 1.8)), ratio


def test_consistent_payload_is_physical(ur5, ur5_base):
    """A point-like payload (tiny inertia about its CoM) under noise: OLS leaves J
    indefinite, the consistent fit keeps it positive definite near the OLS estimate."""
    payload = pin.Inertia(0.5, np.array([0.0, 0.0, 0.05]), np.diag([1e-6, 1e-6, 1e-6]))
    for seed in range(6):
        u, ld = make_runs(ur5, "tool0", payload, n=300, seed=seed, noise=0.2)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PayloadWarning)
            ols = identify_payload(ur5, u, ld, "tool0", base=ur5_base)
        if np.linalg.eigvalsh(_pseudo_inertia(ols.payload.standard))[0] < 0:
            break
    else:
        pytest.fail("no seed gave an indefinite OLS payload")
    assert ols.payload.physically_consistent is False
    cons = identify_payload(ur5, u, ld, "tool0", base=ur5_base, consistent=True)
    assert np.linalg.eigvalsh(_pseudo_inertia(cons.payload.standard))[0] > 0
    assert cons.payload.physically_consistent is True
    assert abs(cons.payload.mass - ols.payload.mass) < 4 * ols.payload.std[0]
    assert "Clarabel" in cons.solver


# ------------------------------------------------------------------ bad input
def test_loaded_runs_without_payload_information(ur5, ur5_base):
    payload = make_payload()
    u, ld = make_runs(ur5, "tool0", payload, n=300)
    with pytest.raises(DataError, match="same data"):
        identify_payload(ur5, u, u, "tool0", base=ur5_base)
    # other runs, still without the payload
    other = rnea_run(ur5, loaded_model(ur5, "tool0", payload)[0], 300, 77, noise=0.01)
    with pytest.raises(DataError, match="no payload information"):
        identify_payload(ur5, u, other, "tool0", base=ur5_base)


def test_bad_inputs(ur5, ur5_base, pendulum):
    payload = make_payload()
    u, ld = make_runs(ur5, "tool0", payload, n=200)
    with pytest.raises(InputError, match="tool0"):
        identify_payload(ur5, u, ld, "gripper", base=ur5_base)
    with pytest.raises(InputError, match="no loaded runs"):
        identify_payload(ur5, u, [], "tool0", base=ur5_base)
    with pytest.raises(InputError, match="no unloaded runs"):
        identify_payload(ur5, None, ld, "tool0", base=ur5_base)
    with pytest.raises(InputError, match="method"):
        identify_payload(ur5, u, ld, "tool0", method="tls")
    pu, _ = make_runs(pendulum, "link2", payload, n=200)
    with pytest.raises(InputError, match="unloaded run 0"):  # a double pendulum's runs
        identify_payload(ur5, pu, ld, "tool0", base=ur5_base)

    class Named:  # a dataset-like object naming other joints
        def __init__(self, block, names):
            self.q, self.dq, self.ddq, self.tau = block
            self.joint_names = names

    names = [f"j{i}" for i in range(6)]
    with pytest.raises(DataError, match="names the joints"):
        identify_payload(ur5, u, Named(ld, names), "tool0", base=ur5_base)


def test_unexcited_payload_is_named(ur5, ur5_base):
    """Loaded runs where the wrist never moves and stays at one pose: the payload's
    inertia is not excited, and the error says which directions."""
    payload = make_payload()
    m0, m1 = loaded_model(ur5, "tool0", payload)
    u = rnea_run(ur5, m0, 400, 5)
    ld = rnea_run(ur5, m1, 400, 6, still=(0, 1, 2, 3, 4, 5))
    with pytest.raises(RankDeficiencyError, match="payload"):
        identify_payload(ur5, u, ld, "tool0", base=ur5_base)


def test_velocity_deadband_counts_rows(ur5, ur5_base):
    payload = make_payload()
    u, ld = make_runs(ur5, "tool0", payload, n=400)
    res = identify_payload(ur5, u, ld, "tool0", base=ur5_base, velocity_deadband=0.05)
    eps = 0.05
    want = (np.abs(u[1]) < eps).sum(axis=0) + (np.abs(ld[1]) < eps).sum(axis=0)
    assert np.array_equal(res.rows_left_out, want)
    assert np.allclose(res.payload.values, truth(payload), atol=1e-6)


def test_payload_frame_named_as_its_joint():
    """The msd's link and joint are both named ``cart``: Pinocchio's untyped
    ``getFrameId`` refuses the name, the payload frame is the link's (BODY) frame."""
    msd = get_robot("msd")
    pf = payload_frame(msd, "cart")
    assert msd.model.frames[pf.frame_id].type == pin.BODY
    assert (pf.joint_name, pf.body) == ("cart", 0)
