"""An identified payload written back into the robot's URDF as a fixed link.

Reference: the exported URDF read by our loader (Pinocchio's URDF parser) must give the
torques of the robot plus the payload, the payload's torques computed by the payload
regressor of :mod:`manip_id.payload` (an independent formula, tested against
``pinocchio.rnea`` in tests/test_payload.py), to 1e-9.
"""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot
from test_cli_payload import _save
from test_payload import SYM6, loaded_model, make_payload, make_runs

from manip_id import load_robot
from manip_id.cli import main
from manip_id.errors import InputError
from manip_id.export import PayloadLink, export_payload_urdf, sidecar_path
from manip_id.payload import payload_regressor, standard_from_quantities
from manip_id.physics.consistency import PhysicalConsistencyError
from manip_id.robot.model import JointSelection

MASS, COM = 1.3, np.array([0.02, -0.03, 0.08])  # [kg], [m]
INERTIA = np.array([0.010, 0.001, 0.012, -0.0005, 0.0008, 0.006])  # about the CoM [kg m^2]


def _no_armature(model: pin.Model) -> pin.Model:
    m = model.copy()
    m.armature[:] = 0.0
    return m


@pytest.mark.parametrize(
    "spec, frame",
    [
        ("ur5", "tool0"),  # a link on a fixed joint
        ("ur5", "wrist_3_joint"),  # a joint frame: its child link
        ("panda", "panda_hand_tcp"),  # a link carried by joint 7 (fingers locked)
        ("panda", "panda_link7"),  # the joint's own link
    ],
)
def test_exported_payload_link_gives_robot_plus_payload_torques(tmp_path, spec, frame):
    robot = get_robot(spec)
    out = tmp_path / "with_payload.urdf"
    result = export_payload_urdf(robot, PayloadLink(frame, MASS, COM, INERTIA), out)
    assert result.path == out and result.unresolved == []
    loaded = load_robot(
        out,
        active_joints=JointSelection(robot.joint_names, robot.locked_configuration),
    )
    m0, m1 = _no_armature(robot.model), _no_armature(loaded.model)
    d0, d1 = m0.createData(), m1.createData()
    phi = standard_from_quantities(MASS, COM, INERTIA)
    q, dq, ddq = robot.random_states(15, seed=4)
    Yp = payload_regressor(robot, frame, q, dq, ddq)
    for k in range(q.shape[0]):
        want = pin.rnea(m0, d0, q[k], dq[k], ddq[k]) + Yp[k] @ phi
        got = pin.rnea(m1, d1, q[k], dq[k], ddq[k])
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * np.abs(want).max())
    side = json.loads(sidecar_path(out).read_text())
    assert side["payload"]["frame"] == frame and side["payload"]["mass"] == MASS
    assert side["active_joints"] == robot.joint_names
    back = load_robot(out, identified=True)  # the sidecar reads back
    assert back.joint_names == robot.joint_names


def test_payload_export_refuses_a_non_physical_payload_and_bad_input(tmp_path):
    robot = get_robot("ur5")
    out = tmp_path / "p.urdf"
    flat = INERTIA.copy()
    flat[5] = -0.001  # Izz < 0
    with pytest.raises(PhysicalConsistencyError, match="tool0"):
        export_payload_urdf(robot, PayloadLink("tool0", MASS, COM, flat), out)
    with pytest.raises(PhysicalConsistencyError, match="m > 0"):
        export_payload_urdf(robot, PayloadLink("tool0", 0.0, COM, INERTIA), out)
    with pytest.raises(InputError, match="no frame 'nowhere'"):
        export_payload_urdf(robot, PayloadLink("nowhere", MASS, COM, INERTIA), out)
    with pytest.raises(InputError, match="already"):
        export_payload_urdf(robot, PayloadLink("tool0", MASS, COM, INERTIA, name="tool0"), out)
    assert not out.exists() and not sidecar_path(out).exists()
    export_payload_urdf(robot, PayloadLink("tool0", MASS, COM, INERTIA), out)
    with pytest.raises(InputError, match="exists"):
        export_payload_urdf(robot, PayloadLink("tool0", MASS, COM, INERTIA), out)
    export_payload_urdf(robot, PayloadLink("tool0", MASS, COM, INERTIA), out, force=True)


def test_cli_payload_export_urdf(tmp_path, capsys):
    """`manip-id payload --consistent --export-urdf`: the exported robot is the loaded one."""
    ur5 = get_robot("ur5")
    payload = make_payload()
    u, ld = make_runs(ur5, "tool0", payload, n=500)
    fu, fl = _save(tmp_path / "u.npz", u, ur5), _save(tmp_path / "l.npz", ld, ur5)
    out = tmp_path / "ur5_payload.urdf"
    base = ["payload", "ur5", "--unloaded", fu, "--loaded", fl, "--frame", "tool0"]
    assert main([*base, "--export-urdf", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "add --consistent" in err[0]
    assert main([*base, "--consistent", "--export-urdf", str(out)]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    exported = load_robot(out)
    _, truth_model = loaded_model(ur5, "tool0", payload)
    m1 = _no_armature(exported.model)
    d0, d1 = truth_model.createData(), m1.createData()
    q, dq, ddq = ur5.random_states(10, seed=9)
    for k in range(q.shape[0]):
        want = pin.rnea(truth_model, d0, q[k], dq[k], ddq[k])
        got = pin.rnea(m1, d1, q[k], dq[k], ddq[k])
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-6 * np.abs(want).max())
    side = json.loads(sidecar_path(out).read_text())
    assert side["provenance"]["command"] == "manip-id payload"
    assert side["provenance"]["options"]["loaded"] == [fl]
    Ic = payload.inertia
    assert side["payload"]["inertia"] == pytest.approx([Ic[a, b] for a, b in SYM6], abs=1e-6)
    assert main([*base, "--consistent", "--export-urdf", str(out)]) == 2
    assert "exists" in capsys.readouterr().err
