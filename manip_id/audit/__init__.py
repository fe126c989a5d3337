"""The log auditor: the user's data mistakes, found against the robot's models before a fit.

For each file (its window, bad rows and torque scale applied as the fit would see
them; :mod:`~.files`), with ddq from the file or from
:func:`manip_id.signals.preprocess` when it has none (torques filtered alike):

- **scale, sign, offset** per joint (:mod:`~.fits`): the Huber-weighted fit, on the
  rows of the motion stream ``k`` and the torque stream ``k + L``, of::

      tau_j[k + L] = s_j tau0_j[k] + f_v dq_j[k] + f_c sgn_eps(dq_j[k]) + o_j + e[k]

  with ``tau0 = rnea(q, dq, ddq)`` of the robot's own (URDF) model. ``scale = s_j``
  is the measured over nominal torque (about 0.1 for currents of a drive of 10 N m/A,
  -1 for a flipped sign), ``offset = o_j / s_j`` [N m]. The friction columns keep
  unmodelled friction out of the scale. A scale counts as determined when the
  nominal column explains at least :data:`EXPLAINED_MIN` of the torque variance the
  other columns leave.
- **delay** of the torque stream behind the motion stream (:mod:`~.delay`): the lag
  ``L`` whose torques (each divided by its scale) one rigid-body model (the full
  regressor, parameters shared by all joints, plus friction and offset per joint)
  predicts best on held-out rows (two-fold cross-validation), refined to a
  sub-sample. One lag per file: a logger delays a stream, not a joint; the lag that
  best fits one joint alone is reported as ``own_delay`` (it also absorbs unmodelled
  friction dynamics). A delay is a finding when it exceeds :data:`DELAY_STEPS`
  samples and removes at least :data:`DELAY_GAIN` of the held-out error.
- **time unit**: a rate outside 1 Hz .. 100 kHz is refused, naming the likely unit
  (:func:`manip_id.datasets.adjust.check_rate`);
- **positions** (:mod:`~.findings`): degrees, an offset against the limits,
  wrap-around;
- **motion**: the standstill share per joint (``|dq_j| < eps``), the rest at the
  file's edges (the window :attr:`FileAudit.kept` that ``--trim-standstill``
  keeps), static files (no joint moves beyond its encoder's resolution: "used for
  gravity and offset only", no motion findings);
- **bad rows** dropped, per reason.

Findings are sentences; :class:`Audit` holds them, its compact
:meth:`~Audit.table` and its JSON (:meth:`~Audit.to_dict`, the ``audit`` of the
commands' JSON). The audit holds one file's rows in memory at a time.
"""

from .delay import LAG_BLOCK, LAG_ROWS, stream_lags
from .files import EDGE_REST, REST_SHARE, audit_file, audit_files
from .findings import DELAY_GAIN, DELAY_STEPS, FAR
from .fits import EXPLAINED_MIN, nominal_torque
from .report import Audit, AuditOptions, FileAudit, JointAudit

__all__ = [
    "DELAY_GAIN",
    "DELAY_STEPS",
    "EDGE_REST",
    "EXPLAINED_MIN",
    "FAR",
    "LAG_BLOCK",
    "LAG_ROWS",
    "REST_SHARE",
    "Audit",
    "AuditOptions",
    "FileAudit",
    "JointAudit",
    "audit_file",
    "audit_files",
    "nominal_torque",
    "stream_lags",
]
