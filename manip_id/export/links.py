"""Where an identified composite goes among the links of the URDF: holder and carried links.

Pinocchio merges every link attached rigidly to an identified joint ``j`` (through fixed
joints, or through joints locked for the identification at the robot's
:attr:`~manip_id.robot.model.Robot.locked_configuration`) into the one body whose standard
parameters ``theta_j`` (10,) were identified. The export writes:

- each **carried** link ``l`` (every link of the composite but the joint's child link)
  with a share ``s_j`` of its nominal inertia ``pi_l`` (``s_j = 1``: the URDF's own, the
  default whenever possible);
- the joint's child link, the **holder**, with the rest
  ``pi_hold = theta_j - s_j sum_l X_jl pi_l`` (``X_jl`` moves a link's parameters into
  the joint frame at the locked configuration).

So the composite is exactly ``theta_j`` at the locked configuration, and every link of
the unreduced model has a physical inertia (a finger keeps its mass: ``crba`` stays
positive definite and ``aba`` finite when the locked joints move again).

The holder is checked consistent as :mod:`manip_id.physics.consistency` checks a body: its
pseudo-inertia ``J(pi_hold) = J(theta_j) - s_j J_c`` positive definite beyond
``EIG_TOLERANCE``. When the nominal links do not fit (``s_j = 1`` fails):

- ``carried="nominal"``: :class:`~manip_id.errors.CarriedInertiaError` names the bodies;
- ``carried="auto"`` (default) or ``"scaled"``: ``s_j = SHARE_MARGIN / mu_max`` where
  ``mu_max`` is the largest generalized eigenvalue of ``(J_c, J(theta_j))``, the share at
  which the holder's pseudo-inertia would become singular (``J(theta_j)`` is positive
  definite, so ``0 < s_j < 1`` exists); the links keep their centres of mass and the
  shape of their inertia, scaled by ``s_j``, and the holder keeps
  ``1 - SHARE_MARGIN`` of the slack. ``"auto"`` warns (:class:`~manip_id.errors.ExportWarning`).
"""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..errors import CarriedInertiaError, ExportWarning, InputError, RobotError
from ..physics.consistency import EIG_TOLERANCE, pseudo_inertia

#: Policies for the links a composite carries.
CARRIED_POLICIES: tuple[str, ...] = ("auto", "nominal", "scaled")
#: Fraction of the largest admissible share given to the carried links when they must shrink.
SHARE_MARGIN = 0.9


@dataclass(frozen=True)
class LinkTree:
    """The links and joints of a URDF, by name.

    Attributes
    ----------
    links: link name -> its ``<link>`` element
    joints: joint name -> its ``<joint>`` element
    parent_of: child link -> (joint, parent link)
    child_of: joint -> its child link
    owner: link -> the active joint whose body it belongs to (links above every active
        joint have none)
    """

    links: dict[str, ET.Element]
    joints: dict[str, ET.Element]
    parent_of: dict[str, tuple[str, str]]
    child_of: dict[str, str]
    owner: dict[str, str]


def link_tree(root: ET.Element, active: list[str]) -> LinkTree:
    """The tree of a parsed URDF and, per link, the active joint owning it."""
    links = {str(lk.get("name")): lk for lk in root.findall("link")}
    joints = {str(j.get("name")): j for j in root.findall("joint")}
    parent_of: dict[str, tuple[str, str]] = {}
    child_of: dict[str, str] = {}
    for name, joint in joints.items():
        child, parent = joint.find("child"), joint.find("parent")
        if child is None or parent is None:
            continue
        parent_of[str(child.get("link"))] = (name, str(parent.get("link")))
        child_of[name] = str(child.get("link"))
    owner: dict[str, str] = {}
    active_set = set(active)
    for link in links:
        cur, seen = link, set()
        while cur in parent_of and cur not in seen:
            seen.add(cur)
            jname, up = parent_of[cur]
            if jname in active_set:
                owner[link] = jname
                break
            cur = up
    return LinkTree(links, joints, parent_of, child_of, owner)


def urdf_floats(text: str | None, n: int, default: float = 0.0) -> np.ndarray:
    """``n`` numbers of a URDF attribute (``default`` each when it is missing)."""
    if text is None:
        return np.full(n, default)
    values = [float(v) for v in text.split()]
    if len(values) != n:
        raise RobotError(f"expected {n} numbers in a URDF attribute, got {text!r}")
    return np.array(values)


def link_inertia(link: ET.Element) -> pin.Inertia | None:
    """A link's ``<inertial>`` in the link frame (None without one)."""
    inertial = link.find("inertial")
    if inertial is None:
        return None
    origin, mass, inertia = (inertial.find(t) for t in ("origin", "mass", "inertia"))
    m = float(mass.get("value", 0.0)) if mass is not None else 0.0
    xyz = urdf_floats(origin.get("xyz") if origin is not None else None, 3)
    rpy = urdf_floats(origin.get("rpy") if origin is not None else None, 3)
    get = (lambda k: float(inertia.get(k, 0.0))) if inertia is not None else (lambda k: 0.0)
    ixx, ixy, ixz, iyy, iyz, izz = (get(k) for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"))
    I_c = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])  # [kg m^2]
    R = pin.rpy.rpyToMatrix(*rpy)
    try:
        return pin.Inertia(m, xyz, R @ I_c @ R.T)
    except RuntimeError as exc:  # Pinocchio refuses a non-positive inertia
        raise RobotError(f"link {link.get('name')!r} of the URDF: {exc}") from exc


@dataclass(frozen=True)
class Composite:
    """One identified body among its links.

    Attributes
    ----------
    joint: the active joint; holder: its child link
    carried: the other links of the body that have an ``<inertial>``
    carried_parameters: their nominal parameters in the joint frame, shape (len(carried), 10)
    share: ``s_j``, the fraction of their nominal inertia the carried links keep
    holder_parameters: ``theta_j - s_j sum(carried_parameters)`` (10,), about the joint
        (= holder link) origin [kg, kg m, kg m^2]
    """

    joint: str
    holder: str
    carried: list[str]
    carried_parameters: np.ndarray
    share: float
    holder_parameters: np.ndarray


def carried_parameters(robot, tree: LinkTree) -> dict[str, tuple[list[str], np.ndarray]]:
    """Per active joint, its carried links and their nominal parameters in its frame.

    Placements from :attr:`Robot.full_model` at :attr:`Robot.locked_configuration`.
    """
    full = robot.full_model
    data = full.createData()
    pin.framesForwardKinematics(full, data, robot.locked_configuration)
    out: dict[str, tuple[list[str], list[np.ndarray]]] = {j: ([], []) for j in robot.joint_names}
    for link, joint in tree.owner.items():
        if link == tree.child_of[joint]:
            continue
        inertia = link_inertia(tree.links[link])
        if inertia is None or not np.any(inertia.toDynamicParameters()):
            continue  # nothing to carry (a frame-only link)
        if not full.existFrame(link, pin.BODY):
            raise RobotError(f"link {link!r} of the URDF is not a body frame of {robot.name!r}")
        oMl = data.oMf[full.getFrameId(link, pin.BODY)]
        oMj = data.oMi[full.getJointId(joint)]
        names, params = out[joint]
        names.append(link)
        params.append(oMj.actInv(oMl).act(inertia).toDynamicParameters())
    return {
        j: (names, np.array(params).reshape(len(names), 10)) for j, (names, params) in out.items()
    }


def _positive_definite(pi: np.ndarray) -> tuple[float, bool]:
    """Smallest eigenvalue of ``J(pi)`` and whether it passes the consistency test."""
    lam = np.linalg.eigvalsh(pseudo_inertia(pi))
    return float(lam[0]), bool(lam[0] > EIG_TOLERANCE * np.abs(lam).max())


def _largest_share(theta_j: np.ndarray, carried: np.ndarray) -> float:
    """The share ``s`` at which ``J(theta_j) - s J_c`` becomes singular (inf if never)."""
    Jt, Jc = pseudo_inertia(theta_j), pseudo_inertia(carried)
    try:
        Li = np.linalg.inv(np.linalg.cholesky(Jt))
    except np.linalg.LinAlgError:  # J(theta_j) not numerically positive definite
        return 0.0
    mu = float(np.linalg.eigvalsh(Li @ Jc @ Li.T).max())
    return np.inf if mu <= 0 else 1.0 / mu


def split_composites(robot, theta, tree: LinkTree, carried: str = "auto") -> list[Composite]:
    """Holder and carried links of every identified body of ``theta`` (module docstring).

    ``theta`` must be physically consistent (checked by the caller). Raises
    :class:`~manip_id.errors.CarriedInertiaError` for the bodies that cannot be split
    under the policy ``carried`` (one of :data:`CARRIED_POLICIES`).
    """
    if carried not in CARRIED_POLICIES:
        raise InputError(f"carried must be one of {list(CARRIED_POLICIES)}, got {carried!r}")
    blocks = robot.rigid_body_parameters(theta)
    nominal = carried_parameters(robot, tree)
    out: list[Composite] = []
    failed: dict[str, list[str]] = {}
    worst: dict[str, float] = {}
    scaled: list[str] = []
    for j, block in zip(robot.joint_names, blocks, strict=True):
        names, params = nominal[j]
        total = params.sum(axis=0) if names else np.zeros(10)
        share = 1.0
        rest = block - total
        lam, ok = _positive_definite(rest)
        if names and not ok and carried != "nominal":
            share = SHARE_MARGIN * min(1.0, _largest_share(block, total))
            rest = block - share * total
            lam, ok = _positive_definite(rest)
            scaled.append(f"{j} (kept share {share:.3g})")
        if not ok:
            failed[j], worst[j] = names, lam
        out.append(Composite(j, tree.child_of[j], names, params, share, rest))
    if failed:
        raise CarriedInertiaError(failed, worst)
    if scaled and carried == "auto":
        warnings.warn(
            "the nominal inertias of the links rigidly attached to "
            + ", ".join(scaled)
            + " do not fit in the identified bodies: they keep that share of their nominal "
            "inertia (the sidecar's 'composites' lists them)",
            ExportWarning,
            stacklevel=3,
        )
    return out
