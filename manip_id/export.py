"""The identified model back out: a URDF with the identified inertias and friction, and a sidecar.

:func:`export_urdf` copies the robot's URDF and rewrites, for every identified
(active) joint ``j``:

- the ``<inertial>`` of the joint's child link: mass, centre of mass in
  ``<origin xyz>`` (``rpy="0 0 0"``) and the inertia about the centre of mass in
  the link frame, from the 10 standard parameters of body ``j``
  ``[m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` (about the joint origin);
- ``<dynamics damping="fv" friction="fc">`` of the joint, when viscous or Coulomb
  friction is among the identified terms.

Where the composite goes. Pinocchio merges every link attached rigidly to joint
``j`` (through fixed joints, or through joints that were locked for the
identification) into one body; the identified block is that composite. The
export puts the whole composite into the joint's child link and sets the
``<inertial>`` of the other links of the composite to zero mass and inertia, so
that ``pinocchio.buildModelFromUrdf(out)`` has
``model.inertias[j].toDynamicParameters()`` equal to the identified block
whether or not the locked joints are locked again (they carry no mass now).

Armature ``Ia``, offset ``fo`` and spring ``k`` have no URDF field: they go to a
sidecar JSON next to the URDF (``OUT.identified.json``, :func:`sidecar_path`),
with the identified parameter vector, the joint terms and the active joints;
``load_robot(OUT, identified=True)`` reads it back. Everything else of the URDF
(meshes, limits, comments, other tags) is left as it was.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._checks import as_float_array, check_finite
from ._io import atomic_write_text, json_text
from .consistency import require_consistent
from .errors import InputError, RobotError

#: ``format`` field of the sidecar JSON.
SIDECAR_FORMAT = "manip_id identified parameters"
SIDECAR_VERSION = 1


@dataclass(frozen=True)
class ExportResult:
    """What :func:`export_urdf` wrote: ``urdf`` and ``sidecar`` paths; ``links`` per joint
    (the child link that holds the composite) and ``zeroed`` (links set to zero inertia)."""

    urdf: Path
    sidecar: Path
    links: dict[str, str]
    zeroed: list[str]


def sidecar_path(urdf_path) -> Path:
    """The sidecar JSON of an exported URDF: ``robot.urdf`` -> ``robot.identified.json``."""
    p = Path(urdf_path)
    return p.with_name(p.stem + ".identified.json")


def check_output(path, force: bool = False) -> tuple[Path, Path]:
    """Check an export target before any work: a ``.urdf`` path in an existing or creatable
    folder, not existing unless ``force`` (its sidecar too). Returns (urdf, sidecar)."""
    p = Path(path)
    if p.suffix.lower() != ".urdf":
        raise InputError(f"the exported robot must be a .urdf file, got {str(path)!r}")
    if p.is_dir():
        raise InputError(f"{p} is a folder, expected a .urdf file path")
    side = sidecar_path(p)
    for target in (p, side):
        if target.exists() and not force:
            raise InputError(f"{target} exists: give force=True (--force) to replace it")
    parent = p.parent if str(p.parent) else Path(".")
    anc = parent
    while not anc.exists():
        anc = anc.parent
    if not anc.is_dir():
        raise InputError(f"cannot create {p}: {anc} is not a folder")
    return p, side


def _fmt(x: float) -> str:
    return repr(float(x))


def _composite_inertial(block: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass [kg], com (3,) [m], inertia about the com (3, 3) [kg m^2]) of a body block."""
    m = float(block[0])
    c = block[1:4] / m
    ixx, ixy, iyy, ixz, iyz, izz = block[4:]
    I_o = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    I_c = I_o - m * (float(c @ c) * np.eye(3) - np.outer(c, c))
    return m, c, I_c


def _set_inertial(link: ET.Element, m: float, c, I_c) -> None:
    inertial = link.find("inertial")
    if inertial is None:
        inertial = ET.SubElement(link, "inertial")
    el: dict[str, ET.Element] = {}
    for tag in ("origin", "mass", "inertia"):
        found = inertial.find(tag)
        el[tag] = found if found is not None else ET.SubElement(inertial, tag)
    el["origin"].attrib.update(xyz=" ".join(_fmt(v) for v in c), rpy="0 0 0")
    el["mass"].attrib.update(value=_fmt(m))
    el["inertia"].attrib.update(
        ixx=_fmt(I_c[0, 0]),
        ixy=_fmt(I_c[0, 1]),
        ixz=_fmt(I_c[0, 2]),
        iyy=_fmt(I_c[1, 1]),
        iyz=_fmt(I_c[1, 2]),
        izz=_fmt(I_c[2, 2]),
    )


def _owners(root: ET.Element, active: list[str]) -> tuple[dict[str, str], dict[str, str]]:
    """Per link, the active joint whose body it belongs to; per active joint, its child link."""
    parent_of: dict[str, tuple[str, str]] = {}  # child link -> (joint, parent link)
    child_of: dict[str, str] = {}
    for joint in root.findall("joint"):
        child, parent = joint.find("child"), joint.find("parent")
        if child is None or parent is None:
            continue
        parent_of[str(child.get("link"))] = (str(joint.get("name")), str(parent.get("link")))
        child_of[str(joint.get("name"))] = str(child.get("link"))
    owner: dict[str, str] = {}
    active_set = set(active)
    for link in (str(lk.get("name")) for lk in root.findall("link")):
        cur, seen = link, set()
        while cur in parent_of and cur not in seen:
            seen.add(cur)
            jname, up = parent_of[cur]
            if jname in active_set:
                owner[link] = jname
                break
            cur = up
    return owner, child_of


@dataclass(frozen=True)
class ExportTexts:
    """The exported URDF text, the sidecar object and where the composites went."""

    urdf: str
    sidecar: dict
    links: dict[str, str]
    zeroed: list[str]


def export_urdf(robot, theta, path, *, force: bool = False, source=None) -> ExportResult:
    """Write ``robot``'s URDF with the identified ``theta`` (shape (p,)), and its sidecar.

    Refuses a ``theta`` that is not physically consistent
    (:class:`~manip_id.consistency.PhysicalConsistencyError`) and an existing output
    unless ``force`` (both checked before any work). ``source``: the URDF to copy
    (default ``robot.source``). The files are written atomically.
    """
    urdf, side = check_output(path, force)
    texts = export_texts(robot, theta, urdf.name, source=source, target=urdf)
    atomic_write_text(urdf, texts.urdf)
    atomic_write_text(side, json_text(texts.sidecar))
    return ExportResult(urdf=urdf, sidecar=side, links=texts.links, zeroed=texts.zeroed)


def export_texts(robot, theta, urdf_name: str, *, source=None, target=None) -> ExportTexts:
    """The exported URDF text and sidecar of :func:`export_urdf`, without writing them."""
    urdf = Path(target) if target is not None else None
    theta = as_float_array(theta, "theta", ndim=1)
    if theta.shape != (robot.n_parameters,):
        raise InputError(f"{theta.shape=} but robot.n_parameters={robot.n_parameters}")
    check_finite(theta, "theta", robot.parameter_names)
    require_consistent(robot, theta, "the parameter vector to export")
    src = Path(source if source is not None else (robot.source or ""))
    if not src.is_file():
        raise RobotError(f"robot {robot.name!r} has no URDF file to copy (source {src})")
    if urdf is not None and src.resolve() == urdf.resolve():
        raise InputError(f"{urdf} is the robot's own URDF: write the export elsewhere")
    try:
        parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
        tree = ET.parse(src, parser=parser)
    except (ET.ParseError, OSError) as exc:
        raise RobotError(f"cannot read URDF {src}: {exc}") from exc
    root = tree.getroot()
    links = {lk.get("name"): lk for lk in root.findall("link")}
    joints = {j.get("name"): j for j in root.findall("joint")}
    active = list(robot.joint_names)
    missing = [j for j in active if j not in joints]
    if missing:
        raise RobotError(f"joint {missing[0]!r} of {robot.name!r} is not in the URDF {src}")
    owner, child_of = _owners(root, active)
    blocks = robot.rigid_body_parameters(theta)
    holder: dict[str, str] = {}
    zeroed: list[str] = []
    for j, block in zip(active, blocks, strict=True):
        link = child_of[j]
        holder[j] = link
        _set_inertial(links[link], *_composite_inertial(block))
    for link_name, j in owner.items():
        if link_name != holder[j] and links[link_name].find("inertial") is not None:
            _set_inertial(links[link_name], 0.0, np.zeros(3), np.zeros((3, 3)))
            zeroed.append(link_name)
    # friction on the joints (one-DoF joints: dof name == joint name)
    names = robot.parameter_names
    values = dict(zip(names, theta, strict=True))
    for j in active:
        fv, fc = values.get(f"{j}.fv"), values.get(f"{j}.fc")
        if fv is None and fc is None:
            continue
        dyn = joints[j].find("dynamics")
        if dyn is None:
            dyn = ET.SubElement(joints[j], "dynamics")
        if fv is not None:
            dyn.set("damping", _fmt(fv))
        if fc is not None:
            dyn.set("friction", _fmt(fc))
    text = ET.tostring(root, encoding="unicode")
    head = '<?xml version="1.0" encoding="utf-8"?>\n'
    sidecar = {
        "format": SIDECAR_FORMAT,
        "version": SIDECAR_VERSION,
        "urdf": urdf_name,
        "robot": robot.name,
        "source": str(src),
        "active_joints": active,
        "joint_terms": list(robot.terms.enabled),
        "composite_links": holder,
        "zeroed_links": zeroed,
        "joints": {
            dof: {
                t: float(values[f"{dof}.{t}"])
                for t in robot.terms.enabled
                if f"{dof}.{t}" in values
            }
            for dof in robot.dof_names
        },
        "parameters": [
            {"name": n, "value": float(v), "unit": u}
            for n, v, u in zip(names, theta, robot.parameter_units, strict=True)
        ],
    }
    return ExportTexts(urdf=head + text + "\n", sidecar=sidecar, links=holder, zeroed=zeroed)


def read_sidecar(path) -> dict:
    """Read and check a sidecar JSON written by :func:`export_urdf`."""
    p = Path(path)
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise InputError(f"no identified-parameter sidecar at {p}") from exc
    except (OSError, json.JSONDecodeError) as exc:
        raise InputError(f"cannot read the identified-parameter sidecar {p}: {exc}") from exc
    if not isinstance(data, dict) or data.get("format") != SIDECAR_FORMAT:
        raise InputError(f"{p} is not a manip_id sidecar (expected format {SIDECAR_FORMAT!r})")
    if not isinstance(data.get("joints"), dict) or not isinstance(data.get("active_joints"), list):
        raise InputError(f"{p}: the sidecar misses 'joints' or 'active_joints'")
    return data


_TERM_FLAGS = {"Ia": "armature", "fv": "viscous", "fc": "coulomb", "fo": "offset", "k": "spring"}


def identified_options(spec: str, identified, armature, friction, spring, active_joints):
    """The sidecar of an exported URDF and the load options it implies (explicit ones win).

    Returns ``(sidecar, armature, friction, spring, active_joints)`` for
    :func:`manip_id.robot.load_robot`.
    """
    path = sidecar_path(spec) if identified is True else Path(identified)
    data = read_sidecar(path)
    terms = [t for t in data.get("joint_terms", []) if t in _TERM_FLAGS]
    if armature is None:
        armature = "Ia" in terms
    if friction is None:
        friction = [_TERM_FLAGS[t] for t in terms if t in ("fv", "fc", "fo")]
    if spring is None:
        spring = "k" in terms
    if active_joints is None:
        active_joints = list(data["active_joints"])
    return data, armature, friction, spring, active_joints


def apply_identified(robot, sidecar: dict) -> None:
    """Put the sidecar's armature into ``robot.model`` and its offset and spring into
    ``robot.settings`` (so that ``robot.nominal_parameters`` holds them)."""
    joints = sidecar["joints"]
    arm = np.array(robot.model.armature, dtype=float)
    offset, spring = np.zeros(robot.nv), np.zeros(robot.nv)
    for k, dof in enumerate(robot.dof_names):
        terms = joints.get(dof, {})
        if "Ia" in terms:
            arm[k] = float(terms["Ia"])
        offset[k] = float(terms.get("fo", 0.0))
        spring[k] = float(terms.get("k", 0.0))
    robot.model.armature = arm
    robot.settings["offset"] = offset
    if any("k" in joints.get(d, {}) for d in robot.dof_names):
        robot.settings["spring"] = spring
