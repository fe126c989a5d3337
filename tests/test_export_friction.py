"""Every friction law out to the sidecar and back: the reloaded robot and the simulator.

Each law is identified on simulated data (consistent standard parameters), exported as a
URDF with its sidecar, loaded back with ``identified=True``; the reloaded robot's inverse
dynamics (``rnea`` of the exported URDF plus its joint terms, no regressor) must equal the
identifying robot's regressor times the exported parameters, and its joint terms must
equal the law's formula written out here from the sidecar's coefficients and shapes.
"""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest
from test_friction import _data, _fit

from manip_id import load_robot
from manip_id.export import export_urdf, sidecar_path
from manip_id.identification import identify
from manip_id.identification.selection import SelectionOptions, candidate_terms, select_model
from manip_id.robot.regressor import regressor
from manip_id.simulation import inverse_dynamics
from manip_id.trajectories import random_trajectory

LAWS = ["linear", "asymmetric", "stribeck", "sigmoid", "position", "load", "auto"]


@pytest.fixture(scope="module")
def robot():
    return load_robot("double_pendulum", friction=())


def _identified(robot, law):
    """The robot with the law's terms and its consistent standard parameters."""
    train, _ = _data(robot, law, seed=1, duration=20.0)
    if law == "auto":  # --friction auto: each joint its own model (per_dof)
        train, _ = _data(robot, "stribeck", seed=1, duration=20.0)
        valid, _ = _data(robot, "stribeck", seed=2, duration=10.0)
        _, sel = select_model(_fit(robot, train, valid), robot, SelectionOptions())
        terms = sel.terms
    elif law in ("stribeck", "sigmoid"):
        valid, _ = _data(robot, law, seed=2, duration=10.0)
        opts = SelectionOptions(candidates=(law,), combine=False)
        _, sel = select_model(_fit(robot, train, valid), robot, opts)
        terms = sel.terms
    else:
        terms = candidate_terms(robot.terms, law, SelectionOptions())
    r = robot.with_terms(terms)
    res = identify(r, tuple(train), consistent=True)
    return r, res


def _formula(side: dict, dof: str, j: int, q, dq, load):
    """The joint torque of the sidecar's terms of DoF ``dof`` (index ``j``), written out."""
    c = side["joints"][dof]
    model = side["joint_model"]
    keep = set(c) if model["per_dof"] is None else set(model["per_dof"][j])
    g = {t: (c[t] if t in keep else 0.0) for t in c}
    get = g.get
    shapes = model["shapes"] or {}
    tau = get("fv", 0.0) * dq + get("fc", 0.0) * np.sign(dq) + get("fo", 0.0)
    tau = tau + np.where(dq > 0, get("fvp", 0.0) * dq, get("fvn", 0.0) * dq)
    tau = tau + np.where(dq > 0, get("fcp", 0.0), np.where(dq < 0, -get("fcn", 0.0), 0.0))
    if "fs" in g:
        vs = shapes["stribeck_velocity"][j]
        tau = tau + g["fs"] * np.exp(-((dq / vs) ** 2)) * np.sign(dq)
    if "fsg" in g:
        a = shapes["sigmoid_slope"][j]
        s = shapes["sigmoid_shift"][j] if shapes.get("sigmoid_shift") else 0.0
        tau = tau + g["fsg"] * (1 / (1 + np.exp(-a * (dq + s))) - 1 / (1 + np.exp(-a * s)))
    for k in range(1, model["harmonics"] + 1):
        tau = tau + get(f"h{k}s", 0.0) * np.sin(k * q) + get(f"h{k}c", 0.0) * np.cos(k * q)
    if "fl" in g:
        tau = tau + g["fl"] * np.abs(load) * np.sign(dq)
    return tau


@pytest.mark.parametrize("law", LAWS)
def test_every_law_is_exported_and_evaluated_when_loaded_back(robot, tmp_path, law):
    r, res = _identified(robot, law)
    theta = res.standard.values
    out = tmp_path / f"{law}.urdf"
    export_urdf(r, theta, out)
    side = json.loads(sidecar_path(out).read_text())
    back = load_robot(out, identified=True)
    assert back.terms.enabled == r.terms.enabled
    assert back.terms == r.terms  # the laws, the shapes, the per-joint models
    assert r.terms.per_dof is not None or law != "auto"  # auto: each joint its own model
    np.testing.assert_allclose(back.nominal_parameters, theta, rtol=1e-12, atol=1e-14)

    # fresh states, not those of the fit
    traj = random_trajectory(robot, harmonics=4, wf=0.4, seed=7)
    q, dq, ddq = traj.sample(np.arange(400) / 100.0)
    # the identification's model with the exported parameters: its regressor times theta
    expected = np.einsum("njp,p->nj", regressor(r, q, dq, ddq), theta)
    got = inverse_dynamics(back, back.nominal_parameters, q, dq, ddq)  # rnea + joint terms
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9 * np.abs(expected).max())
    # and the identification's own prediction (the consistent fit of noisy data: close)
    pred = res.predict(r, q, dq, ddq)
    assert np.linalg.norm(got - pred) <= 0.02 * np.linalg.norm(pred)

    # the simulator's joint-term torque is the law's formula from the sidecar's numbers
    exported = back.with_parameters(back.nominal_parameters)
    d = exported.createData()
    rigid = np.array([pin.rnea(exported, d, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
    m0, d0 = robot.model, robot.model.createData()  # the load law's load: the nominal model
    load = np.array([pin.rnea(m0, d0, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
    friction = np.stack(
        [
            _formula(side, dof, j, q[:, j], dq[:, j], load[:, j])
            for j, dof in enumerate(back.dof_names)
        ],
        axis=1,
    )
    assert np.abs(friction).max() > 0.1  # the law is there [N m]
    np.testing.assert_allclose(got - rigid, friction, rtol=0, atol=1e-9)


def test_explicit_laws_win_over_the_sidecars(robot, tmp_path):
    r, res = _identified(robot, "stribeck")
    out = tmp_path / "stribeck.urdf"
    export_urdf(r, res.standard.values, out)
    plain = load_robot(out, identified=True, friction="viscous", armature=True)
    assert plain.terms.enabled == ("Ia", "fv")
    assert plain.terms.shapes is None and plain.terms.per_dof is None
    side = json.loads(sidecar_path(out).read_text())
    fv = [side["joints"][d]["fv"] for d in plain.dof_names]
    np.testing.assert_allclose(plain.nominal_parameters[plain.layout.joint_columns("fv")], fv)
    # an explicit armature flag joins the sidecar's laws, in every joint's model
    with_ia = load_robot(out, identified=True, armature=True)
    assert with_ia.terms.armature and with_ia.terms.stribeck
    assert all("Ia" in keep for keep in with_ia.terms.per_dof or [with_ia.terms.enabled])
