"""The real Panda, identified and exported: does the exported robot simulate, and replay?

Run from the repository root (needs the optional ``mujoco`` package)::

    PYTHONPATH=$PWD .venv/bin/python experiments/export_panda.py [LOG]

Runs ``manip-id identify panda --data LOG --friction viscous,coulomb,offset --split 0.7
--consistent --export-urdf OUT/panda_id.urdf --export-mjcf OUT/panda_id.xml`` (LOG
defaults to /work/shared/data/panda_gaz2019, OUT is a temporary folder), then prints:

- the full exported model (fingers free, 9 DoF) in plain Pinocchio: the smallest
  eigenvalue of ``crba`` and whether ``aba`` is finite, at the neutral configuration and
  at 1000 random states within the limits;
- a 2 s MuJoCo rollout of the MJCF export from rest at the log's first configuration
  (fingers at the locked configuration), the identified gravity ``g(q)`` of the
  exported URDF (Pinocchio) applied as the compensation: the largest joint excursion
  of the 7 arm joints [mrad], with MuJoCo's friction loss on and off (off: the
  compensation alone holds it);
- replay along the log's validation part (preprocessed as ``identify`` does): per
  joint, the relative difference ``||tau_x - Y theta|| / ||Y theta||`` of the URDF
  through Pinocchio (``rnea`` + URDF damping and friction + the sidecar's offset) and
  of the MJCF through MuJoCo (``mj_inverse`` with contacts, limits and friction loss
  off, + ``fc sign(dq)`` + offset), and both against the measured torques.
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import mujoco  # optional dependency of manip_id: this experiment needs it
import numpy as np
import pinocchio as pin

from manip_id import load_robot, regressor
from manip_id.cli import main as manip_id
from manip_id.datasets import load_dataset
from manip_id.export import sidecar_path
from manip_id.signals import preprocess

DATA = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("/work/shared/data/panda_gaz2019")
JOINT = mujoco.mjtObj.mjOBJ_JOINT
OFF = mujoco.mjtDisableBit


def _rel(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per column ``||a - b|| / ||b||``."""
    return np.linalg.norm(a - b, axis=0) / np.linalg.norm(b, axis=0)


def full_model_checks(urdf: Path, n: int = 1000) -> None:
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    rng = np.random.default_rng(0)
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    z = np.zeros(model.nv)
    worst, finite = np.inf, True
    for q in [pin.neutral(model), *rng.uniform(lo, hi, size=(n, model.nq))]:
        M = pin.crba(model, data, q)
        worst = min(worst, float(np.linalg.eigvalsh(np.triu(M) + np.triu(M, 1).T)[0]))
        finite &= bool(np.isfinite(pin.aba(model, data, q, z, z)).all())
    print(f"full exported model: nq={model.nq}; over neutral + {n} random states")
    print(f"  smallest crba eigenvalue {worst:.4g} [kg m^2 or kg], aba finite: {finite}")


def rollout(xml: Path, urdf: Path, q0: np.ndarray, friction: bool, seconds: float = 2.0) -> float:
    model = mujoco.MjModel.from_xml_path(str(xml))
    if not friction:
        model.opt.disableflags |= int(OFF.mjDSBL_FRICTIONLOSS)
    data = mujoco.MjData(model)
    pmodel = pin.buildModelFromUrdf(str(urdf))
    pdata = pmodel.createData()
    ids = [mujoco.mj_name2id(model, JOINT, pmodel.names[i]) for i in range(1, pmodel.njoints)]
    qadr, vadr = model.jnt_qposadr[ids], model.jnt_dofadr[ids]
    data.qpos[qadr] = q0
    steps = int(round(seconds / model.opt.timestep))
    worst = 0.0
    for _ in range(steps):
        data.qfrc_applied[vadr] = pin.computeGeneralizedGravity(pmodel, pdata, data.qpos[qadr])
        mujoco.mj_step(model, data)
        worst = max(worst, float(np.abs(data.qpos[qadr][:7] - q0[:7]).max()))
    return worst


def replay(robot, theta, urdf: Path, xml: Path, side: dict, q, dq, ddq, tau) -> None:
    n, nv = q.shape[0], robot.nv
    tau_id = (regressor(robot, q, dq, ddq) @ theta).reshape(n, nv)
    offset = np.array([side["joints"][d].get("fo", 0.0) for d in robot.dof_names])
    fc = np.array([side["joints"][d].get("fc", 0.0) for d in robot.dof_names])
    qref = robot.locked_configuration
    # URDF through Pinocchio (the unreduced model, fingers held at the locked configuration)
    pm = pin.buildModelFromUrdf(str(urdf))
    pd = pm.createData()
    idx = [pm.joints[pm.getJointId(j)].idx_v for j in robot.dof_names]
    tau_urdf = np.empty((n, nv))
    qf, vf, af = qref.copy(), np.zeros(pm.nv), np.zeros(pm.nv)
    for k in range(n):
        qf[idx], vf[idx], af[idx] = q[k], dq[k], ddq[k]
        t = pin.rnea(pm, pd, qf, vf, af)[idx]
        tau_urdf[k] = t + pm.damping[idx] * dq[k] + pm.friction[idx] * np.sign(dq[k]) + offset
    # MJCF through MuJoCo
    mm = mujoco.MjModel.from_xml_path(str(xml))
    for flag in (OFF.mjDSBL_CONTACT, OFF.mjDSBL_LIMIT, OFF.mjDSBL_FRICTIONLOSS):
        mm.opt.disableflags |= int(flag)
    md = mujoco.MjData(mm)
    ids = [mujoco.mj_name2id(mm, JOINT, pm.names[i]) for i in range(1, pm.njoints)]
    qadr = mm.jnt_qposadr[ids]
    act = [mm.jnt_dofadr[mujoco.mj_name2id(mm, JOINT, j)] for j in robot.dof_names]
    tau_mj = np.empty((n, nv))
    md.qpos[qadr] = qref
    for k in range(n):
        md.qpos[mm.jnt_qposadr[[ids[i] for i in idx]]] = q[k]
        md.qvel[:], md.qacc[:] = 0.0, 0.0
        md.qvel[act], md.qacc[act] = dq[k], ddq[k]
        mujoco.mj_inverse(mm, md)
        tau_mj[k] = md.qfrc_inverse[act] + fc * np.sign(dq[k]) + offset
    rows = {
        "URDF (Pinocchio) vs identified": _rel(tau_urdf, tau_id),
        "MJCF (MuJoCo) vs identified": _rel(tau_mj, tau_id),
        "identified vs measured": _rel(tau_id, tau),
        "URDF (Pinocchio) vs measured": _rel(tau_urdf, tau),
        "MJCF (MuJoCo) vs measured": _rel(tau_mj, tau),
    }
    print(f"replay along the validation part ({n} samples), relative error per joint:")
    print(" " * 34 + " ".join(f"{d[-6:]:>9}" for d in robot.dof_names))
    for label, v in rows.items():
        print(f"  {label:<32}" + " ".join(f"{x:9.3g}" for x in v))


def main() -> None:
    out = Path(tempfile.mkdtemp(prefix="manip_id_export_"))
    urdf, xml = out / "panda_id.urdf", out / "panda_id.xml"
    argv = ["identify", "panda", "--data", str(DATA), "--friction", "viscous,coulomb,offset"]
    argv += ["--split", "0.7", "--consistent", "--quiet"]
    status = manip_id([*argv, "--export-urdf", str(urdf), "--export-mjcf", str(xml)])
    if status != 0:
        raise SystemExit(f"manip-id identify failed with status {status}")
    print(f"exported {urdf} and {xml}")
    side = json.loads(sidecar_path(urdf).read_text())
    for joint, c in side["composites"].items():
        if c["carried"]:
            print(f"  {joint}: {c['holder']} holds the composite, carries {c['carried']}")
            print(f"    share of their nominal inertia kept: {c['share']:.4g}")
    full_model_checks(urdf)

    robot = load_robot("panda", friction="viscous,coulomb,offset")
    theta = np.array([p["value"] for p in side["parameters"]])
    data = load_dataset(DATA)
    _, valid = data.split(0.7)
    valid = preprocess(valid)
    q0 = robot.locked_configuration
    full = robot.full_model
    for i, j in enumerate(robot.dof_names):
        q0[full.joints[full.getJointId(j)].idx_q] = valid.q[0, i]
    for friction in (True, False):
        dev = rollout(xml, urdf, q0, friction)
        state = "on" if friction else "off"
        print(f"2 s MuJoCo rollout from rest, friction loss {state}: {dev * 1e3:.4g} mrad")
    replay(robot, theta, urdf, xml, side, valid.q, valid.dq, valid.ddq, valid.tau)


if __name__ == "__main__":
    main()
