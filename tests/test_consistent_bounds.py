"""Plausible, not only consistent: bounding ellipsoids, mass bounds, the plausibility report.

References independent of the code under test: point masses sampled inside and outside
an ellipsoid written out here (their parameters by Pinocchio's ``Inertia``), the
ellipsoid's quadratic form, eigenvalues, noise-free data made with the regressor.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id import regressor
from manip_id.errors import InputError
from manip_id.estimators import InformationAccumulator, solve_accumulator
from manip_id.estimators.consistent import consistent_estimate
from manip_id.estimators.consistent.bounds import (
    KINEMATIC_RADIUS,
    BoundsOptions,
    body_bounds,
    minimum_volume_ellipsoid,
    parse_total_mass,
)
from manip_id.identifiability import analyze
from manip_id.physics.consistency import check_plausibility, ellipsoid_matrix, ellipsoid_rows
from manip_id.robot.model import JointTerms, Robot


def _random_ellipsoid(rng):
    R = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    axes = rng.uniform(0.05, 0.3, 3)  # semi-axes [m]
    return rng.uniform(-0.2, 0.2, 3), R @ np.diag(axes**2) @ R.T, R, axes


def _inside(x, c, Q) -> float:
    """``(x - c)^T Q^-1 (x - c)``: <= 1 inside (written here from the definition)."""
    d = x - c
    return float(d @ np.linalg.solve(Q, d))


def _point_masses(masses, points) -> np.ndarray:
    """Standard parameters of point masses (Pinocchio's inertia of each, added)."""
    total = pin.Inertia.Zero()
    for m, x in zip(masses, points, strict=True):
        total += pin.Inertia(float(m), np.asarray(x, dtype=float), np.zeros((3, 3)))
    return total.toDynamicParameters()


def test_ellipsoid_lmi_is_the_quadratic_form_and_bites_on_point_masses():
    rng = np.random.default_rng(0)
    for _ in range(20):
        c, Q, R, axes = _random_ellipsoid(rng)
        Qbar = ellipsoid_matrix(c, Q)
        d = ellipsoid_rows(Qbar)
        for _ in range(5):
            x = c + R @ (axes * rng.uniform(-1.5, 1.5, 3))
            assert np.r_[x, 1.0] @ Qbar @ np.r_[x, 1.0] == pytest.approx(
                1.0 - _inside(x, c, Q), abs=1e-9
            )
            pi = _point_masses([2.0], [x])
            assert d @ pi == pytest.approx(2.0 * (1.0 - _inside(x, c, Q)), abs=1e-9)
        # a body made of point masses inside passes; one point just outside fails alone
        u = rng.standard_normal((50, 3))
        u *= (rng.uniform(0, 1, 50) ** (1 / 3) / np.linalg.norm(u, axis=1))[:, None]
        inside = c + (u * axes) @ R.T
        assert max(_inside(x, c, Q) for x in inside) <= 1.0
        assert d @ _point_masses(rng.uniform(0.1, 1.0, 50), inside) >= 0
        out = c + R @ (axes * np.array([1.05, 0.0, 0.0]))
        assert d @ _point_masses([1.0], [out]) < 0
        # Q_bar has one positive and three negative eigenvalues (a proper ellipsoid)
        lam = np.linalg.eigvalsh(Qbar)
        assert (lam < 0).sum() == 3 and (lam > 0).sum() == 1


def test_minimum_volume_ellipsoid_holds_every_point_and_finds_a_known_one():
    rng = np.random.default_rng(1)
    c, Q, R, axes = _random_ellipsoid(rng)
    u = rng.standard_normal((400, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    surface = c + (u * axes) @ R.T  # points on the ellipsoid's surface
    c_hat, Q_hat = minimum_volume_ellipsoid(surface)
    assert max(_inside(x, c_hat, Q_hat) for x in surface) <= 1.0 + 1e-9
    np.testing.assert_allclose(c_hat, c, atol=2e-3)
    np.testing.assert_allclose(
        np.sort(np.sqrt(np.linalg.eigvalsh(Q_hat))), np.sort(axes), rtol=0.02
    )
    flat = np.c_[rng.uniform(-1, 1, (30, 2)), np.zeros(30)]  # coplanar: padded, still finite
    c_f, Q_f = minimum_volume_ellipsoid(flat)
    assert np.linalg.eigvalsh(Q_f)[0] > 0
    assert max(_inside(x, c_f, Q_f) for x in flat) <= 1.0 + 1e-9


def test_geometry_ellipsoids_hold_every_collision_vertex_of_a_composite():
    """panda_joint7 carries link 7, the hand and both (locked) fingers: its ellipsoid
    holds the vertices and box corners of all of them, and the nominal body."""
    robot = get_robot("panda")
    bounds = body_bounds(robot, BoundsOptions())
    assert bounds is not None and bounds.ellipsoids is not None
    assert all(s.startswith("collision geometry") for s in bounds.sources)
    Qbar = bounds.ellipsoids[6]
    on7 = [o for o in robot.collision_model.geometryObjects if o.parentJoint == 7]
    assert {o.name.split("_")[1] for o in on7} >= {"link7", "hand", "leftfinger"}
    for obj in on7:
        g = obj.geometry
        if hasattr(g, "vertices"):
            pts = np.asarray(g.vertices())
        else:
            h = np.asarray(g.halfSide)
            pts = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)]) * h
        world = pts @ np.asarray(obj.placement.rotation).T + obj.placement.translation
        for x in world:
            assert np.r_[x, 1.0] @ Qbar @ np.r_[x, 1.0] >= -1e-9
    nominal = robot.nominal_parameters[: robot.n_rigid].reshape(-1, 10)
    assert np.all(np.einsum("ik,ik->i", bounds.rows, nominal) >= -1e-12)


def test_kinematic_fallback_without_geometry():
    """A model built in code (no URDF): each body's ellipsoid spans its joint and its
    child's origin, padded by the documented radius, and holds the nominal body."""
    model = pin.Model()
    j1 = model.addJoint(0, pin.JointModelRY(), pin.SE3.Identity(), "shoulder")
    model.appendBodyToJoint(
        j1, pin.Inertia(2.0, np.array([0.2, 0.0, 0.0]), np.diag([1e-3] * 3)), pin.SE3.Identity()
    )
    j2 = model.addJoint(j1, pin.JointModelRY(), pin.SE3(np.eye(3), np.array([0.4, 0, 0])), "elbow")
    model.appendBodyToJoint(
        j2, pin.Inertia(1.0, np.array([0.1, 0.0, 0.0]), np.diag([1e-3] * 3)), pin.SE3.Identity()
    )
    robot = Robot("arm", model, JointTerms())
    bounds = body_bounds(robot, BoundsOptions())
    assert bounds.sources[0] == "kinematic segment"
    Qbar = bounds.ellipsoids[0]
    r = KINEMATIC_RADIUS[0] * 0.4
    for x in ([0.0, 0, 0], [0.4, 0, 0], [0.2, r, 0], [0.4 + r, 0, 0]):
        assert np.r_[x, 1.0] @ Qbar @ np.r_[x, 1.0] >= -1e-9
    assert np.r_[1.0, 0, 0, 1.0] @ Qbar @ np.r_[1.0, 0, 0, 1.0] < 0  # 1 m out: outside
    nominal = robot.nominal_parameters[: robot.n_rigid].reshape(-1, 10)
    assert np.all(np.einsum("ik,ik->i", bounds.rows, nominal) >= -1e-12)


def _problem_data(robot, theta, n=1500, seed=3, noise=0.0):
    base = analyze(robot).base
    q, dq, ddq = robot.random_states(n, seed=seed)
    tau = regressor(robot, q, dq, ddq) @ theta
    tau = tau + noise * tau.std(axis=0) * np.random.default_rng(seed).standard_normal(tau.shape)
    acc = InformationAccumulator(base.n_base, robot.nv).add(
        regressor(robot, q, dq, ddq), tau, columns=base.independent
    )
    return base, acc, solve_accumulator(acc)


@pytest.mark.parametrize("solver", ["sdp", "logchol"])
def test_noise_free_recovery_unchanged_with_every_bound(solver):
    robot = get_robot("ur5", friction="viscous,coulomb")
    theta = robot.nominal_parameters.copy()
    theta[robot.n_rigid :] = 0.2
    base, acc, ls = _problem_data(robot, theta)
    total = float(theta[: robot.n_rigid : 10].sum())
    opts = BoundsOptions("geometry", mass_range=(0.5, 2.0), total_mass=(total, 0.01 * total))
    est = consistent_estimate(robot, acc, base, ls, solver=solver, bounds=opts)
    np.testing.assert_allclose(base.to_base(est.values), ls.estimate, rtol=1e-5, atol=1e-7)
    assert est.physically_consistent and est.plausibility.plausible and est.warnings == []
    assert est.bounds.violations(est.values) == []
    doc = est.to_dict()["plausibility"]
    assert doc["plausible"] and len(doc["bodies"]) == robot.n_bodies
    assert doc["bodies"][1]["mass_ratio"] == pytest.approx(1.0, rel=1e-3)


def test_mass_range_holds_and_logchol_falls_back_to_the_sdp():
    """Truth: the shoulder_lift link 4x heavier (its whole pseudo-inertia scaled, so still
    inside its link); a mass range of 0.5-2x must hold it at 2x, in both solvers."""
    robot = get_robot("ur5")
    theta = robot.nominal_parameters.copy()
    theta[10:20] *= 4.0
    base, acc, ls = _problem_data(robot, theta, noise=0.02)
    m0 = robot.nominal_parameters[10]
    free = consistent_estimate(robot, acc, base, ls, solver="sdp")
    assert free.values[10] > 3.0 * m0  # unbounded: the data pull it up (its mass is
    ratio = free.values[10] / m0  # regrouped with its neighbours', the prior picks the rest)
    assert free.bounds.violations(free.values) == []  # the 4x link is inside its ellipsoid
    named = f"shoulder_lift_joint: {free.values[10]:.3g} kg, {ratio:.2g}x nominal"
    assert any(named in w for w in free.warnings), free.warnings
    opts = BoundsOptions(mass_range=(0.5, 2.0))
    for solver in ("sdp", "logchol"):
        est = consistent_estimate(robot, acc, base, ls, solver=solver, bounds=opts)
        assert est.values[10] <= 2.0 * m0 * (1 + 1e-6)
        assert est.bounds.violations(est.values) == []
    assert "solved by the SDP" in est.status


def test_plausibility_report_names_the_body():
    robot = get_robot("ur5")
    theta = robot.nominal_parameters.copy()
    theta[10:20] *= 3.4
    rep = check_plausibility(robot, theta)
    assert [b.name for b in rep.implausible] == ["shoulder_lift_joint"]
    m = theta[10]
    assert rep.messages()[0].startswith(f"shoulder_lift_joint: {m:.3g} kg, 3.4x nominal")
    far = robot.nominal_parameters.copy()
    far[11:14] += far[10] * np.array([0.0, 0.0, 2.0])  # centre of mass 2 m away
    bounds = body_bounds(robot, BoundsOptions())
    rep2 = check_plausibility(robot, far, bounds.ellipsoids)
    assert rep2.bodies[1].com_inside is False and "outside" in rep2.messages()[0]


def test_bound_options_are_checked():
    with pytest.raises(InputError, match="bounds must be one of"):
        BoundsOptions("box")
    with pytest.raises(InputError, match="lo <= 1"):
        BoundsOptions(mass_range=(2.0, 3.0))
    with pytest.raises(InputError, match="kg > 0"):
        BoundsOptions(total_mass=(-1.0, 0.1))
    assert parse_total_mass("28.7+-1.5") == (28.7, 1.5)
    assert parse_total_mass("20") == (20.0, pytest.approx(1.0))
    with pytest.raises(InputError, match="KG"):
        parse_total_mass("heavy")
    assert body_bounds(get_robot("ur5"), BoundsOptions("none")) is None


def test_cli_bounds_options_reach_the_estimate(tmp_path):
    """``--mass-range`` holds every link mass within it; the JSON carries the plausibility
    section and the warning names each implausible body, printed as saved."""
    import json
    import subprocess
    import sys

    out = tmp_path / "r.json"
    base = ["identify", "ur5", "--simulate", "--duration", "4", "--noise", "0.05"]
    cmd = [sys.executable, "-m", "manip_id", *base, "--consistent", "--json", str(out)]
    run = subprocess.run(
        [*cmd, "--mass-range", "0.5,2", "--total-mass", "18+-20"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    doc = json.loads(out.read_text())
    bodies = doc["plausibility"]["bodies"]
    assert all(0.5 * (1 - 1e-6) <= b["mass_ratio"] <= 2.0 * (1 + 1e-6) for b in bodies)
    assert doc["plausibility"]["bounds"]["bodies"][1]["mass_range"] is not None
    for w in doc["warnings"]:
        if w.startswith("implausible"):
            assert w in run.stdout + run.stderr
    bad = subprocess.run([*cmd, "--mass-range", "2"], capture_output=True, text=True)
    assert bad.returncode == 2 and "--mass-range must read LO,HI" in bad.stderr
    plain = [sys.executable, "-m", "manip_id", *base, "--bounds", "none"]
    bad = subprocess.run(plain, capture_output=True, text=True)
    assert bad.returncode == 2 and "--bounds applies to --consistent only" in bad.stderr


def test_missing_joint_terms_are_compared_on_the_same_sums():
    """Truth with Coulomb friction, model without: adding fc lowers the error to the noise
    floor, armature (absent from the truth) does not; the suggestion names --friction
    coulomb, and only when the consistent fit is implausible."""
    from types import SimpleNamespace

    from manip_id.estimators.consistent.terms import (
        accumulate_candidates,
        compare_terms,
        missing_term_warnings,
        missing_terms,
    )

    truth_robot = get_robot("ur5", friction="coulomb")
    robot = get_robot("ur5")
    theta = truth_robot.nominal_parameters.copy()
    theta[truth_robot.n_rigid :] = 2.0  # [N m]
    q, dq, ddq = robot.random_states(800, seed=5)
    tau = regressor(truth_robot, q, dq, ddq) @ theta
    tau = tau + 0.005 * tau.std(axis=0) * np.random.default_rng(5).standard_normal(tau.shape)
    base = analyze(robot).base
    terms = [c[0] for c in missing_terms(robot)]
    assert terms == ["Ia", "fv", "fc", "fo"]
    acc = accumulate_candidates(robot, [(q, dq, ddq, tau)], base.independent, terms, 256)
    # the candidate accumulator's own-columns block is the plain base accumulator's
    plain = InformationAccumulator(base.n_base, robot.nv).add(
        regressor(robot, q, dq, ddq), tau, columns=base.independent
    )
    np.testing.assert_allclose(acc.A[: base.n_base, : base.n_base], plain.A, rtol=1e-12)
    by = {c.term: c for c in compare_terms(robot, acc, base.n_base)}
    assert by["fc"].lowers and by["fc"].train_with < 0.2 * by["fc"].train_without
    assert by["fc"].train_with == pytest.approx(0.005, rel=0.3)  # the noise floor
    assert not by["Ia"].lowers
    bad = robot.nominal_parameters.copy()
    bad[10:20] *= 5.0
    implausible = SimpleNamespace(plausibility=check_plausibility(robot, bad))
    (text,) = missing_term_warnings(
        robot, implausible, [(q, dq, ddq, tau)], None, base.independent, 256
    )
    assert "--friction coulomb (Coulomb friction) lowers the training error" in text
    assert "--armature" not in text
    fine = SimpleNamespace(plausibility=check_plausibility(robot, robot.nominal_parameters))
    assert (
        missing_term_warnings(robot, fine, [(q, dq, ddq, tau)], None, base.independent, 256) == []
    )
