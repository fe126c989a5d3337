"""manip_id: dynamic parameter identification of robot manipulators.

The linear-in-parameters model is the centre of everything::

    tau = Y(q, dq, ddq) theta                          inverse dynamics
    M(q) v + C(q, dq) w + g(q) = Y(q, dq, v, w) theta  Slotine-Li form
    z(t) = phi(t)^T theta                              scalar regression

Pinocchio supplies the rigid-body regressor; manip_id adds joint-level terms,
rank analysis, estimators, adaptive control, data handling and pictures.
"""

from .errors import (
    DataError,
    InfeasibleTrajectoryError,
    InputError,
    ManipIdError,
    RankDeficiencyError,
    RobotError,
)
from .regressor import (
    iter_regressor,
    iter_slotine_li_regressor,
    joint_torques,
    regressor,
    slotine_li_regressor,
)
from .robot import JointTerms, Robot, available_robots, load_robot

__version__ = "0.1.0"

__all__ = [
    "DataError",
    "InfeasibleTrajectoryError",
    "InputError",
    "JointTerms",
    "ManipIdError",
    "RankDeficiencyError",
    "Robot",
    "RobotError",
    "available_robots",
    "iter_regressor",
    "iter_slotine_li_regressor",
    "joint_torques",
    "load_robot",
    "regressor",
    "slotine_li_regressor",
]
