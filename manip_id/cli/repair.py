"""``manip-id repair ROBOT OUT.urdf``: a URDF whose non-physical inertias are made physical.

The bodies of ROBOT that fail the eigenvalue test of their pseudo-inertia are
replaced by their nearest physical ones (:func:`manip_id.physics.repair.repair_nominal`:
mass and centre of mass kept, the second moments about the centre of mass
projected onto the physical ones); the others are left as they are. The table
says what changed per body; OUT (and its sidecar, :func:`manip_id.export.export_urdf`)
is checked before the work and written atomically.
"""

from __future__ import annotations

from ._common import (
    add_robot_arguments,
    command,
)


def register(sub) -> None:
    p = sub.add_parser(
        "repair",
        help="write a copy of a URDF whose non-physical inertias are made physical",
        description="Make the nominal model of ROBOT physically consistent: each body whose "
        "pseudo-inertia is not positive definite (negative mass or inertia, broken triangle "
        "inequalities) gets the nearest physical inertia with the same mass and centre of "
        "mass; the other bodies are unchanged. Writes OUT (a .urdf) and its sidecar.",
    )
    add_robot_arguments(p)
    p.add_argument("out", metavar="OUT.urdf", help="the repaired URDF to write")
    p.add_argument("--force", action="store_true", help="replace OUT if it exists")
    p.add_argument("--json", metavar="OUT", help="write what changed per body as JSON")
    p.set_defaults(func=command("manip_id.cli._repair"))
