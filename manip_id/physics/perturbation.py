"""The truth of a simulation: parameters perturbed within physics, and the physical check.

A perturbed body keeps a positive mass and an inertia at its centre of mass that is
positive definite and satisfies the triangle inequalities (:func:`perturb_parameters`);
joint terms that must be non-negative (armature, viscous and Coulomb friction, spring)
keep their sign. :func:`require_physical` refuses parameters no body can have, naming
the body, before anything is simulated with them.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from .._checks import as_float_array, as_real, check_finite, random_generator
from ..errors import InputError
from ..resources import check_count
from ..robot.model import Robot
from .consistency import PhysicalConsistencyError, check_consistency

#: Joint terms that must stay non-negative (offset may take either sign).
_POSITIVE_TERMS = ("Ia", "fv", "fc", "k")


#: Relative eigenvalue tolerance: a body's pseudo-inertia may be singular (a point mass,
#: a massless frame) but not indefinite (``lambda_min < -tol * max |lambda|``).
PSD_TOLERANCE = 1e-10


def parameter_vector(robot: Robot, theta) -> np.ndarray:
    """``theta`` checked as the robot's parameter vector: finite, shape (p,)."""
    theta = as_float_array(theta, "theta", ndim=1)
    if theta.shape[0] != robot.n_parameters:
        raise InputError(f"{theta.shape=} but robot.n_parameters={robot.n_parameters}")
    check_finite(theta, "theta", robot.parameter_names)
    return theta


def _perturb_body(block: np.ndarray, rel: float, rng: np.random.Generator) -> np.ndarray:
    """One body's 10 parameters, perturbed and kept physically consistent.

    With ``Ic = R diag(lambda) R^T`` at the centre of mass, the second moments
    of the mass distribution along the principal axes are
    ``s_i = (lambda_j + lambda_k - lambda_i) / 2`` (>= 0 for a real body;
    ``lambda_i = s_j + s_k``, which is the triangle inequality). The mass and
    each ``s_i`` are multiplied by ``exp(rel e)``, the principal axes rotated
    by ``exp3(rel e)`` [rad] and the centre of mass moved by
    ``rel max(|c|, r_g) e / sqrt(3)`` (about ``rel max(|c|, r_g)`` in norm),
    ``r_g = sqrt(trace(Ic) / (2 m))`` the radius of gyration, with ``e``
    standard normal draws.
    """
    inertia = pin.Inertia.FromDynamicParameters(block)
    mass = inertia.mass
    if not mass > 0:  # massless placeholder bodies are left as they are
        return block.copy()
    com = np.array(inertia.lever)
    Ic = np.array(inertia.inertia)
    lam, R = np.linalg.eigh(0.5 * (Ic + Ic.T))
    s = 0.5 * (lam.sum() - 2.0 * lam)
    floor = 1e-9 * max(lam.max(), 1e-12)  # descriptions that violate the triangle inequality
    s = np.maximum(s, floor)
    e = rng.standard_normal(10)
    mass_p = mass * math.exp(rel * e[0])
    # second moments scale with the mass (same shape), then change by exp(rel e) each
    s_p = s * (mass_p / mass) * np.exp(rel * e[1:4])
    R_p = pin.exp3(rel * e[4:7]) @ R
    r_g = math.sqrt(max(lam.sum(), 0.0) / (2.0 * mass))
    com_p = com + rel * max(float(np.linalg.norm(com)), r_g) * e[7:10] / math.sqrt(3.0)
    lam_p = s_p.sum() - s_p
    Ic_p = R_p @ np.diag(lam_p) @ R_p.T
    return pin.Inertia(mass_p, com_p, 0.5 * (Ic_p + Ic_p.T)).toDynamicParameters()


#: The largest relative perturbation [-]: factors exp(rel e) of e ~ N(0, 1) stay finite
#: (and below about 1e10) for rel up to 5.
MAX_REL = 5.0


def perturb_parameters(robot: Robot, rel: float, seed: int = 0, theta=None) -> np.ndarray:
    """Parameters perturbed by a relative amount ``rel`` while staying physically valid.

    Parameters
    ----------
    robot : Robot
        the robot whose layout ``theta`` follows.
    rel : float
        relative standard deviation of the perturbation (e.g. 0.1 for about 10%).
    seed : int
        seed of the draws.
    theta : array_like
        parameters to perturb, shape (p,); default ``robot.nominal_parameters``.

    Returns
    -------
    numpy.ndarray
        Perturbed parameters, shape (p,). Per body: mass times ``exp(rel e)``,
        principal second moments of the mass distribution times ``exp(rel e)``
        (the principal moments of inertia at the CoM then satisfy the triangle
        inequalities), principal axes rotated by about ``rel`` [rad], centre of
        mass moved by about ``rel`` times its distance from the joint (at least
        the radius of gyration); massless bodies are left unchanged. Joint terms
        times ``exp(rel e)``, so Ia, fv, fc, k keep their (non-negative) sign; a
        zero term stays zero.
    """
    rel = as_real(rel, "rel", minimum=0.0)
    check_count(rel, MAX_REL, "the relative perturbation")  # exp(rel e) overflows beyond
    theta = (
        robot.nominal_parameters.copy() if theta is None else parameter_vector(robot, theta).copy()
    )
    if rel == 0.0:
        return theta
    rng = random_generator(seed)
    blocks = robot.layout.rigid_blocks(theta)  # views into theta
    for i in range(robot.n_bodies):
        blocks[i] = _perturb_body(blocks[i], rel, rng)
    terms = robot.terms.enabled
    if terms:
        joint = robot.layout.joint_block(theta)
        joint *= np.exp(rel * rng.standard_normal(joint.shape))
        for k, t in enumerate(terms):
            if t in _POSITIVE_TERMS:
                joint[:, k] = np.abs(joint[:, k])
    return theta


def require_physical(robot: Robot, theta) -> None:
    """Raise unless ``theta`` can be simulated: every body physically realizable.

    A body fails when its pseudo-inertia has a negative eigenvalue (negative mass,
    inertia not positive semi-definite about the centre of mass, triangle inequalities
    broken), and a joint when its armature or viscous / Coulomb friction is negative
    (:func:`manip_id.physics.consistency.check_consistency`); the message names the body.
    A singular pseudo-inertia (a point mass, a massless frame) is accepted.
    """
    report = check_consistency(robot, theta)
    if report.consistent:
        return
    indefinite = {
        name
        for name, low, high in zip(
            report.body_names, report.min_eigenvalues, report.max_eigenvalues, strict=True
        )
        if low < -PSD_TOLERANCE * max(abs(low), abs(high))
    }
    bodies = set(report.body_names)
    violations = [v for v in report.violations if v.name in indefinite or v.name not in bodies]
    if violations:
        named = [b for b in report.body_names if b in {v.name for v in violations}]
        hint = (
            f" (bodies {', '.join(named)}; 'manip-id repair ROBOT OUT.urdf' writes the "
            "nearest physical model)"
            if named
            else ""
        )
        raise PhysicalConsistencyError(f"robot {robot.name!r} to simulate{hint}", violations)


__all__ = ["PSD_TOLERANCE", "parameter_vector", "perturb_parameters", "require_physical"]
