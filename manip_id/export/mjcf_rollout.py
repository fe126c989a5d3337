"""The exported MJCF rolled out in MuJoCo, beside the Pinocchio rollout of the same model.

MuJoCo integrates the file of :func:`~manip_id.export.export_mjcf` from the measured state
of a log with the measured torque as ``qfrc_applied`` (minus the offset ``fo``, which MJCF
has no field for), contacts off, at the log step with MuJoCo's Euler integrator (velocity
first, then position: the semi-implicit Euler of :mod:`manip_id.identification.rollout`;
its implicit damping is turned off so that ``fv dq`` is explicit in both). Joints of the
file that the robot locks are held by a large armature (they do not move). The Coulomb
term differs by design: MuJoCo's friction loss is a soft constraint, the Pinocchio
rollout's is ``tanh(dq / eps)``; the gap between the two rollouts at the horizon says how
alike the model simulates in both.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..identification.forward import ForwardModel
from ..identification.rollout import Log, simulate, start_points

#: Armature [kg m^2 or kg] that holds a joint the robot locks.
LOCKED_ARMATURE = 1e8


@dataclass(frozen=True)
class SimulatorGap:
    """Per joint (nv,): RMS over start points of ``q_mujoco - q_pinocchio`` at the horizon
    [rad or m], and the RMS of each simulator's error against the log."""

    horizon: float
    gap_rms: np.ndarray
    mujoco_rms: np.ndarray
    pinocchio_rms: np.ndarray
    n_starts: int

    def to_dict(self) -> dict:
        return {
            "horizon": self.horizon,
            "gap_rms": self.gap_rms.tolist(),
            "mujoco_position_rms": self.mujoco_rms.tolist(),
            "pinocchio_position_rms": self.pinocchio_rms.tolist(),
            "n_starts": self.n_starts,
        }


def _mujoco_model(path, robot, dt: float):
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(path))
    m.opt.timestep = dt
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_EULERDAMP)
    names = list(robot.dof_names)
    qadr, vadr = [], []
    for name in names:
        jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid < 0:
            raise InputError(f"the MJCF file {path} has no joint {name!r}")
        qadr.append(int(m.jnt_qposadr[jid]))
        vadr.append(int(m.jnt_dofadr[jid]))
    locked = np.setdiff1d(np.arange(m.nv), vadr)
    m.dof_armature[locked] = LOCKED_ARMATURE
    return m, np.asarray(qadr), np.asarray(vadr)


def mujoco_rollout_gap(
    path, robot, theta, log: Log, *, horizon: float, eps, starts: int = 50
) -> SimulatorGap:
    """Roll the MJCF file ``path`` (exported from ``robot`` with standard parameters
    ``theta``, shape (p,)) and the Pinocchio model of ``theta`` out from the same start
    points of ``log`` over ``horizon`` [s]; ``eps`` the Coulomb width of the Pinocchio one."""
    import mujoco

    m, qadr, vadr = _mujoco_model(path, robot, log.dt)
    d = mujoco.MjData(m)
    fm = ForwardModel(robot, theta, eps)
    fo = np.zeros(robot.nv)
    if "fo" in robot.terms.enabled:
        fo = np.asarray(theta, float)[robot.layout.joint_columns("fo")]
    steps = max(1, int(round(horizon / log.dt)))
    pts = start_points(len(log.t), steps, starts)
    gaps, e_mj, e_pin = [], [], []
    for s in pts:
        mujoco.mj_resetData(m, d)
        d.qpos[qadr], d.qvel[vadr] = log.q[s], log.dq[s]
        for k in range(steps):
            d.qfrc_applied[vadr] = log.tau[s + k] - fo
            mujoco.mj_step(m, d)
        q_mj = np.array(d.qpos[qadr])
        q_pin, _ = simulate(fm, log, s, steps)
        gaps.append(q_mj - q_pin[-1])
        e_mj.append(q_mj - log.q[s + steps])
        e_pin.append(q_pin[-1] - log.q[s + steps])

    def rms(x):
        return np.sqrt(np.mean(np.square(x), axis=0))

    return SimulatorGap(float(steps * log.dt), rms(gaps), rms(e_mj), rms(e_pin), len(pts))


__all__ = ["LOCKED_ARMATURE", "SimulatorGap", "mujoco_rollout_gap"]
