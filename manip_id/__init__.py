"""manip_id: dynamic parameter identification of robot manipulators.

The linear-in-parameters model is the centre of everything::

    tau = Y(q, dq, ddq) theta                          inverse dynamics
    M(q) v + C(q, dq) w + g(q) = Y(q, dq, v, w) theta  Slotine-Li form
    z(t) = phi(t)^T theta                              scalar regression

Pinocchio supplies the rigid-body regressor; manip_id adds joint-level terms,
rank analysis, estimators, adaptive control, data handling and pictures.
Data flow one way: robot + data -> regressor -> (identifiability) ->
estimator -> result -> report / figures / meshcat.
"""

from .adaptive import AdaptiveGains, SlotineLiController, default_gains, lyapunov_function
from .closed_loop import ClosedLoopRun, compare_fixed, with_payload
from .closed_loop import simulate as simulate_adaptive
from .datasets import Dataset, check_robot, load_dataset, save_dataset
from .errors import (
    DataError,
    InfeasibleTrajectoryError,
    InputError,
    ManipIdError,
    RankDeficiencyError,
    RobotError,
)
from .estimators import (
    GradientEstimator,
    InformationAccumulator,
    LeastSquaresSolution,
    RLSEstimator,
    solve_accumulator,
    solve_stacked,
)
from .identifiability import (
    BaseParameters,
    RankAnalysis,
    analyze,
    analyze_dataset,
    analyze_information,
    analyze_trajectory,
)
from .identification import IdentificationResult, identify, identify_chunks, identify_dataset
from .regressor import (
    iter_regressor,
    iter_slotine_li_regressor,
    joint_torques,
    regressor,
    slotine_li_regressor,
)
from .robot import JointTerms, Robot, available_robots, load_robot
from .signals import Lowpass, preprocess
from .simulation import SimulatedData, perturb_parameters, simulate
from .trajectories import (
    ExcitationResult,
    FourierTrajectory,
    check_limits,
    optimize_excitation,
    random_trajectory,
)

__version__ = "0.1.0"

__all__ = [
    "AdaptiveGains",
    "ClosedLoopRun",
    "SlotineLiController",
    "compare_fixed",
    "default_gains",
    "lyapunov_function",
    "simulate_adaptive",
    "with_payload",
    "BaseParameters",
    "DataError",
    "Dataset",
    "ExcitationResult",
    "FourierTrajectory",
    "GradientEstimator",
    "IdentificationResult",
    "InfeasibleTrajectoryError",
    "InformationAccumulator",
    "InputError",
    "JointTerms",
    "LeastSquaresSolution",
    "Lowpass",
    "ManipIdError",
    "RLSEstimator",
    "RankAnalysis",
    "RankDeficiencyError",
    "Robot",
    "RobotError",
    "SimulatedData",
    "analyze",
    "analyze_dataset",
    "analyze_information",
    "analyze_trajectory",
    "available_robots",
    "check_limits",
    "check_robot",
    "identify",
    "identify_chunks",
    "identify_dataset",
    "iter_regressor",
    "iter_slotine_li_regressor",
    "joint_torques",
    "load_dataset",
    "load_robot",
    "optimize_excitation",
    "perturb_parameters",
    "preprocess",
    "random_trajectory",
    "regressor",
    "save_dataset",
    "simulate",
    "slotine_li_regressor",
    "solve_accumulator",
    "solve_stacked",
]
