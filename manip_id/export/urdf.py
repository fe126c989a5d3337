"""The identified model as a URDF that simulates: every link physical, meshes loadable.

:func:`export_urdf` copies the robot's URDF and rewrites, for every identified (active)
joint ``j``:

- the ``<inertial>`` of the joint's child link (the holder) and of the links its body
  carries (fixed joints, joints locked for the identification): the carried links keep
  their nominal inertia (or a consistent share) and the holder gets the identified
  composite minus theirs (:mod:`manip_id.export.links`): mass, centre of mass in
  ``<origin xyz>`` (``rpy="0 0 0"``) and the inertia about the centre of mass in the link
  frame, from the 10 standard parameters ``[m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz,
  Izz]`` (about the joint origin);
- ``<dynamics damping="fv" friction="fc">`` of the joint, when viscous or Coulomb
  friction is among the identified terms;
- the mesh references, as absolute paths (:mod:`manip_id.export.meshes`).

Then ``pinocchio.buildModelFromUrdf(out)`` with the identification's locked joints locked
at the same configuration has the identified blocks as its inertias, and the unreduced
model is physical (``crba`` positive definite, ``aba`` finite). Armature, offset and
spring have no URDF field: they go to the sidecar (:mod:`manip_id.export.sidecar`).
Everything else (limits, comments, other tags) is left as it was.
"""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from .._checks import as_float_array, check_finite
from .._io import atomic_write_text, check_output_file, json_text
from .._io.reading import read_text
from ..errors import ExportWarning, InputError, RobotError
from ..physics.consistency import EIG_TOLERANCE, pseudo_inertia, require_consistent
from .links import Composite, LinkTree, link_inertia, link_tree, split_composites
from .meshes import rewrite_meshes
from .sidecar import sidecar_document, sidecar_path


@dataclass(frozen=True)
class ExportResult:
    """What an export wrote.

    Attributes
    ----------
    path: the exported file (``.urdf`` or ``.xml``); sidecar: its JSON
    composites: per identified body, its holder link, carried links and their share
    unresolved: mesh references that name no file (left as they were)
    skipped: meshes left out of an MJCF file (a format MuJoCo cannot read)
    min_eigenvalues: the self-check: per joint of the unreduced exported model (no joint
        locked), the smallest eigenvalue of its body's pseudo-inertia (all positive: the
        model simulates) [mixed kg / kg m^2]
    """

    path: Path
    sidecar: Path
    composites: list[Composite]
    unresolved: list[str]
    skipped: list[str]
    min_eigenvalues: dict[str, float]

    @property
    def urdf(self) -> Path:
        """The exported file (name kept from the URDF-only export)."""
        return self.path


def check_output(path, force: bool = False, suffixes: tuple[str, ...] = (".urdf",)) -> tuple:
    """Check an export target before any work: a path ending in one of ``suffixes`` in an
    existing or creatable folder, not existing unless ``force`` (its sidecar too).
    Returns ``(path, sidecar)``."""
    p = Path(path)
    if p.suffix.lower() not in suffixes:
        raise InputError(f"the exported robot must be a {' or '.join(suffixes)} file, got {path!r}")
    if p.is_dir():
        raise InputError(f"{p} is a folder, expected a {suffixes[0]} file path")
    side = sidecar_path(p)
    for target in (p, side):
        if target.exists() and not force:
            raise InputError(f"{target} exists: give force=True (--force) to replace it")
        if target.parent.is_dir():
            check_output_file(target, what="export")
    anc = p.parent if str(p.parent) else Path(".")
    while not anc.exists():
        anc = anc.parent
    if not anc.is_dir():
        raise InputError(f"cannot create {p}: {anc} is not a folder")
    return p, side


def _fmt(x: float) -> str:
    return repr(float(x))


def inertial_of(block: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass [kg], com (3,) [m], inertia about the com (3, 3) [kg m^2]) of a body block."""
    inertia = pin.Inertia.FromDynamicParameters(np.asarray(block, dtype=float))
    return float(inertia.mass), np.array(inertia.lever), np.array(inertia.inertia)


def set_inertial(link: ET.Element, m: float, c, I_c) -> None:
    """Write mass [kg], centre of mass (3,) [m] and inertia about it (3, 3) [kg m^2]."""
    inertial = link.find("inertial")
    if inertial is None:
        inertial = ET.SubElement(link, "inertial")
    el: dict[str, ET.Element] = {}
    for tag in ("origin", "mass", "inertia"):
        found = inertial.find(tag)
        el[tag] = found if found is not None else ET.SubElement(inertial, tag)
    el["origin"].attrib.update(xyz=" ".join(_fmt(v) for v in c), rpy="0 0 0")
    el["mass"].attrib.update(value=_fmt(m))
    keys = {"ixx": (0, 0), "ixy": (0, 1), "ixz": (0, 2), "iyy": (1, 1), "iyz": (1, 2)}
    el["inertia"].attrib.update({k: _fmt(I_c[a, b]) for k, (a, b) in keys.items()})
    el["inertia"].set("izz", _fmt(I_c[2, 2]))


def read_urdf(robot, source=None) -> tuple[Path, ET.Element]:
    """The robot's URDF (``source`` or ``robot.source``) and its root, parsed with comments."""
    src = Path(source if source is not None else (robot.source or ""))
    if not src.exists():
        raise RobotError(f"robot {robot.name!r} has no URDF file to copy (source {src})")
    text = read_text(src, "URDF", "urdf", error=RobotError)
    try:
        parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
        parser.feed(text)
        root = parser.close()
    except ET.ParseError as exc:
        raise RobotError(f"cannot read URDF {src}: {exc}") from exc
    if root is None or root.tag != "robot":
        raise RobotError(f"{src} is not a URDF (no <robot> root element)")
    return src, root


def checked_theta(robot, theta) -> np.ndarray:
    """``theta`` (p,) finite and physically consistent, or the error saying why not."""
    theta = as_float_array(theta, "theta", ndim=1)
    if theta.shape != (robot.n_parameters,):
        raise InputError(f"{theta.shape=} but robot.n_parameters={robot.n_parameters}")
    check_finite(theta, "theta", robot.parameter_names)
    require_consistent(robot, theta, "the parameter vector to export")
    return theta


def _set_dynamics(robot, tree: LinkTree, theta: np.ndarray) -> None:
    values = dict(zip(robot.parameter_names, theta, strict=True))
    for j in robot.joint_names:
        fv, fc = values.get(f"{j}.fv"), values.get(f"{j}.fc")
        if fv is None and fc is None:
            continue
        joint = tree.joints[j]
        dyn = joint.find("dynamics")
        if dyn is None:
            dyn = ET.SubElement(joint, "dynamics")
        if fv is not None:
            dyn.set("damping", _fmt(fv))
        if fc is not None:
            dyn.set("friction", _fmt(fc))


def _set_transmissions(robot, root: ET.Element) -> None:
    """One ``<transmission>`` per joint with its ``mechanicalReduction`` (ROS
    ``transmission_interface/SimpleTransmission``) when the robot's ``R`` is diagonal; a
    coupled ``R`` and the motor terms have no URDF form: the sidecar holds them. Existing
    transmissions of the same name are replaced."""
    tr = robot.transmission
    if tr is None or not tr.is_diagonal:
        return
    for j, (joint, motor, ratio) in enumerate(
        zip(robot.dof_names, tr.motor_names, tr.ratios, strict=True)
    ):
        name = f"{joint}_transmission"
        for old in root.findall("transmission"):
            if old.get("name") == name:
                root.remove(old)
        el = ET.SubElement(root, "transmission", name=name)
        ET.SubElement(el, "type").text = "transmission_interface/SimpleTransmission"
        ET.SubElement(el, "joint", name=joint)
        act = ET.SubElement(el, "actuator", name=motor)
        ET.SubElement(act, "mechanicalReduction").text = _fmt(float(ratio))
        if tr.q0[j] != 0.0:  # no URDF field: a comment for the reader (the sidecar has it)
            el.append(ET.Comment(f" offset {_fmt(float(tr.q0[j]))} rad: see the sidecar "))


@dataclass(frozen=True)
class ExportedTree:
    """The rewritten URDF tree, its source and what the rewriting decided."""

    source: Path
    root: ET.Element
    tree: LinkTree
    composites: list[Composite]
    unresolved: list[str]
    meshes: str

    def text(self) -> str:
        return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(self.root, "unicode") + "\n"

    def model(self) -> pin.Model:
        """The unreduced Pinocchio model of the rewritten URDF."""
        try:
            return pin.buildModelFromXML(self.text())
        except Exception as exc:  # Pinocchio raises plain RuntimeError / ValueError
            raise RobotError(f"cannot build the exported model of {self.source}: {exc}") from exc


def body_check(model: pin.Model) -> dict[str, float]:
    """Per joint of ``model``, the smallest eigenvalue of its body's pseudo-inertia; warns
    (:class:`~manip_id.errors.ExportWarning`) naming the bodies that are not positive
    definite (a locked joint's link whose nominal inertia is not physical: the unreduced
    model will not simulate, the identified one still does)."""
    out: dict[str, float] = {}
    bad: list[str] = []
    for i in range(1, model.njoints):
        lam = np.linalg.eigvalsh(pseudo_inertia(model.inertias[i].toDynamicParameters()))
        out[model.names[i]] = float(lam[0])
        if not lam[0] > EIG_TOLERANCE * np.abs(lam).max():
            bad.append(model.names[i])
    if bad:
        warnings.warn(
            "the bodies of " + ", ".join(bad) + " in the exported model (no joint locked) "
            "are not physical: their URDF links' own inertias are not (they are kept)",
            ExportWarning,
            stacklevel=3,
        )
    return out


def exported_tree(
    robot, theta, *, source=None, carried: str = "auto", meshes: str = "absolute"
) -> ExportedTree:
    """The robot's URDF tree with the identified ``theta`` written in (module docstring)."""
    theta = checked_theta(robot, theta)
    src, root = read_urdf(robot, source)
    active = list(robot.joint_names)
    tree = link_tree(root, active)
    missing = [j for j in active if j not in tree.joints]
    if missing:
        raise RobotError(f"joint {missing[0]!r} of {robot.name!r} is not in the URDF {src}")
    composites = split_composites(robot, theta, tree, carried)
    for comp in composites:
        set_inertial(tree.links[comp.holder], *inertial_of(comp.holder_parameters))
        if comp.share != 1.0:
            for link in comp.carried:
                nominal = _scaled_nominal(tree.links[link], comp.share)
                set_inertial(tree.links[link], *nominal)
    _set_dynamics(robot, tree, theta)
    _set_transmissions(robot, root)
    unresolved = rewrite_meshes(root, src.parent, robot.package_dirs, meshes)
    return ExportedTree(src, root, tree, composites, unresolved, meshes)


def _scaled_nominal(link: ET.Element, share: float) -> tuple[float, np.ndarray, np.ndarray]:
    inertia = link_inertia(link)
    assert inertia is not None  # carried links have an <inertial>
    return share * inertia.mass, np.array(inertia.lever), share * np.array(inertia.inertia)


def exported_sidecar(
    robot, theta: np.ndarray, exp: ExportedTree, target: str, provenance: Mapping | None
) -> dict:
    """The sidecar of an export of ``exp``: the parameters, and per body its holder,
    carried links and share (``composites``), and the mesh references (``meshes``)."""
    side = sidecar_document(
        robot, theta, target=str(target), source=str(exp.source), provenance=provenance
    )
    side["composites"] = {
        c.joint: {"holder": c.holder, "carried": list(c.carried), "share": c.share}
        for c in exp.composites
    }
    side["meshes"] = {"written": exp.meshes, "unresolved": exp.unresolved}
    return side


@dataclass(frozen=True)
class ExportTexts:
    """The exported URDF text, the sidecar object and what the export decided."""

    urdf: str
    sidecar: dict
    composites: list[Composite]
    unresolved: list[str]
    min_eigenvalues: dict[str, float]


def export_texts(
    robot,
    theta,
    urdf_name: str,
    *,
    source=None,
    carried: str = "auto",
    meshes: str = "absolute",
    provenance: Mapping | None = None,
) -> ExportTexts:
    """The exported URDF text and sidecar of :func:`export_urdf`, without writing them."""
    theta = checked_theta(robot, theta)
    exp = exported_tree(robot, theta, source=source, carried=carried, meshes=meshes)
    side = exported_sidecar(robot, theta, exp, urdf_name, provenance)
    check = body_check(exp.model())
    side["min_eigenvalues"] = check
    return ExportTexts(exp.text(), side, exp.composites, exp.unresolved, check)


def export_urdf(
    robot,
    theta,
    path,
    *,
    force: bool = False,
    source=None,
    carried: str = "auto",
    meshes: str = "absolute",
    provenance: Mapping | None = None,
) -> ExportResult:
    """Write ``robot``'s URDF with the identified ``theta`` (shape (p,)), and its sidecar.

    Parameters
    ----------
    robot : Robot
        The robot ``theta`` was identified for (its locked joints decide the composites).
    theta : array_like, shape (p,)
        Standard parameters; refused unless physically consistent
        (:class:`~manip_id.physics.consistency.PhysicalConsistencyError`).
    path : path
        The ``.urdf`` to write; refused if it exists unless ``force`` (checked first).
    source : path, optional
        The URDF to copy (default ``robot.source``).
    carried : {"auto", "nominal", "scaled"}
        What the links rigidly attached to an identified body keep
        (:mod:`manip_id.export.links`).
    meshes : {"absolute", "keep"}
        How mesh references are written (:mod:`manip_id.export.meshes`).
    provenance : mapping, optional
        Command, source data and uncertainty summary for the sidecar.

    Returns
    -------
    ExportResult
        The files written (atomically) and what the export decided.
    """
    urdf, side = check_output(path, force)
    src = Path(source if source is not None else (robot.source or ""))
    if src.is_file() and src.resolve() == urdf.resolve():
        raise InputError(f"{urdf} is the robot's own URDF: write the export elsewhere")
    texts = export_texts(
        robot,
        theta,
        urdf.name,
        source=source,
        carried=carried,
        meshes=meshes,
        provenance=provenance,
    )
    atomic_write_text(urdf, texts.urdf)
    atomic_write_text(side, json_text(texts.sidecar))
    return ExportResult(urdf, side, texts.composites, texts.unresolved, [], texts.min_eigenvalues)
