"""Seeing it: meshcat scenes, matplotlib figures and HTML reports.

Conventions shared by the members of this subpackage
----------------------------------------------------

Inputs are plain arrays and small typed objects; nothing here runs an
identification. Shapes follow the package: ``t`` [s] of shape (N,), ``q`` of
shape (N, nq) [rad or m], torques of shape (N, nv) [N m or N], parameter
vectors of shape (p,) in :attr:`manip_id.robot.model.Robot.parameter_names` order.

**Equivalent inertia ellipsoid** (:mod:`.inertia_ellipsoid`). A body block
``[m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` (first moment and inertia
about the joint origin) is drawn as the homogeneous solid ellipsoid with the
same mass, centre of mass and rotational inertia::

    c   = (mc) / m                                 centre of mass [m]
    I_c = I_o - m (|c|^2 E - c c^T)                 inertia about the CoM [kg m^2]
    I_c = R diag(l_1, l_2, l_3) R^T                 principal axes R, moments l_i
    a_i = sqrt(5 / (2 m) (l_j + l_k - l_i))         semi-axes [m], {i, j, k} = {1, 2, 3}

since a solid ellipsoid has ``l_i = m (a_j^2 + a_k^2) / 5``. A block with
``m <= 0``, a non-positive moment or ``l_i > l_j + l_k`` has no such ellipsoid
(it is not physically consistent): it is skipped and a note says why.

**Identifiability share** of a link: among the parameters named
``<joint>.*`` (its 10 inertial parameters and the joint terms of its joint),
the fraction that is *determined*: flagged identifiable and, when relative
standard deviations are given, with ``std / |value| <= threshold``. Colors run
from red (share 0) through yellow (0.5) to green (1); links without parameters
(the fixed base) are grey.

**Files** are written atomically: to a temporary file in the target folder,
then renamed; a failure never leaves a partial file (reports: a temporary
folder, then renamed).

**Colors** are RGBA floats in [0, 1].
"""

from __future__ import annotations

import importlib
from typing import Any

#: Public name -> (submodule, attribute; None for the submodule itself), imported on
#: first use (PEP 562): ``import manip_id.viz`` loads neither matplotlib nor meshcat.
_WHERE: dict[str, tuple[str, str | None]] = {
    "figures": (".figures", None),
    "EquivalentEllipsoid": (".inertia_ellipsoid", "EquivalentEllipsoid"),
    "LinkIdentifiability": (".link_colors", "LinkIdentifiability"),
    "RobotScene": (".meshcat_scene", "RobotScene"),
    "check_trajectory": (".trajectory_check", "check_trajectory"),
    "equivalent_ellipsoid": (".inertia_ellipsoid", "equivalent_ellipsoid"),
    "inertia_ellipsoids": (".inertia_ellipsoid", "inertia_ellipsoids"),
    "link_identifiability": (".link_colors", "link_identifiability"),
    "ReportExistsError": ("..errors", "ReportExistsError"),
    "check_report_target": ("manip_id._io", "check_report_target"),
    "write_report": (".report", "write_report"),
    "ReportContent": (".report", "ReportContent"),
}


def __getattr__(name: str) -> Any:
    """Import the submodule that defines ``name`` on first access (PEP 562)."""
    try:
        module, attr = _WHERE[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = importlib.import_module(module, __name__)
    if attr is not None:
        value = getattr(value, attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


__all__ = [
    "EquivalentEllipsoid",
    "LinkIdentifiability",
    "RobotScene",
    "check_trajectory",
    "equivalent_ellipsoid",
    "inertia_ellipsoids",
    "link_identifiability",
    "figures",
    "ReportExistsError",
    "check_report_target",
    "ReportContent",
    "write_report",
]
