"""Logs made in the tests with numpy and Pinocchio alone (independent of manip_id's code)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

FV = np.array([0.8, 1.1, 0.6, 0.3, 0.25, 0.2])  # [N m s/rad]
FC = np.array([1.5, 2.0, 1.2, 0.5, 0.4, 0.3])  # [N m]


def fourier(t, nv, seed, amp=0.6, harmonics=4, base=0.2):
    """q, dq, ddq of a random finite Fourier series (analytic derivatives)."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(-1, 1, (harmonics, nv)) * amp / harmonics
    b = rng.uniform(-1, 1, (harmonics, nv)) * amp / harmonics
    w = 2 * np.pi * base * np.arange(1, harmonics + 1)
    s, c = np.sin(np.outer(t, w)), np.cos(np.outer(t, w))
    q = s @ a + c @ b
    dq = (c * w) @ a - (s * w) @ b
    ddq = -(s * w**2) @ a - (c * w**2) @ b
    return q, dq, ddq


def torques(robot, q, dq, ddq, fv=FV, fc=FC):
    """rnea of the nominal model plus viscous and Coulomb friction [N m]."""
    model = robot.model
    data = model.createData()
    tau = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(q.shape[0])])
    return tau + fv[: robot.nv] * dq + fc[: robot.nv] * np.sign(dq)


def truth(robot, fv=FV, fc=FC):
    """The standard parameter vector of those torques (nominal bodies, FV, FC)."""
    theta = np.array(robot.nominal_parameters, dtype=float)
    names = list(robot.parameter_names)
    for j, dof in enumerate(robot.dof_names):
        theta[names.index(f"{dof}.fv")] = fv[j]
        theta[names.index(f"{dof}.fc")] = fc[j]
    return theta


def log(robot, *, n=1500, rate=200.0, seed=0, t0=0.0):
    """(t, q, dq, ddq, tau) of a noise-free excitation."""
    t = t0 + np.arange(n) / rate
    q, dq, ddq = fourier(t - t0, robot.nv, seed)
    return t, q, dq, ddq, torques(robot, q, dq, ddq)


def save_npz(path, robot, t, q, dq, ddq, tau, with_ddq=True):
    arrays = dict(t=t, q=q, dq=dq, tau=tau, joint_names=np.array(robot.dof_names))
    if with_ddq:
        arrays["ddq"] = ddq
    np.savez(path, **arrays)
    return path
