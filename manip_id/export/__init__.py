"""The identified model out to where it is used: URDF, MJCF, the payload as a link, a sidecar.

- :func:`export_urdf` (:mod:`~manip_id.export.urdf`): the robot's URDF with the identified
  inertias and friction; every link keeps a physical inertia
  (:mod:`~manip_id.export.links`), meshes are written as absolute paths
  (:mod:`~manip_id.export.meshes`).
- :func:`export_mjcf` (:mod:`~manip_id.export.mjcf`): a MuJoCo model of the same
  robot, bodies' ``inertial``, joints' ``armature``, ``damping`` and ``frictionloss``.
- :func:`export_payload_urdf` (:mod:`~manip_id.export.payload_link`): the robot's URDF
  with an identified payload as a fixed link.
- :func:`saved_parameters` (:mod:`~manip_id.export.saved`): the physically consistent
  standard parameters of a saved result, to export it later (``manip-id export``).

Every export refuses a parameter vector that is not physically consistent, checks its
outputs before the work, never replaces a file unless ``force``, and writes the sidecar
JSON (:mod:`~manip_id.export.sidecar`) next to its file.
"""

from .links import CARRIED_POLICIES, Composite
from .meshes import MESH_POLICIES
from .mjcf import export_mjcf, mjcf_text
from .payload_link import PayloadLink, export_payload_urdf, payload_urdf_texts
from .saved import saved_parameters
from .sidecar import (
    SIDECAR_FORMAT,
    SIDECAR_VERSION,
    apply_identified,
    identified_options,
    locked_configuration,
    read_sidecar,
    sidecar_path,
)
from .urdf import ExportResult, ExportTexts, check_output, export_texts, export_urdf

__all__ = [
    "CARRIED_POLICIES",
    "MESH_POLICIES",
    "SIDECAR_FORMAT",
    "SIDECAR_VERSION",
    "Composite",
    "ExportResult",
    "ExportTexts",
    "PayloadLink",
    "apply_identified",
    "check_output",
    "export_mjcf",
    "export_payload_urdf",
    "export_texts",
    "export_urdf",
    "identified_options",
    "locked_configuration",
    "mjcf_text",
    "payload_urdf_texts",
    "read_sidecar",
    "saved_parameters",
    "sidecar_path",
]
