"""Collision and external-torque monitoring on an identified model.

The generalized-momentum observer (:mod:`~.observer`) gives per joint a residual ``r``,
the external torque through a first-order low-pass of bandwidth ``K``::

    r = K (p(t) - p(0) - int (tau + C^T dq - g - f + r) dt),   p = M(q) dq
    dr/dt = K (tau_ext - r)

for ``M ddq + C dq + g + f = tau + tau_ext`` on the identified model. A joint is flagged
when ``|r_j| > b_j``; the bounds ``b_j`` come from collision-free runs
(:mod:`~.thresholds`) with the false-alarm rate they imply, detections are time intervals
(:mod:`~.detections`), logs are read as the file pipeline reads them (:mod:`~.logs`).
"""

from .detections import Detection, MonitorRun
from .logs import MonitorLog, ReadOptions, as_logs, check_temperatures, read_log
from .observer import (
    DEFAULT_FILTER_GAIN,
    DEFAULT_GAIN,
    CollisionMonitor,
    MonitorModel,
    MonitorStep,
    check_parameters,
    covariance_kind,
    load_model,
    model_from_result,
    model_from_robot,
)
from .thresholds import DEFAULT_FALSE_ALARM, Thresholds, calibrate_thresholds, load_thresholds

__all__ = [
    "DEFAULT_FALSE_ALARM",
    "DEFAULT_FILTER_GAIN",
    "DEFAULT_GAIN",
    "CollisionMonitor",
    "Detection",
    "MonitorLog",
    "MonitorModel",
    "MonitorRun",
    "MonitorStep",
    "ReadOptions",
    "Thresholds",
    "as_logs",
    "calibrate_thresholds",
    "check_temperatures",
    "check_parameters",
    "covariance_kind",
    "load_model",
    "load_thresholds",
    "model_from_result",
    "model_from_robot",
    "read_log",
]
